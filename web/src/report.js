// report.html's page logic (docs/guide/report-page.md): the face before and after, lit and opaque, in
// the head's views (profile by default); the midsagittal profile tracing; landmark labels; the
// displacement colour map with its legend in mm; per-segment sliders that re-plan live from the
// plan basis; tables; PNG export and a one-page print layout. Data come from the
// <script id="facesim-data"> JSON that facesim writes (arrays as base64 little-endian float32 /
// uint32 / uint8). Frame: LPS, millimetres.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { planMatrix, predictFace, moveRigid, interleaveColumns, clinicalMove, readBack } from "./plan.js";
import { viridis } from "./viridis.js";
import { surfaceMaterial, setOpacity, viewUp, setHeadUp } from "./shading.js";
import { vertexNormals, leadingVertexNormals } from "./normals.js";
import { orderSkull, reorder } from "./skull_order.js";
import { StaticCache, STATIC_LAYER } from "./frame_cache.js";
import { placeLandmarks, regionStats } from "./landmarks.js";
import { midsagittalCut, facialPart, pathData } from "./profile.js";
import { STYLE } from "./style.js";
import { materials, theta as thetaOf, outside, solveOnline, outputBound, landmarkBound, unpackDual, reducedFace, rangeAt, rangeFraction, rangeWith } from "./tissue.js";

// While a slider or the view is being dragged the scene is drawn at this pixel ratio (a quarter
// of the pixels); DRAG_SETTLE_MS after the last move it is drawn once more at full resolution.
// facesim.options.dragPixelRatio = 1 draws every frame at full resolution (web/bench/rate.mjs).
const DRAG_PIXEL_RATIO = 0.5;
const DRAG_SETTLE_MS = 200;
// The views keep this much of the picture (CSS px) free at its left and right edges for the
// landmark labels (a label sits 6 px beside its marker and is up to ~40 px wide).
const LABEL_ROOM_PX = 56;
const BACKGROUND = 0xf4f4f4;
const SKIN = 0xd9a98c;
// The face's opacity with the skull seen through it.
const SEE_THROUGH = 0.5;

function decode(b64, Type) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}
const f32 = (b64) => decode(b64, Float32Array);
const u32 = (b64) => decode(b64, Uint32Array);
const f64 = (b64) => decode(b64, Float64Array);

const el = (tag, attrs = {}, text) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
};
const SVG_NS = "http://www.w3.org/2000/svg";
const svgEl = (tag, attrs = {}, text) => {
  const e = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
};

// The views: where the camera stands, seen from the head's middle, in the head frame. The
// profiles look at the patient's side; "profile" alone is the right one (face to the picture's
// right, as a cephalometric tracing is drawn). Keys 1–4 on the picture choose them.
const VIEWS = [
  ["front", "front", (f) => f.front.clone()],
  ["profile-right", "profile right", (f) => f.left.clone().negate()],
  ["profile-left", "profile left", (f) => f.left.clone()],
  ["three-quarter", "three-quarter", (f) => f.front.clone().sub(f.left).normalize()],
];
const VIEW_TEXT = {
  front: "from the front",
  "profile-right": "in profile from the patient's right",
  "profile-left": "in profile from the patient's left",
  "three-quarter": "in three-quarter view from the patient's front right",
};
// The plan's sliders per segment: [key, label, unit, tooltip]. Clinical: docs/guide/planning.md
// "Signs"; LPS: [translate | rotate_deg, axis index].
const SLIDER_KEYS = {
  clinical: [
    ["advance_mm", "advance", "mm", "forward (+) or back (−, setback) along the clinical frame's forward axis"],
    ["up_mm", "up", "mm", "up (+, impaction) or down (−)"],
    ["left_mm", "left", "mm", "toward the patient's left (+)"],
    ["pitch_deg", "pitch", "°", "about the left axis through the pivot: + turns the front down"],
    ["roll_deg", "roll", "°", "about the forward axis through the pivot: + raises the patient's left side"],
    ["yaw_deg", "yaw", "°", "about the up axis through the pivot: + turns the front toward the patient's left"],
  ],
  lps: [
    [["translate", 0], "move x", "mm", "along LPS x (the patient's left)"],
    [["translate", 1], "move y", "mm", "along LPS y (the back of the head)"],
    [["translate", 2], "move z", "mm", "along LPS z (up)"],
    [["rotate_deg", 0], "turn x", "°", "about LPS x through the pivot (first)"],
    [["rotate_deg", 1], "turn y", "°", "about LPS y through the pivot (second)"],
    [["rotate_deg", 2], "turn z", "°", "about LPS z through the pivot (third)"],
  ],
};
/** A plan slider's value as shown: to 0.1, with its unit; no "−0.0" for a read-back round-off. */
const sliderText = (v, unit) => `${(Math.abs(v) < 0.05 ? 0 : Number(v)).toFixed(1)} ${unit}`;
const MODES = [
  ["before", "before"],
  ["after", "after"],
  ["both", "both"],
];

