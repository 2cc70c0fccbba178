// report.html's page logic (docs/report-page.md): the face and skull before and after, the
// displacement colour map, report.json's figures and warnings, and per-segment sliders that re-plan
// live from the plan basis. Data come from the <script id="facesim-data"> JSON that facesim writes
// (arrays as base64 little-endian float32 / uint32 / uint8). Frame: LPS, millimetres.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { planMatrix, predictFace, moveRigid, interleaveColumns } from "./plan.js";
import { viridis } from "./viridis.js";
import { surfaceMaterial, setOpacity, viewUp } from "./shading.js";
import { vertexNormals, leadingVertexNormals } from "./normals.js";
import { orderSkull, reorder } from "./skull_order.js";
import { StaticCache, STATIC_LAYER } from "./frame_cache.js";
import { placeLandmarks, regionStats } from "./landmarks.js";

// While a slider or the view is being dragged the scene is drawn at this pixel ratio (a quarter
// of the pixels); DRAG_SETTLE_MS after the last move it is drawn once more at full resolution.
// facesim.options.dragPixelRatio = 1 draws every frame at full resolution (web/bench/rate.mjs).
const DRAG_PIXEL_RATIO = 0.5;
const DRAG_SETTLE_MS = 200;

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
  // Drawn: every triangle in vertex-cache order; while dragging, a simplified set over the same
  // vertices (report_page.rs: LOD_FRACTION of the triangles, < 0.5 mm from the full face).
  const faceDraw = data.face_draw ? u32(data.face_draw) : faceTris;
  const faceLod = data.face_lod ? u32(data.face_lod) : faceDraw;
  const n = facePre.length / 3;
  const basis = data.basis
    ? {
        label: data.basis.label,
        segments: data.basis.segments.map((s) => ({
          name: s.name,
          pivot: s.pivot,
          runPlan: { translate: s.translate, rotate_deg: s.rotate_deg },
          columns: interleaveColumns(f32(s.columns), 3 * n),
        })),
      }
    : null;
  // The basis segment of each of the case's segments (−1: not in the basis, never moves).
  const basisOf = data.segments.map((name) => (basis ? basis.segments.findIndex((s) => s.name === name) : -1));
  const skullSegmentRaw = decode(data.skull_segment, Uint8Array);
  const skull = orderSkull(skullSegmentRaw, (seg) => seg < basisOf.length && basisOf[seg] >= 0, u32(data.skull_triangles));
  const skullTris = new Uint32Array(skull.movingTris.length + skull.staticTris.length);
  skullTris.set(skull.movingTris);
  skullTris.set(skull.staticTris, skull.movingTris.length);
  const skullPre = reorder(f32(data.skull_pre), skull.order, 3);
  const skullPost = reorder(f32(data.skull_post), skull.order, 3);
  const skullSegment = reorder(skullSegmentRaw, skull.order, 1);

  // ---- layout ----
  const side = document.getElementById("side");
  const view = document.getElementById("view");
  side.appendChild(el("h1", {}, data.title));
  const model = el("p", { class: "model" }, `model: ${data.model}`);
  side.appendChild(model);

  // ---- three.js scene ----
  const BACKGROUND = 0xf4f4f4;
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setClearColor(BACKGROUND);
  view.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(30, 1, 1, 5000);
  camera.layers.enable(STATIC_LAYER);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.2);
  camera.add(sun);
  sun.position.set(0.3, 0.5, 1);
  scene.add(camera);

  const meshOf = (positions, tris, material) => {
    const g = new THREE.BufferGeometry();
    const pos = new Float32Array(positions);
    const normals = new Float32Array(pos.length);
    vertexNormals(pos, tris, normals);
    g.setAttribute("position", new THREE.BufferAttribute(pos, 3));
    g.setAttribute("normal", new THREE.BufferAttribute(normals, 3));
    g.setIndex(new THREE.BufferAttribute(tris, 1));
    const m = new THREE.Mesh(g, material);
    scene.add(m);
    return m;
  };
  const colours = new Float32Array(3 * n);
  const faceMaterial = surfaceMaterial({ perVertex: true });
  const faceAfter = meshOf(facePost, faceTris, faceMaterial);
  const faceIndexFull = new THREE.BufferAttribute(faceDraw, 1);
  const faceIndexLod = new THREE.BufferAttribute(faceLod, 1);
  faceAfter.geometry.setIndex(faceIndexFull);
  faceAfter.geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
  const skinMaterial = surfaceMaterial({ colour: 0xd9b38c });
  const faceBefore = meshOf(facePre, faceTris, skinMaterial);
  const ghost = new THREE.MeshBasicMaterial({ color: 0x333333, wireframe: true, transparent: true, opacity: 0.25 });
  const faceOverlay = new THREE.Mesh(faceBefore.geometry, ghost);
  scene.add(faceOverlay);
  const boneMaterial = surfaceMaterial({ colour: 0xeeeadd });
  const skullBefore = meshOf(skullPre, skullTris, boneMaterial);
  // The skull after: one set of vertex buffers, drawn as the triangles a plan moves or shades
  // differently and the static rest (cached while a slider is dragged: frame_cache.js).
  const skullAfter = meshOf(skullPost, skullTris, boneMaterial);
  scene.remove(skullAfter);
  const skullPart = (tris, layer) => {
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", skullAfter.geometry.getAttribute("position"));
    g.setAttribute("normal", skullAfter.geometry.getAttribute("normal"));
    g.setIndex(new THREE.BufferAttribute(tris, 1));
    const m = new THREE.Mesh(g, boneMaterial);
    m.layers.set(layer);
    scene.add(m);
    return m;
  };
  const skullMoving = skullPart(skull.movingTris, 0);
  const skullStatic = skullPart(skull.staticTris, STATIC_LAYER);
  const cache = new StaticCache(renderer, BACKGROUND);

  // Landmarks: small spheres drawn over everything (they sit on the skin, often under the face
  // seen through), soft tissue red, bone blue; moved with every plan.
  const landmarks = data.landmarks || [];
  const landmarkPre = new Float64Array(3 * landmarks.length);
  landmarks.forEach((l, i) => landmarkPre.set(l.pre, 3 * i));
  const landmarkNow = new Float64Array(3 * landmarks.length);
  const markers = new THREE.InstancedMesh(
    new THREE.SphereGeometry(1.3, 12, 8),
    new THREE.MeshBasicMaterial({ depthTest: false, transparent: true }),
    Math.max(landmarks.length, 1),
  );
  markers.count = landmarks.length;
  markers.renderOrder = 10;
  landmarks.forEach((l, i) => markers.setColorAt(i, new THREE.Color(l.anchor ? 0xd62728 : 0x1f4eb4)));
  scene.add(markers);
  const markerMatrix = new THREE.Matrix4();
  function showMarkers(points) {
    for (let i = 0; i < landmarks.length; i++) {
      markerMatrix.makeTranslation(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
      markers.setMatrixAt(i, markerMatrix);
    }
    markers.instanceMatrix.needsUpdate = true;
  }

  // Look at the face from the front: LPS −y is anterior, +z superior.
  const box = new THREE.Box3().setFromBufferAttribute(faceBefore.geometry.getAttribute("position"));
  const centre = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3()).length();
  camera.up.set(0, 0, 1);
  camera.position.set(centre.x, centre.y - 2.2 * size, centre.z);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  controls.update();

  // ---- state: the current face (the after-mesh's vertex buffer), colours, what is shown ----
  const facePosition = faceAfter.geometry.getAttribute("position");
  const faceNormal = faceAfter.geometry.getAttribute("normal");
  const faceColour = faceAfter.geometry.getAttribute("color");
  const current = facePosition.array;
  const state = { mode: "after", skull: true, colour: true, landmarks: true, colourBy: "displacement" };
  const scaleTitle = el("span");
  const scaleLabel = el("span", { class: "max" });
  // Viridis sampled finely once (linear in the colour attribute as before: value / 255).
  const LUT_STEPS = 1024;
  const lut = new Float32Array(3 * (LUT_STEPS + 1));
  for (let i = 0; i <= LUT_STEPS; i++) viridis(i / LUT_STEPS).forEach((c, k) => (lut[3 * i + k] = c / 255));
  const skin = [217 / 255, 179 / 255, 140 / 255];
  const dist = new Float32Array(n);
  // With [uncertainty] samples: the band's width p95 − p05 per vertex (the run's plan).
  const bandWidth = data.band_width ? f32(data.band_width) : null;

  /** Colours, normals and the scale of the face in `current`; marks the buffers for upload. */
  function refreshFace() {
    let dmax = 0;
    for (let v = 0, p = 0; v < n; v++, p += 3) {
      const dx = current[p] - facePre[p];
      const dy = current[p + 1] - facePre[p + 1];
      const dz = current[p + 2] - facePre[p + 2];
      const d = Math.sqrt(dx * dx + dy * dy + dz * dz);
      dist[v] = d;
      if (d > dmax) dmax = d;
    }
    const shown = state.colourBy === "band" && bandWidth ? bandWidth : dist;
    let smax = shown === dist ? dmax : 0;
    if (shown !== dist) for (let v = 0; v < n; v++) smax = Math.max(smax, shown[v]);
    const scale = smax > 0 ? LUT_STEPS / smax : 0;
    for (let v = 0, p = 0; v < n; v++, p += 3) {
      if (state.colour) {
        const q = 3 * Math.round(shown[v] * scale);
        colours[p] = lut[q];
        colours[p + 1] = lut[q + 1];
        colours[p + 2] = lut[q + 2];
      } else {
        colours[p] = skin[0];
        colours[p + 1] = skin[1];
        colours[p + 2] = skin[2];
      }
    }
    vertexNormals(current, faceTris, faceNormal.array);
    facePosition.needsUpdate = true;
    faceNormal.needsUpdate = true;
    faceColour.needsUpdate = true;
    scaleLabel.textContent = `${smax.toFixed(2)} mm`;
    scaleTitle.textContent = shown === dist ? "displacement |x_post − x_pre|" : "uncertainty band width p95 − p05 (the run's plan)";
  }

  // The skull after a plan: only the leading range of movable vertices is rewritten and uploaded
  // (skull_order.js), with the normals of the vertices around them.
  const skullPosition = skullAfter.geometry.getAttribute("position");
  const skullNormal = skullAfter.geometry.getAttribute("normal");
  const mats = basisOf.map(() => new Float64Array(12));
  const segmentMats = basisOf.map(() => null);
  // The run's skull_post also moves segments that are not in the basis; a plan leaves them where
  // they were before. Switching between the two rewrites the whole skull.
  let skullIsRun = true;
  function refreshSkull(plan) {
    if (!plan) {
      skullPosition.array.set(skullPost);
      vertexNormals(skullPosition.array, skullTris, skullNormal.array);
    } else {
      basisOf.forEach((i, seg) => {
        segmentMats[seg] = i < 0 ? null : planMatrix(plan[basis.segments[i].name], basis.segments[i].pivot, mats[seg]);
      });
      if (skullIsRun) {
        moveRigid(skullPre, skullSegment, segmentMats, skullPosition.array);
        vertexNormals(skullPosition.array, skullTris, skullNormal.array);
      } else {
        moveRigid(skullPre, skullSegment, segmentMats, skullPosition.array, skull.moved);
        leadingVertexNormals(skullPosition.array, skull.movingTris, skull.dirty, skullNormal.array);
        skullPosition.addUpdateRange(0, 3 * skull.moved);
        skullNormal.addUpdateRange(0, 3 * skull.dirty);
      }
    }
    refreshLandmarks(plan);
    if (skullIsRun !== !plan) cache.invalidate();
    skullIsRun = !plan;
    skullPosition.needsUpdate = true;
    skullNormal.needsUpdate = true;
  }

  // The landmarks after: the run's own (as report.json has them) or carried with a plan: soft
  // ones on the face shown, bony ones moved as the skull.
  function refreshLandmarks(plan) {
    if (plan) placeLandmarks(landmarks, faceTris, current, segmentMats, landmarkNow);
    else landmarks.forEach((l, i) => landmarkNow.set(l.post, 3 * i));
    showMarkers(state.mode === "before" ? landmarkPre : landmarkNow);
  }

  function showState() {
    const after = state.mode !== "before";
    faceAfter.visible = after;
    faceBefore.visible = state.mode === "before";
    faceOverlay.visible = state.mode === "overlay";
    skullBefore.visible = state.skull && !after;
    skullMoving.visible = skullStatic.visible = state.skull && after;
    markers.visible = state.landmarks && landmarks.length > 0;
    showMarkers(after ? landmarkNow : landmarkPre);
    // The skull shows through the face; the skull itself is always opaque.
    for (const m of [faceMaterial, skinMaterial]) setOpacity(m, state.skull ? 0.55 : 1);
    cache.invalidate();
  }

  // ---- drawing: on demand, at most once an animation frame; coarser while dragging ----
  const options = { dragPixelRatio: DRAG_PIXEL_RATIO, cache: true, lod: true };
  const drawnAt = { w: 0, h: 0, ratio: 0 };
  /** Draw now, at full resolution or (`dragging`) at options.dragPixelRatio; `cached`: the
   *  camera stands still (a slider frame), the static skull may come from the cache. */
  function draw(dragging, cached = false) {
    const w = view.clientWidth;
    const h = view.clientHeight;
    const ratio = dragging ? options.dragPixelRatio : 1;
    if (drawnAt.w !== w || drawnAt.h !== h || drawnAt.ratio !== ratio) {
      Object.assign(drawnAt, { w, h, ratio });
      renderer.setPixelRatio(ratio);
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
    }
    faceAfter.geometry.setIndex(dragging && options.lod ? faceIndexLod : faceIndexFull);
    viewUp(camera);
    if (cached && options.cache && skullStatic.visible && cache.draw(scene, camera)) return;
    renderer.render(scene, camera);
  }
  const render = () => draw(false);
  let settle = 0;
  /** A frame drawn while dragging (`slider`: a slider, not the view); the full-resolution one
   *  follows when the dragging stops. */
  function dragFrame(slider) {
    draw(true, slider);
    clearTimeout(settle);
    settle = setTimeout(() => {
      refreshTables();
      render();
    }, DRAG_SETTLE_MS);
  }
  let frameWanted = false;
  let sliderMoved = false;
  function requestFrame() {
    if (frameWanted) return;
    frameWanted = true;
    requestAnimationFrame(() => {
      frameWanted = false;
      // However many slider events came since the last frame, the face is re-planned once.
      const slider = sliderMoved;
      if (slider) {
        sliderMoved = false;
        applyPlan(sliderPlan());
      }
      dragFrame(slider);
    });
  }
  controls.addEventListener("change", requestFrame);
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
  modes.append(toggle("skull", "skull"), toggle("displacement colours", "colour"), toggle("landmarks", "landmarks"));
  side.appendChild(modes);

  const bar = el("div", { class: "scale" });
  const ramp = el("div", { class: "ramp" });
  const stops = [];
  for (let i = 0; i <= 8; i++) stops.push(`rgb(${viridis(i / 8).join(",")}) ${(i / 8) * 100}%`);
  ramp.style.background = `linear-gradient(to right, ${stops.join(",")})`;
  bar.append(scaleTitle, ramp, el("span", { class: "min" }, "0 mm"), scaleLabel);
  side.appendChild(bar);
  if (bandWidth) {
    const l = el("label");
    const c = el("input", { type: "checkbox", id: "band" });
    c.addEventListener("change", () => {
      state.colourBy = c.checked ? "band" : "displacement";
      refreshFace();
      showState();
      render();
    });
    l.append(c, " colour by the uncertainty band (p95 − p05)");
    side.appendChild(l);
  }

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
          sliderMoved = true;
          requestFrame();
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
      sliderMoved = false;
      current.set(facePost);
      refreshFace();
      refreshSkull(null);
      refreshTables();
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

  // ---- landmarks, regions and measurements ----
  const regionNames = data.region_names || [];
  const regionOf = data.region_of ? decode(data.region_of, Uint8Array) : new Uint8Array(0);
  const fmt = (v, d = 2) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));
  const table = (head) => {
    const t = el("table", { class: "figures" });
    const tr = el("tr");
    for (const h of head) tr.appendChild(el("th", {}, h));
    t.appendChild(tr);
    return t;
  };
  const row = (t, cells, title) => {
    const tr = el("tr", title ? { title } : {});
    cells.forEach((c, i) => tr.appendChild(el(i === 0 ? "th" : "td", {}, c)));
    t.appendChild(tr);
  };
  const landmarkTable = table(["landmark", "moves (mm)"]);
  const regionTable = table(["region", "vertices", "mean", "p90", "max (mm)"]);
  /** The live tables: each landmark's move and each region's displacement for the face shown. */
  function refreshTables() {
    while (landmarkTable.rows.length > 1) landmarkTable.deleteRow(1);
    landmarks.forEach((l, i) => {
      let d = 0;
      for (let k = 0; k < 3; k++) d += (landmarkNow[3 * i + k] - landmarkPre[3 * i + k]) ** 2;
      row(landmarkTable, [l.label, fmt(Math.sqrt(d))]);
    });
    for (const [label, why] of data.missing_landmarks || []) row(landmarkTable, [label, "missing"], why);
    while (regionTable.rows.length > 1) regionTable.deleteRow(1);
    const stats = regionStats(regionNames, regionOf, dist);
    for (const name of regionNames) {
      const r = stats[name];
      row(regionTable, r ? [name, String(r.vertices), fmt(r.mean), fmt(r.p90), fmt(r.max)] : [name, "absent", "", "", ""]);
    }
  }
  side.appendChild(el("h2", {}, "landmarks (live)"));
  side.appendChild(landmarkTable);
  side.appendChild(el("h2", {}, "regions: displacement (live)"));
  side.appendChild(regionTable);
  const measures = Object.entries(data.measurements || {});
  const ratios = Object.entries(data.ratios || {});
  if (measures.length + ratios.length > 0) {
    side.appendChild(el("h2", {}, "measurements (the run's plan)"));
    const mt = table(["", "before", "after", "change"]);
    for (const [name, m] of measures)
      row(mt, [`${name} (${m.unit})`, fmt(m.before, 1), fmt(m.after, 1), fmt(m.change, 1)], m.missing || m.definition);
    for (const [name, r] of ratios) row(mt, [`${name} soft/hard`, fmt(r.soft_mm), fmt(r.hard_mm), fmt(r.ratio)], r.missing || "soft-tissue move / bone move (mm, ratio)");
    side.appendChild(mt);
  }

  // ---- the plan held against the clinic: published soft/hard ratios of its surgery type ----
  const clinic = data.published;
  if (clinic) {
    side.appendChild(el("h2", {}, `against the clinic${clinic.title ? `: ${clinic.title}` : ""}`));
    side.appendChild(el("p", { class: "clinic-reading" }, clinic.surgery
      ? `Soft/hard ratios published for this surgery type (the spread of study means; hover a row for its source). The plan: ${clinic.reading}.`
      : `No published ratios for this plan: ${clinic.reading}.`));
    if ((clinic.rows || []).length > 0) {
      const ct = table(["", "predicted", "published", ""]);
      ct.classList.add("clinic");
      for (const r of clinic.rows) {
        const verdict = r.inside === true ? "inside" : r.inside === false ? "outside" : "not measured";
        const notes = [r.missing, `hard: ${r.hard}${r.hard_at ? ` (taken at ${r.hard_at})` : ""}`, r.range_note, r.source].filter(Boolean);
        row(ct, [`${r.soft}${r.axis === "vertical" ? " (vertical)" : ""}`, fmt(r.predicted), `${fmt(r.low)}–${fmt(r.high)}`, verdict], notes.join("; "));
        ct.lastChild.classList.add(r.inside === false ? "outside" : r.inside === true ? "inside" : "unmeasured");
      }
      side.appendChild(ct);
    }
  }

  const u = data.uncertainty;
  if (u && u.samples > 0) {
    side.appendChild(el("h2", {}, `uncertainty: ${u.samples} samples (the run's plan)`));
    side.appendChild(el("p", {}, "displacement (mm): mean [5 %, 95 %] over tissue parameters drawn from their literature ranges"));
    const ut = table(["", "mean", "5 %", "95 %"]);
    for (const [k, b] of Object.entries(u.landmarks || {})) row(ut, [k, fmt(b.mean), fmt(b.p05), fmt(b.p95)]);
    for (const [k, b] of Object.entries(u.regions || {})) if (b) row(ut, [k, fmt(b.mean), fmt(b.p05), fmt(b.p95)]);
    side.appendChild(ut);
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
     *  does not move. Applied and drawn before it returns, as a slider move is: at the dragging
     *  resolution, the full one following when no further plan comes for DRAG_SETTLE_MS. */
    setPlan(p) {
      if (!basis) throw new Error(data.no_basis_reason || "report.html: no plan basis");
      for (const name of Object.keys(p))
        if (!basis.segments.some((s) => s.name === name)) throw new Error(`report.html: the plan names an unknown segment '${name}'`);
      setSliders(p);
      sliderMoved = false;
      applyPlan(p);
      dragFrame(true);
    },
    /** The predicted face: LPS mm, flat [x0, y0, z0, x1, …], face_post order. */
    faceVertices() {
      return Array.from(current);
    },
    /** The landmarks on the face shown: label → [x, y, z] (LPS mm), as `facesim replan` carries
     *  the run's landmarks. */
    landmarks() {
      const out = {};
      landmarks.forEach((l, i) => (out[l.label] = Array.from(landmarkNow.subarray(3 * i, 3 * i + 3))));
      return out;
    },
    /** Per present facial region: {vertices, mean, p90, max} of the displacement shown (mm). */
    regions() {
      return regionStats(regionNames, regionOf, dist);
    },
    /** Draw the scene now at full resolution (benchmarks time it). */
    render,
    /** dragPixelRatio: the pixel ratio of frames drawn while dragging (1: always full). */
    options,
    /** How many segments and face vertices the page holds (for tests and benchmarks). */
    info() {
      return {
        vertices: n,
        segments: basis ? basis.segments.map((s) => s.name) : [],
        basis: basis ? basis.label : null,
        // Whether slider frames draw the static skull from the cache (frame_cache.js).
        frame_cache: cache.enabled,
      };
    },
  };

  refreshFace();
  refreshLandmarks(null);
  showState();
  refreshTables();
  render();
  document.body.dataset.ready = "1";
}

main();
