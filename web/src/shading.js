// The page's surface material: Lambert lighting (three.js' hemisphere + directional light model,
// the same sky/ground/sun as before) evaluated per vertex, both sides, so a fragment only picks
// one of two interpolated colours. With software WebGL (SwiftShader) the per-fragment lighting of
// MeshStandardMaterial was most of the 140 ms a frame (docs/performance.md); with ≈ 20 k-vertex
// meshes per-vertex lighting looks the same.
import * as THREE from "three";

const vertexShader = `
#ifdef TINT
attribute vec3 color;
#endif
uniform vec3 base;
uniform vec3 sky;
uniform vec3 ground;
uniform vec3 sun;
uniform vec3 sunDir;
uniform vec3 up;
varying vec3 vFront;
varying vec3 vBack;
void main() {
#ifdef TINT
  vec3 albedo = color;
#else
  vec3 albedo = base;
#endif
  vec3 n = normalize(normalMatrix * normal);
  // The back side's normal is −n: the same two dot products, negated.
  float h = 0.5 * dot(n, up);
  float s = dot(n, sunDir);
  vFront = albedo * (mix(ground, sky, 0.5 + h) + sun * max(s, 0.0));
  vBack = albedo * (mix(ground, sky, 0.5 - h) + sun * max(-s, 0.0));
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;

const fragmentShader = `
uniform float opacity;
varying vec3 vFront;
varying vec3 vBack;
void main() {
  // sRGB written here, not by three.js' linearToOutputTexel, so that an offscreen buffer
  // (frame_cache.js) holds the same values as the canvas.
  gl_FragColor = vec4(sRGBTransferOETF(vec4(gl_FrontFacing ? vFront : vBack, 1.0)).rgb, opacity);
}`;

// Lambert's BRDF is albedo / π; the light intensities of the former scene (hemisphere 1.6 from
// white over grey 0x666666, sun 1.2 from the camera's upper right) are folded into the uniforms.
const hemi = 1.6 / Math.PI;
const sunI = 1.2 / Math.PI;

// The hemisphere light's "up" in view coordinates, shared by every surface material and set once a
// frame (viewUp) rather than per vertex. three.js' HemisphereLight shines down world +y unless
// moved; kept as the page had it.
const up = { value: new THREE.Vector3(0, 1, 0) };

/** Point the hemisphere light for `camera` (call before drawing). */
export function viewUp(camera) {
  camera.updateMatrixWorld();
  up.value.set(0, 1, 0).transformDirection(camera.matrixWorldInverse);
}

/** A two-sided surface: `colour` (sRGB hex) or, with `perVertex`, the geometry's "color" attribute
 *  (linear RGB). */
export function surfaceMaterial({ colour = 0xffffff, perVertex = false } = {}) {
  return new THREE.ShaderMaterial({
    vertexShader,
    fragmentShader,
    defines: perVertex ? { TINT: 1 } : {},
    side: THREE.DoubleSide,
    // Transparent (the skull seen through the face) in one pass, not three.js' back-then-front
    // two passes: with depthWrite off the order of the face's own layers does not matter.
    forceSinglePass: true,
    uniforms: {
      base: { value: new THREE.Color(colour) },
      sky: { value: new THREE.Color(0xffffff).multiplyScalar(hemi) },
      ground: { value: new THREE.Color(0x666666).multiplyScalar(hemi) },
      sun: { value: new THREE.Color(0xffffff).multiplyScalar(sunI) },
      sunDir: { value: new THREE.Vector3(0.3, 0.5, 1).normalize() },
      up,
      opacity: { value: 1 },
    },
  });
}

/** Opacity of a surfaceMaterial (the uniform; `transparent` and depth writes follow it). */
export function setOpacity(material, opacity) {
  material.uniforms.opacity.value = opacity;
  material.transparent = opacity < 1;
  material.depthWrite = opacity >= 1;
}