function main() {
  document.head.appendChild(el("style", {}, STYLE));
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
          // The run's move read in the clinical frame (null without one).
          runMoves: s.moves || null,
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
  // The head frame (report.json head_frame; the CT's axes when the run has none).
  const hf = data.head_frame || { origin: [0, 0, 0], front: [0, -1, 0], up: [0, 0, 1], left: [1, 0, 0], source: "the CT's axes" };
  const frame = {
    origin: new THREE.Vector3(...hf.origin),
    front: new THREE.Vector3(...hf.front).normalize(),
    up: new THREE.Vector3(...hf.up).normalize(),
    left: new THREE.Vector3(...hf.left).normalize(),
  };
  // The clinical frame (report.json clinical_frame): the plan's sliders are moves in it, and the
  // views stand in it, so that a pitched head is shown upright. Without one, the head frame.
  const cf = data.clinical_frame || null;
  const clinical = cf ? { forward: cf.forward, up: cf.up, left: cf.left } : null;
  const viewFrame = cf
    ? {
        origin: new THREE.Vector3(...cf.origin),
        front: new THREE.Vector3(...cf.forward).normalize(),
        up: new THREE.Vector3(...cf.up).normalize(),
        left: new THREE.Vector3(...cf.left).normalize(),
      }
    : frame;
  const viewSource = cf ? `the clinical frame (${cf.method})` : hf.source;
  setHeadUp(viewFrame.up);

  // ---- layout: controls and tables on the left; the picture, its toolbar, labels, legend and
  // the profile tracing on the right ----
  const side = document.getElementById("side");
  const view = document.getElementById("view");
  const mainBox = el("div", { id: "main" });
  view.replaceWith(mainBox);
  mainBox.appendChild(view);
  side.setAttribute("aria-label", "controls and tables");
  side.appendChild(el("h1", {}, data.title));
  side.appendChild(el("p", { class: "model" }, `model: ${data.model}`));

  // ---- three.js scene ----
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setClearColor(BACKGROUND);
  const canvas = renderer.domElement;
  canvas.setAttribute("role", "img");
  canvas.setAttribute("tabindex", "0");
  canvas.setAttribute("aria-describedby", "keys-hint");
  view.appendChild(canvas);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(24, 1, 1, 5000);
  camera.layers.enable(STATIC_LAYER);
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
  const faceMaterial = surfaceMaterial({ perVertex: true, shine: 0.6 });
  // While dragging (half resolution, simplified face) the skin is lit per vertex: the same light,
  // a fraction of the fragment work; the settled frame lights every pixel.
  const faceMaterialDrag = surfaceMaterial({ perVertex: true, shine: 0.6, vertexLit: true });
  const faceAfter = meshOf(facePost, faceTris, faceMaterial);
  const faceIndexFull = new THREE.BufferAttribute(faceDraw, 1);
  const faceIndexLod = new THREE.BufferAttribute(faceLod, 1);
  faceAfter.geometry.setIndex(faceIndexFull);
  faceAfter.geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
  const skinMaterial = surfaceMaterial({ colour: SKIN });
  const skinMaterialDrag = surfaceMaterial({ colour: SKIN, vertexLit: true });
  const faceBefore = meshOf(facePre, faceTris, skinMaterial);
  faceBefore.geometry.setIndex(faceIndexFull);
  // "both": the face after, opaque, over a translucent ghost of the face before — brighter where
  // the ghost is in front, fainter where it lies behind the face after (an advancement). Only the
  // skin's outer side, and each pass nudged in depth so that where the two faces coincide the
  // face after shows clean.
  const outward = outerSide(facePre, faceBefore.geometry.getAttribute("normal").array, frame);
  // The pass behind is weighted by how far the skin moved there (0 below 0.3 mm, full from 1 mm):
  // a fold of the face hidden by another fold (an ear, a nostril) is not a change.
  const ghostWeight = new Float32Array(n);
  faceBefore.geometry.setAttribute("weight", new THREE.BufferAttribute(ghostWeight, 1));
  const ghostMaterial = (opacity, depthFunc, offset) => {
    const m = surfaceMaterial({ colour: 0x4a6fa5, shine: 0, weighted: depthFunc === THREE.GreaterDepth });
    setOpacity(m, opacity);
    m.side = outward;
    m.depthFunc = depthFunc;
    m.polygonOffset = true;
    m.polygonOffsetFactor = offset;
    m.polygonOffsetUnits = 4 * offset;
    return m;
  };
  const ghostFront = new THREE.Mesh(faceBefore.geometry, ghostMaterial(0.5, THREE.LessEqualDepth, 1));
  const ghostBehind = new THREE.Mesh(faceBefore.geometry, ghostMaterial(0.28, THREE.GreaterDepth, -1));
  ghostFront.renderOrder = ghostBehind.renderOrder = 5;
  scene.add(ghostFront, ghostBehind);
  const boneMaterial = surfaceMaterial({ colour: 0xeeeadd, shine: 0.3, vertexLit: true });
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

  // Landmarks: small spheres, soft tissue red on the skin (hidden where the face covers them),
  // bone blue drawn over everything and shown only with the skull.
  const landmarks = data.landmarks || [];
  const landmarkPre = new Float64Array(3 * landmarks.length);
  landmarks.forEach((l, i) => landmarkPre.set(l.pre, 3 * i));
  const landmarkNow = new Float64Array(3 * landmarks.length);
  const markerSet = (colour, overAll) => {
    const m = new THREE.InstancedMesh(
      new THREE.SphereGeometry(1.4, 12, 8),
      new THREE.MeshBasicMaterial({ color: colour, depthTest: !overAll, transparent: overAll }),
      Math.max(landmarks.length, 1),
    );
    m.renderOrder = 10;
    scene.add(m);
    return m;
  };
  const softMarkers = markerSet(0xd62728, false);
  const boneMarkers = markerSet(0x1f4eb4, true);
  const markerMatrix = new THREE.Matrix4();
  function showMarkers(points) {
    let soft = 0;
    let bone = 0;
    for (let i = 0; i < landmarks.length; i++) {
      markerMatrix.makeTranslation(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
      if (landmarks[i].anchor) softMarkers.setMatrixAt(soft++, markerMatrix);
      else boneMarkers.setMatrixAt(bone++, markerMatrix);
    }
    softMarkers.count = soft;
    boneMarkers.count = bone;
    softMarkers.instanceMatrix.needsUpdate = true;
    boneMarkers.instanceMatrix.needsUpdate = true;
  }

  // ---- camera: the head's views, framed on the face ----
  // The face the views frame: the soft-tissue landmarks and the facial regions' vertices (nose,
  // lips, chin, cheeks), before and after the run's plan; the whole skin when the run has
  // neither.
  const facePoints = faceFramePoints(facePre, facePost, data.region_of ? decode(data.region_of, Uint8Array) : null, landmarks);
  const box = new THREE.Box3().setFromArray(facePoints);
  const centre = box.getCenter(new THREE.Vector3());
  const radius = 0.5 * box.getSize(new THREE.Vector3()).length();
  camera.up.copy(viewFrame.up); // before OrbitControls, which orbits about camera.up
  camera.position.copy(centre).addScaledVector(viewFrame.front, 3 * radius);
  const controls = new OrbitControls(camera, canvas);
  controls.target.copy(centre);
  controls.update();

  // ---- state: the current face (the after-mesh's vertex buffer), colours, what is shown ----
  const facePosition = faceAfter.geometry.getAttribute("position");
  const faceNormal = faceAfter.geometry.getAttribute("normal");
  const faceColour = faceAfter.geometry.getAttribute("color");
  const current = facePosition.array;
  // The tissue sliders' current answer (tissueAnswer; null: no reduced model).
  let tissueResult = null;
  const state = { mode: "after", view: "profile-right", skull: false, colour: true, landmarks: true, tracing: true, colourBy: "displacement", max: 0 };
  // Viridis sampled finely once, as linear RGB (the shader lights linear colours and writes sRGB,
  // so an unshaded face would show the legend's sRGB colours).
  const LUT_STEPS = 1024;
  const lut = new Float32Array(3 * (LUT_STEPS + 1));
  const lin = new THREE.Color();
  for (let i = 0; i <= LUT_STEPS; i++) {
    const [r, g, b] = viridis(i / LUT_STEPS);
    lin.setRGB(r / 255, g / 255, b / 255, THREE.SRGBColorSpace);
    lut.set([lin.r, lin.g, lin.b], 3 * i);
  }
  const skin = new THREE.Color(SKIN);
  const dist = new Float32Array(n);
  // With [uncertainty] samples: the band's width p95 − p05 per vertex (the run's plan).
  const bandWidth = data.band_width ? f32(data.band_width) : null;

  // ---- the colour legend (mm), over the picture ----
  const legend = el("div", { id: "legend", role: "group", "aria-label": "colour legend" });
  const legendTitle = el("div", { class: "title" });
  const ramp = el("div", { class: "ramp", "aria-hidden": "true" });
  const stops = [];
  for (let i = 0; i <= 8; i++) stops.push(`rgb(${viridis(i / 8).join(",")}) ${(i / 8) * 100}%`);
  ramp.style.background = `linear-gradient(to right, ${stops.join(",")})`;
  const ticks = el("div", { class: "ticks" });
  const tickLabels = [0, 1, 2].map(() => el("span"));
  ticks.append(...tickLabels);
  legend.append(legendTitle, ramp, ticks);
  view.appendChild(legend);

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
        colours[p] = skin.r;
        colours[p + 1] = skin.g;
        colours[p + 2] = skin.b;
      }
    }
    vertexNormals(current, faceTris, faceNormal.array);
    if (state.mode === "both") refreshGhost();
    facePosition.needsUpdate = true;
    faceNormal.needsUpdate = true;
    faceColour.needsUpdate = true;
    state.max = smax;
  }
  /** The legend's text: not per slider frame (a text change costs the page a layout and a
   *  repaint over the canvas, measurable in software rendering); when a drag settles. */
  function refreshLegend() {
    tickLabels[0].textContent = "0";
    tickLabels[1].textContent = (state.max / 2).toFixed(1);
    tickLabels[2].textContent = `${state.max.toFixed(1)} mm`;
    legendTitle.textContent = state.colourBy === "band" && bandWidth ? "uncertainty band width p95 − p05 (mm, the run's plan)" : "how far the skin moves (mm)";
  }

  function refreshGhost() {
    for (let v = 0; v < n; v++) ghostWeight[v] = Math.min(Math.max((dist[v] - 0.3) / 0.7, 0), 1);
    faceBefore.geometry.getAttribute("weight").needsUpdate = true;
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
    else {
      // The run's plan: bony landmarks as report.json has them, soft ones on the face shown when
      // the tissue sliders changed it.
      const changed = !!(tissueResult && tissueResult.delta);
      if (changed) placeLandmarks(landmarks, faceTris, current, [], landmarkNow);
      landmarks.forEach((l, i) => {
        if (!changed || !l.anchor) landmarkNow.set(l.post, 3 * i);
      });
    }
    showMarkers(state.mode === "before" ? landmarkPre : landmarkNow);
  }

  // ---- landmark labels: text next to each marker, placed at every draw ----
  const labelLayer = el("div", { id: "labels", "aria-hidden": "true" });
  view.appendChild(labelLayer);
  const labels = landmarks.map((l) => {
    const e = el("div", { class: l.anchor ? "lm" : "lm bone", "data-label": l.label }, l.label);
    labelLayer.appendChild(e);
    return e;
  });
  const widths = new Float64Array(labels.length);
  const lp = new THREE.Vector3();
  const offset = new THREE.Vector3();
  const toCamera = new THREE.Vector3();
  const triNormal = new THREE.Vector3();
  const ab = new THREE.Vector3();
  const ac = new THREE.Vector3();
  /** Is landmark i on the side of the face the camera sees? Midline ones always are; a bilateral
   *  soft one when its triangle faces the camera; a bony one when the skull is shown. */
  function facing(i, points, face) {
    const l = landmarks[i];
    lp.fromArray(points, 3 * i);
    if (!l.anchor) return state.skull;
    if (Math.abs(offset.copy(lp).sub(frame.origin).dot(frame.left)) < 5) return true;
    const t = 3 * l.anchor.triangle;
    const [a, b, c] = [faceTris[t], faceTris[t + 1], faceTris[t + 2]];
    ab.set(face[3 * b] - face[3 * a], face[3 * b + 1] - face[3 * a + 1], face[3 * b + 2] - face[3 * a + 2]);
    ac.set(face[3 * c] - face[3 * a], face[3 * c + 1] - face[3 * a + 1], face[3 * c + 2] - face[3 * a + 2]);
    triNormal.crossVectors(ab, ac).normalize();
    if (outward === THREE.BackSide) triNormal.negate();
    toCamera.copy(camera.position).sub(lp).normalize();
    return triNormal.dot(toCamera) > 0.05;
  }
  /** Put each label beside its landmark's projection, pushed away from the face's middle. */
  function placeLabels() {
    const w = view.clientWidth;
    const h = view.clientHeight;
    const before = state.mode === "before";
    const points = before ? landmarkPre : landmarkNow;
    const face = before ? facePre : current;
    const mid = centre.clone().project(camera);
    for (let i = 0; i < labels.length; i++) {
      const e = labels[i];
      const shown = state.landmarks && facing(i, points, face);
      e.hidden = !shown;
      if (!shown) continue;
      lp.fromArray(points, 3 * i).project(camera);
      const x = ((lp.x + 1) / 2) * w;
      const y = ((1 - lp.y) / 2) * h;
      e.dataset.x = x.toFixed(1);
      e.dataset.y = y.toFixed(1);
      // Right of the marker when it is right of the middle, left of it otherwise; kept on the
      // picture. Widths are measured once (the text does not change).
      if (!widths[i]) widths[i] = e.offsetWidth;
      let right = lp.x >= mid.x;
      if (right && x + 6 + widths[i] > w) right = false;
      else if (!right && x - 6 - widths[i] < 0) right = true;
      e.style.transform = `translate(${right ? x + 6 : x - 6 - widths[i]}px, ${y - 7}px)`;
    }
  }

  function showState() {
    const after = state.mode !== "before";
    faceAfter.visible = after;
    faceBefore.visible = state.mode === "before";
    ghostFront.visible = ghostBehind.visible = state.mode === "both";
    if (state.mode === "both") refreshGhost();
    skullBefore.visible = state.skull && !after;
    skullMoving.visible = skullStatic.visible = state.skull && after;
    softMarkers.visible = state.landmarks && landmarks.length > 0;
    boneMarkers.visible = softMarkers.visible && state.skull;
    showMarkers(after ? landmarkNow : landmarkPre);
    // The skin is opaque unless the skull is to be seen through it; the skull is always opaque.
    for (const m of [faceMaterial, skinMaterial, faceMaterialDrag, skinMaterialDrag]) setOpacity(m, state.skull ? SEE_THROUGH : 1);
    legend.hidden = !(after && state.colour);
    refreshLegend();
    profilePanel.hidden = !state.tracing;
    for (const b of modeButtons) b.setAttribute("aria-pressed", String(b.dataset.mode === state.mode));
    for (const b of viewButtons) b.setAttribute("aria-pressed", String(b.dataset.view === state.view));
    describe();
    cache.invalidate();
  }

  /** The canvas' text alternative: what it shows now. */
  function describe() {
    const what = { before: "the face before surgery", after: "the predicted face after surgery", both: "the predicted face after surgery over a translucent blue ghost of the face before" }[state.mode];
    const colour = state.mode !== "before" && state.colour
      ? `, coloured by ${state.colourBy === "band" ? "the uncertainty band width" : "how far the skin moves"} from 0 (dark blue) to ${state.max.toFixed(1)} mm (yellow)`
      : "";
    const shown = labels.filter((e) => !e.hidden).map((e) => e.textContent);
    const lms = state.landmarks && shown.length > 0 ? `; landmarks labelled: ${shown.join(", ")}` : "";
    const t = tissueResult && tissueResult.delta ? tissueResult.materials : null;
    const tissues = t && state.mode !== "before"
      ? `; tissues re-solved by the reduced model: ν ${t[2].poisson.toFixed(3)}, muscle/fat ${(t[1].youngs_kpa / t[2].youngs_kpa).toPrecision(3)}, skin/fat ${(t[0].youngs_kpa / t[2].youngs_kpa).toPrecision(3)}, mucosa ${tissueResult.sliding ? "sliding" : "attached"}`
      : "";
    canvas.setAttribute("aria-label", `3-D picture of ${what}${colour}, seen ${VIEW_TEXT[state.view] || "from a turned viewpoint"}; skull ${state.skull ? "shown through the skin" : "hidden"}${tissues}${lms}.`);
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
      // The print layout keeps the picture's screen size, scaled to fit beside the tracing.
      document.body.style.setProperty("--view-w", `${w}px`);
      document.body.style.setProperty("--view-h", `${h}px`);
      document.body.style.setProperty("--print-zoom", String(Math.min(1, 440 / w, 470 / h)));
    }
    const lod = dragging && options.lod ? faceIndexLod : faceIndexFull;
    faceAfter.geometry.setIndex(lod);
    faceBefore.geometry.setIndex(lod);
    faceAfter.material = dragging ? faceMaterialDrag : faceMaterial;
    faceBefore.material = dragging ? skinMaterialDrag : skinMaterial;
    viewUp(camera);
    placeLabels();
    if (cached && options.cache && skullStatic.visible && cache.draw(scene, camera)) return;
    renderer.render(scene, camera);
  }
  const render = () => draw(false);
  let settle = 0;
  /** A frame drawn while dragging (`slider`: a slider, not the view); the full-resolution one
   *  follows when the dragging stops, with the tables and the profile tracing. */
  function dragFrame(slider) {
    draw(true, slider);
    clearTimeout(settle);
    settle = setTimeout(settleNow, DRAG_SETTLE_MS);
  }
  function settleNow() {
    clearTimeout(settle);
    refreshLegend();
    refreshTables();
    refreshProfile();
    render();
    describe();
  }
  let frameWanted = false;
  let sliderMoved = false;
  let tissueMoved = false;
  function requestFrame() {
    if (frameWanted) return;
    frameWanted = true;
    requestAnimationFrame(() => {
      frameWanted = false;
      // However many slider events came since the last frame, the face is re-planned once.
      const slider = sliderMoved || tissueMoved;
      if (tissueMoved) {
        tissueMoved = false;
        updateTissue();
        if (!sliderMoved) {
          faceNow();
          refreshLandmarks(plan);
        }
      }
      if (sliderMoved) {
        sliderMoved = false;
        applyPlan(sliderPlan());
      }
      dragFrame(slider);
    });
  }
  let quietControls = false;
  controls.addEventListener("change", () => {
    if (quietControls) return;
    // Turned by hand: no named view any more.
    if (state.view) {
      state.view = null;
      for (const b of viewButtons) b.setAttribute("aria-pressed", "false");
    }
    requestFrame();
  });
  window.addEventListener("resize", render);
  window.addEventListener("beforeprint", settleNow);

  /** Move the camera (`change` edits position and target), then draw at full resolution. */
  function moveCamera(change) {
    change();
    quietControls = true;
    controls.update();
    quietControls = false;
    render();
    describe();
  }
  /** One of VIEWS: the camera on that side of the face, far enough to see all of it. */
  function setView(name) {
    const v = VIEWS.find(([key]) => key === name);
    if (!v) throw new Error(`report.html: no view '${name}' (${VIEWS.map(([k]) => k).join(", ")})`);
    state.view = name;
    const aspect = view.clientWidth / Math.max(view.clientHeight, 1);
    const half = THREE.MathUtils.degToRad(camera.fov / 2);
    const toCam = v[2](viewFrame);
    const up = viewFrame.up.clone().addScaledVector(toCam, -viewFrame.up.dot(toCam)).normalize();
    const right = up.clone().cross(toCam);
    // Room for the labels beside the markers at the sides, and for the toolbar and the legend
    // over the picture's top and bottom edges (CSS px, the same at both edges).
    const w = Math.max(view.clientWidth, 1);
    const h = Math.max(view.clientHeight, 1);
    const marginX = Math.min(LABEL_ROOM_PX, 0.25 * w);
    const marginY = Math.min(Math.max(toolbar.offsetTop + toolbar.offsetHeight + 10, legend.offsetHeight + 18, 50), 0.3 * h);
    const tanY = Math.tan(half) * (1 - (2 * marginY) / h);
    const tanX = Math.tan(half) * aspect * (1 - (2 * marginX) / w);
    const { target, distance } = fitFace(facePoints, right, up, toCam, tanX, tanY);
    moveCamera(() => {
      controls.target.copy(target);
      camera.position.copy(target).addScaledVector(toCam, distance);
    });
    showState();
  }

  // Keys on the picture: arrows turn (left/right about the head's vertical, up/down tilt), + and −
  // zoom, 1–4 the views, 0 the default view.
  const STEP = THREE.MathUtils.degToRad(15);
  const axis = new THREE.Vector3();
  canvas.addEventListener("keydown", (e) => {
    const turn = (about, angle) =>
      moveCamera(() => {
        const off = camera.position.clone().sub(controls.target).applyAxisAngle(about, angle);
        camera.position.copy(controls.target).add(off);
      });
    const zoom = (k) => moveCamera(() => camera.position.sub(controls.target).multiplyScalar(k).add(controls.target));
    const right = () => axis.subVectors(controls.target, camera.position).cross(camera.up).normalize();
    const keys = {
      ArrowLeft: () => turn(viewFrame.up, -STEP),
      ArrowRight: () => turn(viewFrame.up, STEP),
      ArrowUp: () => turn(right(), -STEP),
      ArrowDown: () => turn(right(), STEP),
      "+": () => zoom(0.85),
      "=": () => zoom(0.85),
      "-": () => zoom(1 / 0.85),
      1: () => setView("front"),
      2: () => setView("profile-right"),
      3: () => setView("profile-left"),
      4: () => setView("three-quarter"),
      0: () => setView("profile-right"),
    };
    const act = keys[e.key];
    if (!act || e.altKey || e.ctrlKey || e.metaKey) return;
    e.preventDefault();
    if (e.key.startsWith("Arrow")) state.view = null;
    act();
    if (e.key.startsWith("Arrow")) showState();
  });

  // ---- toolbar over the picture: views, before/after/both, picture export ----
  const toolbar = el("div", { id: "toolbar" });
  const group = (label) => {
    const g = el("div", { role: "group", "aria-label": label });
    toolbar.appendChild(g);
    return g;
  };
  const viewGroup = group("view");
  const viewButtons = VIEWS.map(([key, label], i) => {
    const b = el("button", { type: "button", "data-view": key, "aria-pressed": "false", "aria-keyshortcuts": String(i + 1), title: `${label} (key ${i + 1} on the picture)` }, label);
    b.addEventListener("click", () => setView(key));
    viewGroup.appendChild(b);
    return b;
  });
  const modeGroup = group("face shown");
  const modeButtons = MODES.map(([key, label]) => {
    const b = el("button", { type: "button", "data-mode": key, "aria-pressed": "false" }, label);
    b.title = { before: "the face before surgery", after: "the predicted face after surgery", both: "after, over a translucent ghost of before" }[key];
    b.addEventListener("click", () => {
      state.mode = key;
      showState();
      render();
    });
    modeGroup.appendChild(b);
    return b;
  });
  const exportGroup = group("export");
  const pngButton = el("button", { type: "button", id: "png" }, "save picture (PNG)");
  pngButton.addEventListener("click", () => {
    const a = el("a", { download: `${data.title || "facesim"} - ${state.view || "view"}.png` });
    a.href = png();
    a.click();
  });
  const printButton = el("button", { type: "button", id: "print" }, "print summary");
  printButton.addEventListener("click", () => window.print());
  exportGroup.append(pngButton, printButton);
  view.appendChild(toolbar);

  // ---- controls panel ----
  side.appendChild(
    el("p", { class: "hint", id: "keys-hint" }, "On the picture: drag to turn, wheel to zoom, right-drag to move. With the picture focused (Tab): ← → turn, ↑ ↓ tilt, + − zoom, 1 front, 2 profile right, 3 profile left, 4 three-quarter, 0 back to the profile."),
  );
  side.appendChild(el("p", { class: "frame-note" }, cf ? `Views use ${viewSource}; the tracing uses ${hf.source}.` : `Views and tracing use ${hf.source}.`));
  const shownBox = el("fieldset");
  shownBox.appendChild(el("legend", {}, "show"));
  const toggle = (label, key, id) => {
    const l = el("label");
    const c = el("input", { type: "checkbox", id });
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
  shownBox.append(
    toggle("colour by how far the skin moves", "colour", "colour"),
    toggle("landmarks", "landmarks", "landmarks"),
    toggle("see the skull through the skin", "skull", "skull"),
    toggle("profile tracing", "tracing", "tracing"),
  );
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
    shownBox.appendChild(l);
  }
  side.appendChild(shownBox);

  // ---- sliders ----
  const planBox = el("fieldset", { id: "plan" });
  planBox.appendChild(el("legend", {}, "plan"));
  const sliders = new Map();
  let plan = null;
  if (!basis) {
    planBox.appendChild(el("p", { class: "why" }, data.no_basis_reason || "This output directory has no plan basis, so the page cannot re-plan."));
  } else {
    planBox.appendChild(el("p", { class: "label" }, basis.label));
    planBox.appendChild(
      el("p", { class: "hint", id: "plan-axes" }, clinical
        ? `In the clinical frame (${cf.method}), about each segment's pivot: advance, up, left (mm); pitch (+ turns the front down), roll (+ raises the patient's left side), yaw (+ turns the front to the patient's left), in degrees; applied pitch, roll, yaw, then the move.`
        : "Along and about the CT's axes (LPS: x to the patient's left, y to the back, z up), about each segment's pivot: turned about x, then y, then z, then moved."),
    );
    for (const s of basis.segments) {
      planBox.appendChild(el("h3", {}, s.name));
      const initial = clinical ? s.runMoves || readBack(s.runPlan, clinical) : null;
      for (const [key, label, unit, title] of SLIDER_KEYS[clinical ? "clinical" : "lps"]) {
        const l = el("label", { class: "slider", title });
        const value = clinical ? initial[key] : s.runPlan[key[0]][key[1]];
        const lim = Math.max(unit === "mm" ? 15 : 20, Math.ceil(Math.abs(value)));
        const r = el("input", { type: "range", min: -lim, max: lim, step: 0.1, value: String(value) });
        r.dataset.segment = s.name;
        r.dataset.move = clinical ? key : `${key[0]}/${key[1]}`;
        r.setAttribute("aria-valuetext", sliderText(value, unit));
        const out = el("output", {}, sliderText(value, unit));
        // The slider's value: exact as set (the run's plan, setPlan), the range input's own
        // (on its 0.1 step) once dragged.
        const slider = { r, out, unit, value };
        r.addEventListener("input", () => {
          slider.value = Number(r.value);
          out.textContent = sliderText(r.value, unit);
          r.setAttribute("aria-valuetext", out.textContent);
          sliderMoved = true;
          requestFrame();
        });
        l.append(`${label} `, r, out);
        planBox.appendChild(l);
        sliders.set(`${s.name}/${r.dataset.move}`, slider);
      }
    }
    const reset = el("button", { type: "button" }, "the run's plan");
    reset.addEventListener("click", () => {
      const p = {};
      for (const s of basis.segments) p[s.name] = s.runPlan;
      setSliders(p);
      plan = null;
      sliderMoved = false;
      faceNow();
      refreshSkull(null);
      describeTissue();
      settleNow();
    });
    planBox.appendChild(reset);
  }
  side.appendChild(planBox);

  /** The sliders' plan: per segment its LPS move ({translate, rotate_deg}, or {translate,
   *  rotation} from the clinical moves). */
  function sliderPlan() {
    const p = {};
    for (const s of basis.segments) {
      const get = (move) => sliders.get(`${s.name}/${move}`).value;
      if (clinical) {
        const m = {};
        for (const [key] of SLIDER_KEYS.clinical) m[key] = get(key);
        p[s.name] = clinicalMove(m, clinical);
      } else p[s.name] = { translate: [0, 1, 2].map((i) => get(`translate/${i}`)), rotate_deg: [0, 1, 2].map((i) => get(`rotate_deg/${i}`)) };
    }
    return p;
  }
  /** The sliders to the LPS plan `p` (a segment left out: no move); with a clinical frame, its
   *  moves read back in it unless `moves` (segment → clinical moves) gives them. */
  function setSliders(p, moves = null) {
    for (const s of basis.segments) {
      const seg = p[s.name] || { translate: [0, 0, 0], rotate_deg: [0, 0, 0] };
      let values;
      if (clinical) {
        const m = moves ? moves[s.name] || {} : seg === s.runPlan && s.runMoves ? s.runMoves : readBack(seg, clinical);
        values = SLIDER_KEYS.clinical.map(([key]) => [key, Number(m[key] || 0)]);
      } else values = SLIDER_KEYS.lps.map(([key]) => [`${key[0]}/${key[1]}`, (seg[key[0]] || [0, 0, 0])[key[1]]]);
      for (const [move, v] of values) {
        const slider = sliders.get(`${s.name}/${move}`);
        const { r, out, unit } = slider;
        // A plan beyond the slider's range widens it; the slider keeps the value exactly.
        if (Math.abs(v) > Number(r.max)) {
          r.max = String(Math.ceil(Math.abs(v)));
          r.min = String(-Math.ceil(Math.abs(v)));
        }
        slider.value = v;
        r.value = String(v);
        out.textContent = sliderText(v, unit);
        r.setAttribute("aria-valuetext", out.textContent);
      }
    }
  }
  function applyPlan(p) {
    plan = p;
    faceNow();
    refreshSkull(p);
    describeTissue();
  }
  /** The face shown: the plan's (the run's face_post without one), plus the tissue sliders'
   *  change; then colours and normals. */
  function faceNow() {
    if (plan) predictFace(facePre, basis.segments, plan, current);
    else current.set(facePost);
    const d = tissueResult && tissueResult.delta;
    if (d) {
      const idx = tissue.vertices;
      for (let i = 0, a = 0; i < idx.length; i++, a += 3) {
        const p = 3 * idx[i];
        current[p] += d[a];
        current[p + 1] += d[a + 1];
        current[p + 2] += d[a + 2];
      }
    }
    refreshFace();
  }

  // ---- tissue sliders: the run's certified reduced model re-solved live (tissue.js) ----
  // The reduced model is built at the run's plan, so the face shown is
  // plan face + [reduced face(θ) − reduced face(θ̄)]: exact to the certified bound at the run's
  // plan; for another plan the tissue change is the one computed at the run's plan.
  const td = data.tissue;
  const tissueBox = el("fieldset", { id: "tissue" });
  tissueBox.appendChild(el("legend", {}, "tissues"));
  const tissue = td ? tissueModels(td) : null;
  const tissueValues = { poisson: null, muscle_fat: null, skin_fat: null, sliding: td ? td.sliding : false };
  const tissueSliders = new Map();
  const boundText = el("p", { class: "tissue-bound", id: "tissue-bound" });
  const outsideText = el("p", { class: "why", id: "tissue-outside", role: "status" });
  const planNote = el("p", { class: "hint", id: "tissue-plan" }, "The plan differs from the run's: the tissue change shown is the one computed at the run's plan (the reduced model's), not certified for this plan.");
  outsideText.hidden = planNote.hidden = true;
  if (!tissue) {
    tissueBox.appendChild(
      el("p", { class: "hint" }, data.model === "tet"
        ? "Tissue sliders need the run's certified reduced model: run with [uncertainty] samples ≥ 64 (or method = \"reduced\") and the linear tet model (docs/design/reduced.md)."
        : "Tissue sliders need the linear volumetric model (\"tet\") with its certified reduced model."),
    );
  } else {
    tissueBox.appendChild(el("p", { class: "label" }, "certified reduced model"));
    const nominal = td.tissues;
    const runValue = { poisson: nominal[2].poisson, muscle_fat: nominal[1].youngs_kpa / nominal[2].youngs_kpa, skin_fat: nominal[0].youngs_kpa / nominal[2].youngs_kpa };
    const LABELS = { poisson: ["ν", "Poisson's ratio of every soft tissue"], muscle_fat: ["muscle/fat", "Young's modulus of muscle over that of (dark) fat"], skin_fat: ["skin/fat", "Young's modulus of skin over that of (dark) fat"] };
    const STEPS = 200;
    const show = (key, v) => (key === "poisson" ? Number(v).toFixed(3) : Number(v).toPrecision(3));
    for (const key of ["poisson", "muscle_fat", "skin_fat"]) {
      const dist = td.parameters && td.parameters[key];
      if (!dist || !(dist.uniform || dist.log_uniform)) continue;
      const range = rangeWith(dist, runValue[key]);
      const [lo, hi] = range.uniform || range.log_uniform;
      const [label, title] = LABELS[key];
      if (!(hi > lo)) {
        tissueBox.appendChild(el("p", { class: "hint" }, `${label}: held at ${show(key, lo)} (a point range)`));
        continue;
      }
      const l = el("label", { class: "slider tissue", title: `${title}: ${show(key, lo)}–${show(key, hi)}, the range the reduced model was trained on` });
      // 200 steps (0.5 % of the range per arrow key; PageUp/PageDown 10 %).
      const r = el("input", { type: "range", min: 0, max: STEPS, step: 1, value: String(Math.round(STEPS * rangeFraction(range, runValue[key]))) });
      r.dataset.tissue = key;
      const out = el("output", {}, show(key, runValue[key]));
      r.setAttribute("aria-valuetext", out.textContent);
      r.addEventListener("input", () => {
        tissueValues[key] = rangeAt(range, Number(r.value) / STEPS);
        out.textContent = show(key, tissueValues[key]);
        r.setAttribute("aria-valuetext", out.textContent);
        tissueMoved = true;
        requestFrame();
      });
      l.append(`${label} `, r, out);
      tissueBox.appendChild(l);
      tissueSliders.set(key, { r, out, range, set: (v) => {
        r.value = String(Math.round(STEPS * Math.min(Math.max(rangeFraction(range, v), 0), 1)));
        out.textContent = show(key, v);
        r.setAttribute("aria-valuetext", out.textContent);
      } });
    }
    // Sliding on/off: only when the mesh has nodes that slide and both models were built.
    if (td.sliding_matters && tissue.models.some((m) => m.sliding) && tissue.models.some((m) => !m.sliding)) {
      const l = el("label");
      const c = el("input", { type: "checkbox", id: "tissue-sliding" });
      c.checked = td.sliding;
      c.addEventListener("change", () => {
        tissueValues.sliding = c.checked;
        applyTissue();
        settleNow();
      });
      l.append(c, " mucosa slides on the bone");
      tissueBox.appendChild(l);
      tissueSliders.set("sliding", { set: (v) => (c.checked = v) });
    }
    const reset = el("button", { type: "button", id: "tissue-reset" }, "the run's tissues");
    reset.addEventListener("click", () => {
      Object.assign(tissueValues, { poisson: null, muscle_fat: null, skin_fat: null, sliding: td.sliding });
      for (const [key, s] of tissueSliders) s.set(key === "sliding" ? td.sliding : runValue[key]);
      applyTissue();
      settleNow();
    });
    tissueBox.append(boundText, outsideText, planNote, reset);
  }
  side.appendChild(tissueBox);

  /** The models as the page uses them: face fields decoded, the run's model and its answer at
   *  θ̄ (the reference the tissue change is taken from). */
  function tissueModels(t) {
    const models = t.models.map((m) => ({ ...m, liftF: f32(m.lift), columnsF: f32(m.columns), duals: (m.duals || []).map((d) => unpackDual(d, f64)) }));
    const run = models.find((m) => m.sliding === t.sliding) || models[0];
    const ref = solveOnline(run.form, run.form.theta_bar);
    const refFace = reducedFace(run.liftF, run.columnsF, ref.coefficients);
    return {
      models,
      run,
      ref,
      refFace,
      // Each landmark's bound at θ̄, the reference every tissue change is taken from.
      refLandmarkBounds: t.landmarks.map((_, i) => landmarkBound(run, i, run.form.theta_bar, ref)),
      vertices: u32(t.vertices),
      work: new Float64Array(run.liftF.length),
      modelFor: (sliding) => models.find((m) => m.sliding === sliding) || (t.sliding_matters ? null : models[0]),
    };
  }

  /** The tissue sliders' answer for tissueValues: {nominal} (the run's own tissues: no change),
   *  {outside: why} (outside the trained box: not answered, the face shows the run's tissues),
   *  or the change of the face, its coefficients and certified bounds. */
  function tissueAnswer() {
    const mats = materials(td.tissues, tissueValues);
    const same = mats.every((m, i) => m.youngs_kpa === td.tissues[i].youngs_kpa && m.poisson === td.tissues[i].poisson);
    const model = tissue.modelFor(tissueValues.sliding);
    if (same && (model === tissue.run || !td.sliding_matters)) return { nominal: true, materials: mats };
    if (!model) return { outside: "no reduced model for this sliding state", materials: mats };
    const th = thetaOf(model.terms, mats);
    const why = outside(model.terms, model.theta_box, th);
    if (why) return { outside: why, materials: mats, theta: th };
    const o = solveOnline(model.form, th);
    const face = reducedFace(model.liftF, model.columnsF, o.coefficients, tissue.work);
    const delta = new Float32Array(face.length);
    for (let a = 0; a < face.length; a++) delta[a] = face[a] - tissue.refFace[a];
    // shown − full = [reduced(θ) − full(θ)] − [reduced(θ̄) − full(θ̄)] at the run's plan.
    const refBound = tissue.ref.energyBound;
    const landmarkBounds = {};
    td.landmarks.forEach((label, i) => (landmarkBounds[label] = landmarkBound(model, i, th, o) + tissue.refLandmarkBounds[i]));
    return {
      materials: mats,
      theta: th,
      sliding: model.sliding,
      coefficients: Array.from(o.coefficients),
      energyBound: o.energyBound,
      referenceEnergyBound: refBound,
      faceBound: outputBound(model.face_bound, o) + outputBound(tissue.run.face_bound, tissue.ref),
      landmarkBounds,
      delta,
    };
  }
  function updateTissue() {
    if (tissue) tissueResult = tissueAnswer();
    describeTissue();
  }
  function applyTissue() {
    updateTissue();
    faceNow();
    refreshLandmarks(plan);
  }
  const planDiffers = () =>
    !!plan && !!basis && basis.segments.some((s) => {
      const a = planMatrix(plan[s.name] || { translate: [0, 0, 0] }, s.pivot, new Float64Array(12));
      const b = planMatrix(s.runPlan, s.pivot, new Float64Array(12));
      return a.some((x, k) => Math.abs(x - b[k]) > 1e-9);
    });
  const setText = (e, text) => {
    if (e.textContent !== text) e.textContent = text;
  };
  /** The bound line, the notice outside the trained box and the note for another plan; text is
   *  rewritten only when it changes. */
  function describeTissue() {
    if (!tissue || !tissueResult) return;
    const r = tissueResult;
    const fmt2 = (v) => Number(v).toFixed(2);
    if (r.outside) {
      setText(outsideText, `Outside the range the reduced model was trained on (${r.outside}): not answered; the face shows the run's tissues.`);
      setText(boundText, "");
    } else if (r.nominal) {
      setText(boundText, "The run's own tissues: the face is the full model's.");
    } else {
      const b = Object.values(r.landmarkBounds);
      const prn = r.landmarkBounds.Prn;
      setText(boundText,
        `Re-solved by the certified reduced model: the face within ${fmt2(r.faceBound)} mm of the full model's for these tissues (certified, every vertex)` +
        (prn !== undefined ? `; Prn within ${fmt2(prn)} mm` : "") +
        (b.length ? `; every landmark within ${fmt2(Math.max(...b))} mm` : "") + ".");
    }
    const hideOutside = !r.outside;
    if (outsideText.hidden !== hideOutside) outsideText.hidden = hideOutside;
    const hideNote = !(planDiffers() && !r.nominal);
    if (planNote.hidden !== hideNote) planNote.hidden = hideNote;
  }

  // ---- the profile tracing: the midsagittal cut before and after ----
  const cutFrame = { origin: hf.origin, front: frame.front.toArray(), up: frame.up.toArray(), left: frame.left.toArray() };
  const profileBefore = facialPart(midsagittalCut(facePre, faceTris, cutFrame));
  const profilePanel = el("section", { id: "profile", "aria-labelledby": "profile-h" });
  profilePanel.appendChild(el("h2", { id: "profile-h" }, "profile tracing (midsagittal)"));
  const svg = svgEl("svg", { role: "img", "aria-labelledby": "profile-title profile-desc" });
  const svgTitle = svgEl("title", { id: "profile-title" }, "Midsagittal profile before and after");
  const svgDesc = svgEl("desc", { id: "profile-desc" });
  const beforePath = svgEl("path", { class: "before", d: pathData(profileBefore) });
  const afterPath = svgEl("path", { class: "after" });
  const bar = svgEl("path", { class: "bar" });
  const barText = svgEl("text", { "font-size": "3.5", fill: "#333" }, "10 mm");
  svg.append(svgTitle, svgDesc, beforePath, afterPath, bar, barText);
  const key = el("div", { class: "key" });
  key.append(el("span", { class: "b" }, "before"), el("span", {}, "after"));
  profilePanel.append(svg, key);
  mainBox.appendChild(profilePanel);
  /** The view box: the face before and the run's face after, with a margin, fixed so that plans
   *  compare in one picture. */
  const extent = (lines, ext) => {
    for (const l of lines)
      for (let i = 0; i < l.length; i += 2) {
        ext[0] = Math.min(ext[0], l[i]);
        ext[1] = Math.max(ext[1], l[i]);
        ext[2] = Math.min(ext[2], -l[i + 1]);
        ext[3] = Math.max(ext[3], -l[i + 1]);
      }
    return ext;
  };
  const ext = extent(facialPart(midsagittalCut(facePost, faceTris, cutFrame)), extent(profileBefore, [Infinity, -Infinity, Infinity, -Infinity]));
  if (Number.isFinite(ext[0])) {
    const m = 8;
    const [x0, y0, w, h] = [ext[0] - m, ext[2] - m, ext[1] - ext[0] + 2 * m, ext[3] - ext[2] + 2 * m];
    svg.setAttribute("viewBox", `${x0.toFixed(1)} ${y0.toFixed(1)} ${w.toFixed(1)} ${h.toFixed(1)}`);
    bar.setAttribute("d", `M${(x0 + 3).toFixed(1)} ${(y0 + h - 3).toFixed(1)}h10`);
    barText.setAttribute("x", (x0 + 3).toFixed(1));
    barText.setAttribute("y", (y0 + h - 5).toFixed(1));
  }
  let profileAfter = [];
  function refreshProfile() {
    profileAfter = facialPart(midsagittalCut(current, faceTris, cutFrame));
    afterPath.setAttribute("d", pathData(profileAfter));
    // How far the most anterior points of the lower face moved, for the text alternative.
    const lowFront = (lines) => {
      let best = -Infinity;
      for (const l of lines) for (let i = 0; i < l.length; i += 2) if (l[i + 1] < -30) best = Math.max(best, l[i]);
      return best;
    };
    const chin = lowFront(profileAfter) - lowFront(profileBefore);
    svgDesc.textContent =
      `The face cut by the midsagittal plane, front to the right, up at the top: before surgery as a grey dashed line, after as a red line; a 10 mm bar for scale.` +
      (Number.isFinite(chin) ? ` The most forward point more than 30 mm below the nose tip's level moves ${chin >= 0 ? "forward" : "back"} by ${Math.abs(chin).toFixed(1)} mm.` : "");
  }

  // ---- tables: landmarks, regions, measurements ----
  const summary = el("section", { id: "summary", "aria-label": "summary tables" });
  const regionNames = data.region_names || [];
  const regionOf = data.region_of ? decode(data.region_of, Uint8Array) : new Uint8Array(0);
  const fmt = (v, d = 1) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));
  const table = (caption, head, cls = "") => {
    const t = el("table", { class: `figures ${cls}`.trim() });
    t.appendChild(el("caption", {}, caption));
    const thead = el("thead");
    const tr = el("tr");
    for (const h of head) tr.appendChild(el("th", { scope: "col" }, h));
    thead.appendChild(tr);
    t.append(thead, el("tbody"));
    return t;
  };
  const row = (t, cells, title) => {
    const tr = el("tr", title ? { title } : {});
    cells.forEach((c, i) => tr.appendChild(i === 0 ? el("th", { scope: "row" }, c) : el("td", { class: /^[-–+\d.]/.test(c) ? "num" : "" }, c)));
    t.tBodies[0].appendChild(tr);
    return tr;
  };
  const clear = (t) => t.tBodies[0].replaceChildren();
  const regionTable = table("How far the skin moves, per region (mm; the plan shown)", ["region", "mean", "90 %", "max", "vertices"]);
  const landmarkTable = table("How far each landmark moves (mm; the plan shown)", ["landmark", "moves"]);
  /** The live tables: each landmark's move and each region's displacement for the face shown. */
  function refreshTables() {
    clear(landmarkTable);
    landmarks.forEach((l, i) => {
      let d = 0;
      for (let k = 0; k < 3; k++) d += (landmarkNow[3 * i + k] - landmarkPre[3 * i + k]) ** 2;
      row(landmarkTable, [l.label, fmt(Math.sqrt(d))]);
    });
    for (const [label, why] of data.missing_landmarks || []) row(landmarkTable, [label, "not found"], why);
    clear(regionTable);
    const stats = regionStats(regionNames, regionOf, dist);
    for (const name of regionNames) {
      const r = stats[name];
      row(regionTable, r ? [name, fmt(r.mean), fmt(r.p90), fmt(r.max), String(r.vertices)] : [name, "absent", "", "", ""]);
    }
  }
  summary.appendChild(regionTable);
  const measures = Object.entries(data.measurements || {});
  const ratios = Object.entries(data.ratios || {});
  if (measures.length + ratios.length > 0) {
    const mt = table("Measurements before and after (the run's plan)", ["", "before", "after", "change"]);
    for (const [name, m] of measures)
      row(mt, [`${name.replaceAll("_", " ")} (${m.unit})`, fmt(m.before), fmt(m.after), fmt(m.change)], m.missing || m.definition);
    for (const [name, r] of ratios)
      row(mt, [`${name.replaceAll("_", " ")}: soft / hard (mm, ratio)`, fmt(r.soft_mm), fmt(r.hard_mm), fmt(r.ratio, 2)], r.missing || "soft-tissue move / bone move (mm, ratio)");
    summary.appendChild(mt);
  }
  summary.appendChild(landmarkTable);
  side.appendChild(summary);

  // ---- the plan held against the clinic: published soft/hard ratios of its surgery type ----
  const clinic = data.published;
  if (clinic) {
    side.appendChild(el("h2", {}, `against the clinic${clinic.title ? `: ${clinic.title}` : ""}`));
    side.appendChild(el("p", { class: "clinic-reading" }, clinic.surgery
      ? `Soft/hard ratios published for this surgery type (the spread of study means; hover a row for its source). The plan: ${clinic.reading}.`
      : `No published ratios for this plan: ${clinic.reading}.`));
    if ((clinic.rows || []).length > 0) {
      // The band: the ratio over the sampled tissue parameters and on the coarse mesh
      // (report.json published_ratios band); its verdict inside / consistent / outside.
      const banded = clinic.rows.some((r) => r.band);
      const ct = table("Soft/hard ratios: predicted against published", banded ? ["", "predicted", "band", "published", ""] : ["", "predicted", "published", ""], "clinic");
      for (const r of clinic.rows) {
        const verdict = r.verdict ? r.verdict : r.inside === true ? "inside" : r.inside === false ? "outside" : "not measured";
        const notes = [r.missing, `hard: ${r.hard}${r.hard_at ? ` (taken at ${r.hard_at})` : ""}`, r.range_note, r.source, r.evidence && `evidence: ${r.evidence}`].filter(Boolean);
        // One published value (one study, or "≈ x") is shown as itself, not as a range.
        const published = r.low === r.high ? fmt(r.low, 2) : `${fmt(r.low, 2)}–${fmt(r.high, 2)}`;
        if (r.tissue_band) notes.push(`tissue parameters p05–p95: ${fmt(r.tissue_band[0], 2)}–${fmt(r.tissue_band[1], 2)}`);
        if (r.coarse_mesh !== undefined && r.coarse_mesh !== null) notes.push(`at twice the element size: ${fmt(r.coarse_mesh, 2)}`);
        const band = r.band ? `${fmt(r.band[0], 2)}–${fmt(r.band[1], 2)}` : "";
        const cells = banded
          ? [`${r.soft}${r.axis === "vertical" ? " (vertical)" : ""}`, fmt(r.predicted, 2), band, published, verdict]
          : [`${r.soft}${r.axis === "vertical" ? " (vertical)" : ""}`, fmt(r.predicted, 2), published, verdict];
        const tr = row(ct, cells, notes.join("; "));
        tr.classList.add(r.verdict ? r.verdict : r.inside === false ? "outside" : r.inside === true ? "inside" : "unmeasured");
      }
      side.appendChild(ct);
    }
  }

  const u = data.uncertainty;
  if (u && u.samples > 0) {
    side.appendChild(el("h2", {}, `uncertainty: ${u.samples} samples (the run's plan)`));
    const ut = table("Displacement (mm): mean [5 %, 95 %] over tissue parameters drawn from their literature ranges", ["", "mean", "5 %", "95 %"]);
    for (const [k, b] of Object.entries(u.landmarks || {})) row(ut, [k, fmt(b.mean, 2), fmt(b.p05, 2), fmt(b.p95, 2)]);
    for (const [k, b] of Object.entries(u.regions || {})) if (b) row(ut, [k, fmt(b.mean, 2), fmt(b.p05, 2), fmt(b.p95, 2)]);
    side.appendChild(ut);
    // The reduced model's certificate: each sample within these of the full model (docs/design/reduced.md).
    if (u.method === "reduced" && u.largest_bound_mm !== undefined) {
      const bounds = Object.entries(u.landmark_bounds_mm || {}).filter(([, b]) => b > 0);
      const worst = bounds.reduce((m, [, b]) => Math.max(m, b), 0);
      side.appendChild(
        el("p", { class: "certified" },
          `Solved by the certified reduced model: every sample within ${fmt(worst, 2)} mm of the full model at each landmark (certified bound; at most ${fmt(u.largest_bound_mm, 1)} mm anywhere on the face).`),
      );
    }
    // Sobol indices: which tissue parameter each displacement depends on.
    const sens = u.sensitivity;
    if (sens) {
      const names = [];
      for (const g of [sens.landmarks, sens.regions]) for (const p of Object.values(g || {})) for (const k of Object.keys(p)) if (!names.includes(k)) names.push(k);
      const label = { poisson: "ν", muscle_fat: "muscle/fat", skin_fat: "skin/fat", sliding: "sliding", spring_scale: "springs" };
      const st = table(
        "What each displacement depends on: the share of its variance due to each tissue parameter alone (Sobol first-order index), with its interactions in brackets (total index); the largest in bold",
        ["", ...names.map((n) => label[n] || n)],
        "sensitivity",
      );
      for (const g of [sens.landmarks, sens.regions]) {
        for (const [k, p] of Object.entries(g || {})) {
          const top = names.reduce((a, n) => (p[n] && (!p[a] || p[n].first > p[a].first) ? n : a), names[0]);
          const tr = row(st, [k, ...names.map((n) => (p[n] ? `${fmt(p[n].first, 2)} (${fmt(p[n].total, 2)})` : "–"))]);
          const cell = tr.children[1 + names.indexOf(top)];
          if (cell) cell.classList.add("top");
        }
      }
      side.appendChild(st);
    }
  }

  // ---- figures and warnings of report.json ----
  const figs = table("Key figures of report.json", ["", ""]);
  for (const [k, v] of data.figures) row(figs, [k, v]);
  side.appendChild(el("h2", {}, "figures"));
  side.appendChild(figs);
  side.appendChild(el("h2", {}, `warnings (${data.warnings.length})`));
  const ul = el("ul", { class: "warnings" });
  for (const w of data.warnings) ul.appendChild(el("li", {}, w));
  side.appendChild(ul);

  /** The picture as a PNG data URL: the canvas at full resolution with the landmark labels and
   *  the colour legend drawn in. */
  function png() {
    render();
    const out = document.createElement("canvas");
    out.width = canvas.width;
    out.height = canvas.height;
    const g = out.getContext("2d");
    g.drawImage(canvas, 0, 0);
    const k = canvas.width / Math.max(view.clientWidth, 1);
    const origin = view.getBoundingClientRect();
    const box = (e, fill) => {
      const r = e.getBoundingClientRect();
      const [x, y, w, h] = [(r.left - origin.left) * k, (r.top - origin.top) * k, r.width * k, r.height * k];
      g.fillStyle = fill;
      g.fillRect(x, y, w, h);
      return [x, y, w, h];
    };
    g.textBaseline = "middle";
    for (const e of labels) {
      if (e.hidden) continue;
      const [x, y, , h] = box(e, "rgba(255,255,255,0.82)");
      g.font = `600 ${12 * k}px system-ui, sans-serif`;
      g.fillStyle = e.classList.contains("bone") ? "#123b8c" : "#111";
      g.fillText(e.textContent, x + 3 * k, y + h / 2);
    }
    if (!legend.hidden) {
      const [x, y, w] = box(legend, "rgba(255,255,255,0.9)");
      g.font = `${12 * k}px system-ui, sans-serif`;
      g.fillStyle = "#111";
      g.fillText(legendTitle.textContent, x + 8 * k, y + 12 * k);
      const grad = g.createLinearGradient(x + 8 * k, 0, x + w - 8 * k, 0);
      for (let i = 0; i <= 8; i++) grad.addColorStop(i / 8, `rgb(${viridis(i / 8).join(",")})`);
      g.fillStyle = grad;
      g.fillRect(x + 8 * k, y + 22 * k, w - 16 * k, 12 * k);
      g.fillStyle = "#111";
      g.textAlign = "left";
      g.fillText(tickLabels[0].textContent, x + 8 * k, y + 44 * k);
      g.textAlign = "right";
      g.fillText(tickLabels[2].textContent, x + w - 8 * k, y + 44 * k);
    }
    return out.toDataURL("image/png");
  }

  // ---- automation API (docs/guide/report-page.md) ----
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
    /** Re-plan in the clinical frame: segment name → {advance_mm, up_mm, left_mm, pitch_deg,
     *  roll_deg, yaw_deg} (a key left out: 0; docs/guide/planning.md "Signs", about the segment's
     *  pivot); a segment left out does not move. Drawn before it returns, as setPlan. */
    setPlanClinical(p) {
      if (!basis) throw new Error(data.no_basis_reason || "report.html: no plan basis");
      if (!clinical) throw new Error("report.html: this run has no clinical frame; use setPlan (LPS)");
      const keys = SLIDER_KEYS.clinical.map(([k]) => k);
      for (const [name, m] of Object.entries(p)) {
        if (!basis.segments.some((s) => s.name === name)) throw new Error(`report.html: the plan names an unknown segment '${name}'`);
        for (const k of Object.keys(m || {}))
          if (!keys.includes(k)) throw new Error(`report.html: no clinical move '${k}' (${keys.join(", ")})`);
      }
      const lps = {};
      for (const [name, m] of Object.entries(p)) lps[name] = clinicalMove(m || {}, clinical);
      setSliders(lps, p);
      sliderMoved = false;
      applyPlan(lps);
      dragFrame(true);
    },
    /** The plan's sliders: {frame: "clinical" | "lps", segments: name → {move key → value}}
     *  (clinical keys advance_mm … yaw_deg; LPS keys "translate/0" … "rotate_deg/2"), the
     *  values as the sliders hold them; null without a basis. */
    sliders() {
      if (!basis) return null;
      const segments = {};
      for (const s of basis.segments) {
        segments[s.name] = {};
        for (const [key] of SLIDER_KEYS[clinical ? "clinical" : "lps"]) {
          const move = clinical ? key : `${key[0]}/${key[1]}`;
          const { value, r, out } = sliders.get(`${s.name}/${move}`);
          segments[s.name][move] = { value, input: Number(r.value), text: out.textContent };
        }
      }
      return { frame: clinical ? "clinical" : "lps", segments };
    },
    /** The plan's matrices M = [R − I | t′] (12 entries, row-major) per segment, as the face is
     *  computed from them (the run's plan before any re-planning). */
    planMatrices() {
      const out = {};
      if (basis) for (const s of basis.segments) out[s.name] = Array.from(planMatrix((plan || {})[s.name] || (plan ? null : s.runPlan), s.pivot, new Float64Array(12)));
      return out;
    },
    /** The tissue sliders: {poisson, muscle_fat, skin_fat, sliding} (a key left out keeps its
     *  value; null: the run's). Applied and drawn before it returns, as a slider move is; returns
     *  tissue(). A value outside the trained range is not answered: the page says so. */
    setTissue(p) {
      if (!tissue) throw new Error("report.html: no reduced model in this run, so no tissue sliders");
      for (const k of Object.keys(p)) if (!(k in tissueValues)) throw new Error(`report.html: no tissue parameter '${k}' (poisson, muscle_fat, skin_fat, sliding)`);
      Object.assign(tissueValues, p);
      if (tissueValues.sliding === null) tissueValues.sliding = td.sliding;
      for (const [key, s] of tissueSliders) {
        if (key === "sliding") s.set(tissueValues.sliding);
        else if (tissueValues[key] !== null) s.set(tissueValues[key]);
      }
      tissueMoved = false;
      applyTissue();
      dragFrame(true);
      return window.facesim.tissue();
    },
    /** The tissue sliders' state: values, whether answered, the bounds (mm) and the reduced
     *  coefficients; null without a reduced model. */
    tissue() {
      if (!tissue) return null;
      const r = tissueResult || {};
      return {
        values: { ...tissueValues },
        nominal: !!r.nominal,
        outside: r.outside || null,
        sliding: r.sliding ?? null,
        theta: r.theta || null,
        coefficients: r.coefficients || null,
        energy_bound: r.energyBound ?? null,
        reference_energy_bound: r.referenceEnergyBound ?? null,
        face_bound_mm: r.faceBound ?? null,
        landmark_bounds_mm: r.landmarkBounds || null,
        plan_differs: planDiffers(),
        text: boundText.textContent,
        notice: outsideText.hidden ? null : outsideText.textContent,
        plan_note: planNote.hidden ? null : planNote.textContent,
      };
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
    /** What follows a drag 200 ms after it stops, now: tables, profile tracing, full frame. */
    settle: settleNow,
    /** One of "front", "profile-right", "profile-left", "three-quarter". */
    setView,
    /** "before", "after" or "both". */
    setMode(mode) {
      if (!MODES.some(([k]) => k === mode)) throw new Error(`report.html: no mode '${mode}'`);
      state.mode = mode;
      showState();
      render();
    },
    /** The camera, for tests that project points themselves: LPS position, target and up, the
     *  vertical field of view (degrees), and the picture's CSS size. */
    camera() {
      return {
        position: camera.position.toArray(),
        target: controls.target.toArray(),
        up: camera.up.toArray(),
        fov: camera.fov,
        width: view.clientWidth,
        height: view.clientHeight,
      };
    },
    /** The head frame the tracing uses (and the views, without a clinical frame). */
    frame() {
      return { ...hf };
    },
    /** The frame the views stand in: the clinical frame when the run has one, else frame(). */
    viewFrame() {
      return { origin: viewFrame.origin.toArray(), front: viewFrame.front.toArray(), up: viewFrame.up.toArray(), left: viewFrame.left.toArray(), source: viewSource };
    },
    /** The picture (labels and legend drawn in) as a PNG data URL of the canvas' size. */
    png,
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
        tissue: !!tissue,
        view: state.view,
        mode: state.mode,
      };
    },
  };

  updateTissue();
  refreshFace();
  refreshLandmarks(null);
  refreshTables();
  draw(false); // sizes the canvas, so that the view can fit the face
  setView("profile-right");
  refreshProfile();
  describe();
  document.body.dataset.ready = "1";
}

