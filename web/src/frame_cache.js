// While a slider is dragged the camera stands still and only the face and the few hundred skull
// vertices of the moved segments change; the rest of the skull (≈ 97 % of its triangles on the
// real CT) is drawn once into an offscreen colour + depth buffer and copied (blitFramebuffer) into
// the canvas at the start of every slider frame; then only the moving objects are drawn over it.
// Objects on layer STATIC_LAYER are the cached ones. A frame drawn this way equals one drawn whole
// (test: crates/facesim/tests/library/report_page.rs); where the browser cannot copy the depth buffer into
// the canvas, the cache switches itself off and every frame is drawn whole.
import * as THREE from "three";

export const STATIC_LAYER = 1;

export class StaticCache {
  constructor(renderer, background) {
    this.renderer = renderer;
    this.background = background; // the clear colour, sRGB hex
    this.target = null;
    this.valid = false;
    this.key = new Float64Array(34);
    // Depth formats to try for the copy; the canvas' own depth format is the browser's choice.
    this.stencilChoices = [true, false];
    this.enabled = true;
  }

  /** Draw `scene` through the cache; false when the cache cannot be used (nothing was drawn). */
  draw(scene, camera) {
    if (!this.enabled) return false;
    const r = this.renderer;
    const gl = r.getContext();
    const w = gl.drawingBufferWidth;
    const h = gl.drawingBufferHeight;
    const fresh = !this.valid || !this.sameView(w, h, camera);
    if (fresh) {
      if (!this.target || this.target.width !== w || this.target.height !== h) this.makeTarget(w, h);
      this.fill(scene, camera);
    }
    this.blit(w, h);
    // The first copy into the canvas of a new buffer says whether the browser allows it (one
    // synchronous query per camera change, none per slider frame).
    if (fresh && gl.getError() !== gl.NO_ERROR) {
      this.stencilChoices.shift();
      this.valid = false;
      if (this.stencilChoices.length === 0) {
        this.enabled = false;
        this.dispose();
        return false;
      }
      this.makeTarget(w, h);
      return this.draw(scene, camera);
    }
    this.valid = true;
    const autoClear = r.autoClear;
    r.autoClear = false;
    camera.layers.disable(STATIC_LAYER);
    r.render(scene, camera);
    camera.layers.enable(STATIC_LAYER);
    r.autoClear = autoClear;
    return true;
  }

  /** Forget the cached picture (what the static objects show has changed). */
  invalidate() {
    this.valid = false;
  }

  /** Is the view (buffer size, camera) the cached one? Remembers it either way. */
  sameView(w, h, camera) {
    const k = this.key;
    let same = k[0] === w && k[1] === h;
    k[0] = w;
    k[1] = h;
    const m = camera.matrixWorld.elements;
    const p = camera.projectionMatrix.elements;
    for (let i = 0; i < 16; i++) {
      same = same && k[2 + i] === m[i] && k[18 + i] === p[i];
      k[2 + i] = m[i];
      k[18 + i] = p[i];
    }
    return same;
  }

  makeTarget(w, h) {
    this.dispose();
    this.target = new THREE.WebGLRenderTarget(w, h, { depthBuffer: true, stencilBuffer: this.stencilChoices[0] });
  }

  dispose() {
    if (this.target) this.target.dispose();
    this.target = null;
  }

  /** The static objects alone into the offscreen buffer. The surface shader writes sRGB itself
   *  (shading.js), so the buffer holds the canvas' values; the clear colour is given as those
   *  values too (three.js clears an offscreen buffer with linear values). */
  fill(scene, camera) {
    const r = this.renderer;
    const clear = r.getClearColor(new THREE.Color());
    const alpha = r.getClearAlpha();
    const srgb = new THREE.Color(this.background).getRGB({ r: 0, g: 0, b: 0 }, THREE.SRGBColorSpace);
    r.setClearColor(new THREE.Color(srgb.r, srgb.g, srgb.b), alpha);
    r.setRenderTarget(this.target);
    const mask = camera.layers.mask;
    camera.layers.set(STATIC_LAYER);
    r.render(scene, camera);
    camera.layers.mask = mask;
    r.setRenderTarget(null);
    r.setClearColor(clear, alpha);
  }

  blit(w, h) {
    const r = this.renderer;
    const gl = r.getContext();
    // three.js has no call that copies depth into the canvas: the framebuffer is its internal one.
    const fb = r.properties.get(this.target).__webglFramebuffer;
    gl.bindFramebuffer(gl.READ_FRAMEBUFFER, fb);
    gl.bindFramebuffer(gl.DRAW_FRAMEBUFFER, null);
    gl.blitFramebuffer(0, 0, w, h, 0, 0, w, h, gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT, gl.NEAREST);
    gl.bindFramebuffer(gl.READ_FRAMEBUFFER, null);
    r.resetState();
  }
}
