// report.html's page logic (docs/report-page.md): the face and skull before and after, the
// displacement colour map, report.json's figures and warnings, and per-segment sliders that re-plan
// live from the plan basis. Data come from the <script id="facesim-data"> JSON that facesim writes
// (arrays as base64 little-endian float32 / uint32 / uint8). Frame: LPS, millimetres.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { planMatrix, predictFace, moveRigid } from "./plan.js";
import { viridis } from "./viridis.js";

function decode(b64, Type) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}
const f32 = (b64) => decode(b64, Float32Array);
const u32 = (b64) => decode(b64, Uint32Array);

const el = (tag, attrs = {}, text) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
};

function main() {
  const data = JSON.parse(document.getElementById("facesim-data").textContent);
  const facePre = f32(data.face_pre);
  const facePost = f32(data.face_post);
  const faceTris = u32(data.face_triangles);
  const skullPre = f32(data.skull_pre);
  const skullPost = f32(data.skull_post);
  const skullTris = u32(data.skull_triangles);
  const skullSegment = decode(data.skull_segment, Uint8Array);
  const n = facePre.length / 3;
  const basis = data.basis
    ? {
        label: data.basis.label,
        segments: data.basis.segments.map((s) => ({
          name: s.name,
          pivot: s.pivot,
          runPlan: { translate: s.translate, rotate_deg: s.rotate_deg },
          columns: f32(s.columns),
        })),
      }
    : null;

  // ---- layout ----
  const side = document.getElementById("side");
  const view = document.getElementById("view");
  side.appendChild(el("h1", {}, data.title));
  const model = el("p", { class: "model" }, `model: ${data.model}`);
  side.appendChild(model);

  // ---- three.js scene ----
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setClearColor(0xf4f4f4);
  view.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(30, 1, 1, 5000);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.2);
  camera.add(sun);
  sun.position.set(0.3, 0.5, 1);
  scene.add(camera);

  const meshOf = (positions, tris, material) => {
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(positions), 3));
    g.setIndex(new THREE.BufferAttribute(tris, 1));
    g.computeVertexNormals();
    const m = new THREE.Mesh(g, material);
    scene.add(m);
    return m;
  };
  const colours = new Float32Array(3 * n);
  const faceAfter = meshOf(facePost, faceTris, new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.8, side: THREE.DoubleSide }));
  faceAfter.geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
  const skinMaterial = new THREE.MeshStandardMaterial({ color: 0xd9b38c, roughness: 0.8, side: THREE.DoubleSide });
  const faceBefore = meshOf(facePre, faceTris, skinMaterial);
  const ghost = new THREE.MeshBasicMaterial({ color: 0x333333, wireframe: true, transparent: true, opacity: 0.25 });
  const faceOverlay = new THREE.Mesh(faceBefore.geometry, ghost);
  scene.add(faceOverlay);
  const boneMaterial = new THREE.MeshStandardMaterial({ color: 0xeeeadd, roughness: 0.6, side: THREE.DoubleSide });
  const skullBefore = meshOf(skullPre, skullTris, boneMaterial);
  const skullAfter = meshOf(skullPost, skullTris, boneMaterial);

  // Look at the face from the front: LPS −y is anterior, +z superior.
  const box = new THREE.Box3().setFromBufferAttribute(faceBefore.geometry.getAttribute("position"));
  const centre = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3()).length();
  camera.up.set(0, 0, 1);
  camera.position.set(centre.x, centre.y - 2.2 * size, centre.z);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  controls.update();

  // ---- state: the current face, colours, what is shown ----
  const current = Float64Array.from(facePost);
  const state = { mode: "after", skull: true, colour: true };
  let scaleMax = data.colour_scale_mm[1];
  const scaleLabel = el("span", { class: "max" });

  function refreshFace() {
    const pos = faceAfter.geometry.getAttribute("position");
    let dmax = 0;
    const dist = new Float64Array(n);
    for (let v = 0; v < n; v++) {
      const dx = current[3 * v] - facePre[3 * v];
      const dy = current[3 * v + 1] - facePre[3 * v + 1];
      const dz = current[3 * v + 2] - facePre[3 * v + 2];
      dist[v] = Math.sqrt(dx * dx + dy * dy + dz * dz);
      if (dist[v] > dmax) dmax = dist[v];
      pos.array[3 * v] = current[3 * v];
      pos.array[3 * v + 1] = current[3 * v + 1];
      pos.array[3 * v + 2] = current[3 * v + 2];
    }
    scaleMax = dmax;
    for (let v = 0; v < n; v++) {
      const c = state.colour ? viridis(dmax > 0 ? dist[v] / dmax : 0) : [217, 179, 140];
      colours[3 * v] = c[0] / 255;
      colours[3 * v + 1] = c[1] / 255;
      colours[3 * v + 2] = c[2] / 255;
    }
    pos.needsUpdate = true;
    faceAfter.geometry.getAttribute("color").needsUpdate = true;
    faceAfter.geometry.computeVertexNormals();
    scaleLabel.textContent = `${dmax.toFixed(2)} mm`;
  }

  function refreshSkull(plan) {
    const pos = skullAfter.geometry.getAttribute("position");
    if (!plan) {
      pos.array.set(skullPost);
    } else {
      const mats = basis.segments.map((s) => planMatrix(plan[s.name], s.pivot));
      const byName = data.segments.map((name) => basis.segments.findIndex((s) => s.name === name));
      moveRigid(skullPre, skullSegment, byName.map((i) => (i < 0 ? null : mats[i])), pos.array);
    }
    pos.needsUpdate = true;
    skullAfter.geometry.computeVertexNormals();
  }

  function showState() {
    const after = state.mode !== "before";
    faceAfter.visible = after;
    faceBefore.visible = state.mode === "before";
    faceOverlay.visible = state.mode === "overlay";
    skullBefore.visible = state.skull && !after;
    skullAfter.visible = state.skull && after;
    // The skull shows through the face.
    for (const m of [faceAfter.material, skinMaterial]) {
      m.transparent = state.skull;
      m.opacity = state.skull ? 0.55 : 1;
      m.depthWrite = !state.skull;
    }
  }

  function render() {
    const w = view.clientWidth;
    const h = view.clientHeight;
    const c = renderer.domElement;
    if (c.width !== w || c.height !== h) {
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
    }
    renderer.render(scene, camera);
  }
  controls.addEventListener("change", render);
  window.addEventListener("resize", render);

  // ---- controls panel ----
  const modes = el("fieldset");
  modes.appendChild(el("legend", {}, "face"));
  for (const [value, label] of [["before", "before"], ["after", "after"], ["overlay", "after + before (wire)"]]) {
    const l = el("label");
    const r = el("input", { type: "radio", name: "mode", value });
    if (value === state.mode) r.checked = true;
    r.addEventListener("change", () => {
      state.mode = value;
      showState();
      render();
    });
    l.append(r, ` ${label}`);
    modes.appendChild(l);
  }
  const toggle = (label, key) => {
    const l = el("label");
    const c = el("input", { type: "checkbox" });
    c.checked = state[key];
    c.addEventListener("change", () => {
      state[key] = c.checked;
      if (key === "colour") refreshFace();
      showState();
      render();
    });
    l.append(c, ` ${label}`);
    return l;
  };
  modes.append(toggle("skull", "skull"), toggle("displacement colours", "colour"));
  side.appendChild(modes);

  const bar = el("div", { class: "scale" });
  const ramp = el("div", { class: "ramp" });
  const stops = [];
  for (let i = 0; i <= 8; i++) stops.push(`rgb(${viridis(i / 8).join(",")}) ${(i / 8) * 100}%`);
  ramp.style.background = `linear-gradient(to right, ${stops.join(",")})`;
  bar.append(el("span", {}, "displacement |x_post − x_pre|"), ramp, el("span", { class: "min" }, "0 mm"), scaleLabel);
  side.appendChild(bar);

  // ---- sliders ----
  const planBox = el("fieldset", { id: "plan" });
  planBox.appendChild(el("legend", {}, "plan"));
  const sliders = new Map();
  let plan = null;
  if (!basis) {
    planBox.appendChild(el("p", { class: "why" }, data.no_basis_reason || "This output directory has no plan basis, so the page cannot re-plan."));
  } else {
    planBox.appendChild(el("p", { class: "label" }, basis.label));
    for (const s of basis.segments) {
      planBox.appendChild(el("h3", {}, s.name));
      const put = (key, i, label, unit) => {
        const l = el("label", { class: "slider" });
        const value = s.runPlan[key][i];
        const lim = Math.max(unit === "mm" ? 15 : 20, Math.ceil(Math.abs(value)));
        const r = el("input", { type: "range", min: -lim, max: lim, step: 0.1, value: String(value) });
        r.dataset.segment = s.name;
        const out = el("output", {}, `${value.toFixed(1)} ${unit}`);
        r.addEventListener("input", () => {
          out.textContent = `${Number(r.value).toFixed(1)} ${unit}`;
          applyPlan(sliderPlan());
          render();
        });
        l.append(`${label} `, r, out);
        planBox.appendChild(l);
        sliders.set(`${s.name}/${key}/${i}`, { r, out, unit });
      };
      ["x", "y", "z"].forEach((a, i) => put("translate", i, `move ${a}`, "mm"));
      ["x", "y", "z"].forEach((a, i) => put("rotate_deg", i, `turn ${a}`, "°"));
    }
    const reset = el("button", {}, "the run's plan");
    reset.addEventListener("click", () => {
      const p = {};
      for (const s of basis.segments) p[s.name] = s.runPlan;
      setSliders(p);
      plan = null;
      current.set(facePost);
      refreshFace();
      refreshSkull(null);
      render();
    });
    planBox.appendChild(reset);
  }
  side.appendChild(planBox);

  function sliderPlan() {
    const p = {};
    for (const s of basis.segments) {
      const get = (key, i) => Number(sliders.get(`${s.name}/${key}/${i}`).r.value);
      p[s.name] = { translate: [0, 1, 2].map((i) => get("translate", i)), rotate_deg: [0, 1, 2].map((i) => get("rotate_deg", i)) };
    }
    return p;
  }
  function setSliders(p) {
    for (const s of basis.segments) {
      const seg = p[s.name] || { translate: [0, 0, 0], rotate_deg: [0, 0, 0] };
      for (const key of ["translate", "rotate_deg"])
        for (let i = 0; i < 3; i++) {
          const { r, out, unit } = sliders.get(`${s.name}/${key}/${i}`);
          const v = (seg[key] || [0, 0, 0])[i];
          // A plan beyond the slider's range widens it, so the sliders keep the plan exactly.
          if (Math.abs(v) > Number(r.max)) {
            r.max = String(Math.ceil(Math.abs(v)));
            r.min = String(-Math.ceil(Math.abs(v)));
          }
          r.value = String(v);
          out.textContent = `${Number(v).toFixed(1)} ${unit}`;
        }
    }
  }
  function applyPlan(p) {
    plan = p;
    predictFace(facePre, basis.segments, p, current);
    refreshFace();
    refreshSkull(p);
  }

  // ---- figures and warnings of report.json ----
  const figs = el("table", { class: "figures" });
  for (const [k, v] of data.figures) {
    const tr = el("tr");
    tr.append(el("th", {}, k), el("td", {}, v));
    figs.appendChild(tr);
  }
  side.appendChild(el("h2", {}, "figures"));
  side.appendChild(figs);
  side.appendChild(el("h2", {}, `warnings (${data.warnings.length})`));
  const ul = el("ul", { class: "warnings" });
  for (const w of data.warnings) ul.appendChild(el("li", {}, w));
  side.appendChild(ul);

  // ---- automation API (docs/report-page.md) ----
  window.facesim = {
    /** Re-plan: segment name → {translate: [x,y,z] mm, rotate_deg: [rx,ry,rz]}; a segment left out
     *  does not move. Applied (and rendered) before it returns. */
    setPlan(p) {
      if (!basis) throw new Error(data.no_basis_reason || "report.html: no plan basis");
      for (const name of Object.keys(p))
        if (!basis.segments.some((s) => s.name === name)) throw new Error(`report.html: the plan names an unknown segment '${name}'`);
      setSliders(p);
      applyPlan(p);
      render();
    },
    /** The predicted face: LPS mm, flat [x0, y0, z0, x1, …], face_post order. */
    faceVertices() {
      return Array.from(current);
    },
    /** Draw the scene now (benchmarks time it). */
    render,
    /** How many segments and face vertices the page holds (for tests and benchmarks). */
    info() {
      return { vertices: n, segments: basis ? basis.segments.map((s) => s.name) : [], basis: basis ? basis.label : null };
    },
  };

  refreshFace();
  showState();
  render();
  document.body.dataset.ready = "1";
}

main();