/** The points the views frame (flat LPS): the soft landmarks (before and after the run's plan)
 *  and the face vertices of the facial regions (before and after); every skin vertex when
 *  there are fewer than 10 such points. */
function faceFramePoints(pre, post, regionOf, landmarks) {
  const out = [];
  for (const l of landmarks) if (l.anchor) out.push(...l.pre, ...l.post);
  if (regionOf && regionOf.length === pre.length / 3)
    for (let v = 0; v < regionOf.length; v++)
      if (regionOf[v] !== 255) out.push(pre[3 * v], pre[3 * v + 1], pre[3 * v + 2], post[3 * v], post[3 * v + 1], post[3 * v + 2]);
  if (out.length < 30) return Float64Array.from(pre);
  return Float64Array.from(out);
}

/** Where a camera looking along −toCam (`right`, `up`, `toCam` orthonormal) stands to see every
 *  point within the half-angle tangents tanX, tanY: the target is the middle of the points'
 *  extent across and along the view, the distance the least that fits them in perspective
 *  (a point x across, z towards the camera from the target needs distance ≥ z + |x| / tan). */
function fitFace(points, right, up, toCam, tanX, tanY) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  const axes = [right, up, toCam];
  for (let i = 0; i < points.length; i += 3)
    axes.forEach((a, k) => {
      const c = points[i] * a.x + points[i + 1] * a.y + points[i + 2] * a.z;
      lo[k] = Math.min(lo[k], c);
      hi[k] = Math.max(hi[k], c);
    });
  const mid = lo.map((l, k) => 0.5 * (l + hi[k]));
  const target = new THREE.Vector3();
  axes.forEach((a, k) => target.addScaledVector(a, mid[k]));
  let distance = 0;
  for (let i = 0; i < points.length; i += 3) {
    const [x, y, z] = axes.map((a, k) => points[i] * a.x + points[i + 1] * a.y + points[i + 2] * a.z - mid[k]);
    distance = Math.max(distance, z + Math.abs(x) / tanX, z + Math.abs(y) / tanY);
  }
  // In front of the near plane (1 mm) with room to spare.
  distance = Math.max(distance, hi[2] - mid[2] + 10);
  return { target, distance };
}

/** Which side of the skin mesh faces out (three.js FrontSide or BackSide): the side the normal
 *  points to at the most anterior vertex (the nose tip), which faces the front. */
function outerSide(pos, normals, frame) {
  let best = -Infinity;
  let at = 0;
  for (let v = 0; v < pos.length / 3; v++) {
    const a = pos[3 * v] * frame.front.x + pos[3 * v + 1] * frame.front.y + pos[3 * v + 2] * frame.front.z;
    if (a > best) {
      best = a;
      at = v;
    }
  }
  const d = normals[3 * at] * frame.front.x + normals[3 * at + 1] * frame.front.y + normals[3 * at + 2] * frame.front.z;
  return d >= 0 ? THREE.FrontSide : THREE.BackSide;
}

main();
