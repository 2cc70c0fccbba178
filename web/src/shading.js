// The page's surface material: lit per fragment, both sides. A soft studio set-up that reads as
// skin: a hemisphere light along the head's vertical (sky over ground), a key light from the
// camera's upper left and a fill from its right, both with wrapped diffuse (light reaching a
// little past the terminator, as it does through skin), and a broad, weak, Fresnel-weighted
// Blinn-Phong highlight (energy-normalised; F0 0.028, skin's). Hand-written rather than
// MeshStandardMaterial: with software WebGL (SwiftShader) three.js' generic PBR shader cost most
// of a frame (docs/lab/performance.md); this one is a few dozen operations per fragment.
import * as THREE from "three";

// The lighting, in view space (the lights move with the camera): n the unit normal, v the unit
// direction to the eye.
const LIGHT = `
uniform vec3 up;
uniform float shine;
const vec3 KEY = vec3(-0.45, 0.55, 0.70);
const vec3 FILL = vec3(0.75, -0.05, 0.66);
const float WRAP = 0.2;
float wrapped(float c) { return max((c + WRAP) / (1.0 + WRAP), 0.0); }
vec3 shade(vec3 n, vec3 v, vec3 albedo) {
  vec3 key = normalize(KEY);
  vec3 fill = normalize(FILL);
  float h = 0.5 + 0.5 * dot(n, up);
  vec3 light = mix(vec3(0.09, 0.085, 0.085), vec3(0.30, 0.31, 0.34), h);
  light += vec3(0.92, 0.89, 0.84) * wrapped(dot(n, key)) + vec3(0.24, 0.25, 0.28) * wrapped(dot(n, fill));
  vec3 c = albedo * light;
  vec3 hv = normalize(key + v);
  float nh = max(dot(n, hv), 0.0);
  float fresnel = 0.028 + 0.972 * pow(1.0 - max(dot(v, hv), 0.0), 5.0);
  return c + shine * fresnel * 3.6 * pow(nh, 28.0) * max(dot(n, key), 0.0);
}`;

// VERTEX_LIT (the skull): the same light per vertex, both sides, the fragment only picking one;
// bone needs no per-pixel highlight, and the skull's many layers made it the costliest surface.
const vertexShader = `
#ifdef TINT
attribute vec3 color;
#endif
#ifdef WEIGHTED
attribute float weight;
varying float vWeight;
#endif
uniform vec3 base;
#ifdef VERTEX_LIT
${LIGHT}
varying vec3 vFront;
varying vec3 vBack;
#else
varying vec3 vAlbedo;
varying vec3 vNormal;
varying vec3 vView;
#endif
void main() {
#ifdef TINT
  vec3 albedo = color;
#else
  vec3 albedo = base;
#endif
#ifdef WEIGHTED
  vWeight = weight;
#endif
  vec4 mv = modelViewMatrix * vec4(position, 1.0);
#ifdef VERTEX_LIT
  vec3 n = normalize(normalMatrix * normal);
  vec3 v = normalize(-mv.xyz);
  vFront = shade(n, v, albedo);
  vBack = shade(-n, v, albedo);
#else
  vAlbedo = albedo;
  vView = -mv.xyz;
  vNormal = normalMatrix * normal;
#endif
  gl_Position = projectionMatrix * mv;
}`;

const fragmentShader = `
#ifdef WEIGHTED
varying float vWeight;
#endif
uniform float opacity;
#ifdef VERTEX_LIT
varying vec3 vFront;
varying vec3 vBack;
#else
${LIGHT}
varying vec3 vAlbedo;
varying vec3 vNormal;
varying vec3 vView;
#endif
void main() {
#ifdef VERTEX_LIT
  vec3 c = gl_FrontFacing ? vFront : vBack;
#else
  vec3 n = normalize(vNormal);
  vec3 c = shade(gl_FrontFacing ? n : -n, normalize(vView), vAlbedo);
#endif
  // sRGB written here, not by three.js' linearToOutputTexel, so that an offscreen buffer
  // (frame_cache.js) holds the same values as the canvas.
#ifdef WEIGHTED
  gl_FragColor = vec4(sRGBTransferOETF(vec4(c, 1.0)).rgb, opacity * vWeight);
#else
  gl_FragColor = vec4(sRGBTransferOETF(vec4(c, 1.0)).rgb, opacity);
#endif
}`;

// The head's vertical in view coordinates, shared by every surface material and set once a frame
// (viewUp) rather than per fragment.
const up = { value: new THREE.Vector3(0, 1, 0) };
const headUp = new THREE.Vector3(0, 0, 1);

/** The head's vertical (world, LPS) for the hemisphere light. */
export function setHeadUp(v) {
  headUp.copy(v).normalize();
}

/** Point the hemisphere light for `camera` (call before drawing). */
export function viewUp(camera) {
  camera.updateMatrixWorld();
  up.value.copy(headUp).transformDirection(camera.matrixWorldInverse);
}

/** A two-sided surface: `colour` (sRGB hex) or, with `perVertex`, the geometry's "color"
 *  attribute (linear RGB); `shine` scales the highlight (0: matte); `weighted`: the opacity is
 *  scaled per vertex by the geometry's "weight" attribute; `vertexLit`: lit per vertex. */
export function surfaceMaterial({ colour = 0xffffff, perVertex = false, shine = 1, weighted = false, vertexLit = false } = {}) {
  const defines = {};
  if (vertexLit) defines.VERTEX_LIT = 1;
  if (perVertex) defines.TINT = 1;
  if (weighted) defines.WEIGHTED = 1;
  return new THREE.ShaderMaterial({
    vertexShader,
    fragmentShader,
    defines,
    side: THREE.DoubleSide,
    // Transparent (the skull seen through the face) in one pass, not three.js' back-then-front
    // two passes: with depthWrite off the order of the face's own layers does not matter.
    forceSinglePass: true,
    uniforms: {
      base: { value: new THREE.Color(colour) },
      up,
      shine: { value: shine },
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
