//! report.html (docs/guide/report-page.md): one self-contained page per run that opens from disk with
//! no server and no network. The page logic is the three.js bundle built from `web/` and
//! committed as `assets/report.bundle.js`; it is embedded here, so writing the page needs no npm.
//! The run's data go in a JSON block: meshes and basis columns as base64 little-endian float32 /
//! uint32 / uint8 arrays (LPS mm), plus report.json's key figures and warnings.

use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use std::path::Path;

/// The page logic (three.js included), rebuilt by `npm run build` in `web/`.
pub(crate) const BUNDLE: &str = include_str!("../assets/report.bundle.js");

/// The plan basis as the page uses it: per segment, the 12 displacement columns of the face.
pub struct PageBasis {
    /// Shown above the sliders: "exact", or "linear preview" for a linearised model.
    pub label: String,
    pub segments: Vec<PageSegment>,
}

/// One osteotomy segment: its pivot, the run's move (the sliders' start) and its columns.
pub struct PageSegment {
    pub name: String,
    /// LPS mm, from the case.
    pub pivot: [f64; 3],
    /// The run's plan for this segment: mm and degrees (about x, then y, then z).
    pub translate: [f64; 3],
    pub rotate_deg: [f64; 3],
    /// 12 columns (k = 4·i + j of M = [R − I | t′], row-major), each one displacement per face
    /// vertex (mm per unit entry): the face moves by d = Σ_k m_k · columns\[k\].
    pub columns: Vec<Vec<[f64; 3]>>,
}

/// A landmark as the page carries it with a plan (docs/guide/landmarks.md): a soft one as a material
/// point of the face, a bony one with its segment's rigid move.
pub struct PageLandmark {
    pub label: String,
    /// LPS mm on the pre-operative anatomy, and after the run's plan.
    pub pre: [f64; 3],
    pub post: [f64; 3],
    /// Soft tissue: where it sits on face_pre (None: a bony landmark).
    pub anchor: Option<crate::landmarks::SurfaceAnchor>,
    /// Bone: the index in `PageData::segments` of the segment that moves it (255: none).
    pub segment: u8,
}

/// The head's axes (report.json `head_frame`, docs/guide/landmarks.md "Frame"), for the page's views
/// (front, profiles, three-quarter) and the midsagittal profile tracing. LPS mm, unit vectors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PageFrame {
    /// A point on the midsagittal plane.
    pub origin: [f64; 3],
    /// Anterior, superior and towards the patient's left (the midsagittal plane's normal).
    pub front: [f64; 3],
    pub up: [f64; 3],
    pub left: [f64; 3],
}

impl From<&crate::landmarks::HeadFrame> for PageFrame {
    fn from(f: &crate::landmarks::HeadFrame) -> PageFrame {
        PageFrame {
            origin: f.origin,
            front: f.anterior,
            up: f.vertical,
            left: f.lateral,
        }
    }
}

/// The clinical head frame (report.json `clinical_frame`, docs/guide/planning.md "The head frame"): the
/// plan's sliders are advance, up, left, pitch, roll and yaw in it, and the views are set in it.
#[derive(Clone, Debug, PartialEq)]
pub struct PageClinicalFrame {
    /// "frankfort", "facial-plane" or "ct-axes".
    pub method: String,
    /// A point on the midsagittal plane; forward, up and toward the patient's left (LPS units).
    pub origin: [f64; 3],
    pub forward: [f64; 3],
    pub up: [f64; 3],
    pub left: [f64; 3],
}

impl From<&crate::anatomy::readback::FrameReport> for PageClinicalFrame {
    fn from(f: &crate::anatomy::readback::FrameReport) -> PageClinicalFrame {
        PageClinicalFrame {
            method: f.method.clone(),
            origin: f.origin,
            forward: f.forward,
            up: f.up,
            left: f.left,
        }
    }
}

impl PageClinicalFrame {
    fn head_frame(&self) -> crate::landmarks::HeadFrame {
        crate::landmarks::HeadFrame {
            origin: self.origin,
            lateral: self.left,
            vertical: self.up,
            anterior: self.forward,
            symmetry_residual_mm: f64::NAN,
        }
    }
}

/// The tissue sliders' data (docs/guide/report-page.md "Tissue sliders"): the run's
/// certified reduced models, one per sliding state, re-solved live in the page.
pub struct PageTissue<'a> {
    /// The run's materials in `Tet::TISSUES` order (the reference θ̄ and the sliders' start).
    pub tissues: [crate::case::TissueElastic; 4],
    /// The run's `[tet] sliding`, and whether the mesh has nodes that slide at all.
    pub sliding: bool,
    pub sliding_matters: bool,
    /// `[uncertainty]`'s distributions as the run used them: key ("poisson", "muscle_fat",
    /// "skin_fat", "sliding") → `{"uniform": [a, b]}`, `{"log_uniform": [a, b]}` or
    /// `{"probability": p}`: the sliders' ranges.
    pub parameters: serde_json::Value,
    /// The soft landmarks in the order of each model's `output_gains`.
    pub landmarks: Vec<String>,
    pub models: Vec<PageReduced<'a>>,
}

/// One reduced model as the page solves it (`model::reduced::ReducedTet`).
pub struct PageReduced<'a> {
    pub sliding: bool,
    pub form: &'a crate::reduced::OnlineForm,
    /// Per term: the tissue slot (`Tet::TISSUES`) and whether θ_q is λ (else μ).
    pub terms: &'a [(usize, bool)],
    /// The trained box of θ: lowest and highest per term; outside it the page answers nothing.
    pub theta_box: &'a [Vec<f64>; 2],
    /// The certified bound on the face's error (mm) and on each soft landmark's
    /// (`reduced::OutputBound`: the gain and the images' factor).
    pub face_bound: &'a crate::reduced::OutputBound,
    pub output_bounds: &'a [crate::reduced::OutputBound],
    /// Per soft landmark its dual reduced basis (`[uncertainty] landmark_dual_rounds`; empty
    /// without): the page bounds the face's value there by its correction plus the primal–dual
    /// bound where that is smaller.
    pub duals: &'a [crate::reduced::dual::DualForm],
    /// The face displacement: lift + Σ c_n columns\[n\] (mm per face vertex).
    pub face: &'a crate::reduced::LinearFace,
}

/// Everything report.html shows (the default: nothing, no basis, no landmarks or regions).
#[derive(Default)]
pub struct PageData<'a> {
    pub title: String,
    /// `[solve] model`.
    pub model: String,
    pub face_pre: &'a [[f64; 3]],
    /// Same count and order as `face_pre`.
    pub face_post: &'a [[f64; 3]],
    pub face_triangles: &'a [[u32; 3]],
    pub skull_pre: &'a [[f64; 3]],
    pub skull_post: &'a [[f64; 3]],
    pub skull_triangles: &'a [[u32; 3]],
    /// The osteotomy segments' names in case order.
    pub segments: Vec<String>,
    /// Per skull vertex, the index in `segments` of the segment that moves it (255: none); the
    /// page moves the skull rigidly with the sliders.
    pub skull_segment: Vec<u8>,
    /// The colour scale of the displacement (mm).
    pub colour_scale_mm: [f64; 2],
    /// Key figures of report.json, as label → formatted value.
    pub figures: Vec<(String, String)>,
    pub warnings: Vec<String>,
    pub basis: Option<PageBasis>,
    /// The landmarks found on the pre-operative face and skull, carried live with the sliders.
    pub landmarks: Vec<PageLandmark>,
    /// Landmarks the scan lacks: label and why.
    pub missing_landmarks: Vec<(String, String)>,
    /// Facial region names, and per face vertex the index of its region (255: none).
    pub region_names: Vec<String>,
    pub region_of: Vec<u8>,
    /// report.json's `measurements` and `soft_hard_ratios` (the run's plan), shown as tables.
    pub measurements: serde_json::Value,
    pub ratios: serde_json::Value,
    /// report.json's `published_ratios`: the plan's surgery type and its ratios beside the
    /// published ranges (null when none).
    pub published: serde_json::Value,
    /// With `[uncertainty] samples > 0`: per face vertex the width p95 − p05 of the sampled
    /// displacement magnitude (mm), and report.json's `uncertainty`.
    pub band_width: Option<Vec<f64>>,
    pub uncertainty: serde_json::Value,
    /// Shown instead of the sliders when there is no basis.
    pub no_basis_reason: String,
    /// The head frame; None: the LPS axes (front −y, up +z) through the face's middle.
    pub head_frame: Option<PageFrame>,
    /// The clinical frame; None: the sliders move along and turn about the LPS axes, the views
    /// use `head_frame`.
    pub clinical_frame: Option<PageClinicalFrame>,
    /// The tissue sliders (None: the run has no reduced model; the page says how to get one).
    pub tissue: Option<PageTissue<'a>>,
}

/// Write `dir/report.html` (temporary name, then renamed).
pub fn write_report_html(dir: &Path, data: &PageData) -> Result<()> {
    let dest = dir.join("report.html");
    let html = page_html(data).map_err(|msg| Error::output(&dest, msg))?;
    write_bytes_atomic(&dest, |w| w.write_all(html.as_bytes()))
}

/// The whole page as text; an error names what is inconsistent in `data`.
pub(crate) fn page_html(data: &PageData) -> std::result::Result<String, String> {
    let n = data.face_pre.len();
    check_lengths(data)?;
    let landmarks = landmarks_json(data)?;
    let basis = match &data.basis {
        None => serde_json::Value::Null,
        Some(b) => basis_json(b, data.clinical_frame.as_ref(), n)?,
    };
    let tissue = match &data.tissue {
        None => serde_json::Value::Null,
        Some(t) => tissue_json(t, n)?,
    };
    let (frame, frame_source) = match data.head_frame {
        Some(f) => (f, "the head frame"),
        None => (lps_frame(data.face_pre), "the CT's axes (no head frame)"),
    };
    let json = serde_json::json!({
        "title": data.title,
        "model": data.model,
        "face_pre": points(data.face_pre),
        "face_post": points(data.face_post),
        "face_triangles": triangles(data.face_triangles),
        "face_draw": index_base64(&draw_order(data.face_triangles, n)),
        "face_lod": index_base64(&lod(data.face_pre, data.face_triangles)),
        "skull_pre": points(data.skull_pre),
        "skull_post": points(data.skull_post),
        "skull_triangles": triangles(data.skull_triangles),
        "segments": data.segments,
        "skull_segment": base64(&data.skull_segment),
        "colour_scale_mm": data.colour_scale_mm,
        "figures": data.figures,
        "warnings": data.warnings,
        "basis": basis,
        "landmarks": landmarks,
        "missing_landmarks": data.missing_landmarks,
        "region_names": data.region_names,
        "region_of": base64(&data.region_of),
        "measurements": data.measurements,
        "ratios": data.ratios,
        "published": data.published,
        "band_width": data.band_width.as_ref().map(|b| {
            let f: Vec<f32> = b.iter().map(|x| *x as f32).collect();
            base64(&f32_bytes(&f))
        }),
        "uncertainty": data.uncertainty,
        "no_basis_reason": data.no_basis_reason,
        "head_frame": {
            "origin": frame.origin,
            "front": frame.front,
            "up": frame.up,
            "left": frame.left,
            "source": frame_source,
        },
        "clinical_frame": data.clinical_frame.as_ref().map(|c| serde_json::json!({
            "method": c.method,
            "origin": c.origin,
            "forward": c.forward,
            "up": c.up,
            "left": c.left,
        })),
        "tissue": tissue,
    });
    // "</" never appears inside the inline blocks: JSON may escape '/', and the bundle is built
    // without "</script" (web/build.mjs checks).
    let json = json.to_string().replace("</", "<\\/");
    Ok(format!(
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>facesim — {title}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n\
         <aside id=\"side\"></aside>\n<main id=\"view\"></main>\n\
         <script id=\"facesim-data\" type=\"application/json\">{json}</script>\n\
         <script>{BUNDLE}</script>\n</body>\n</html>\n",
        title = escape_html(&data.title),
    ))
}

/// That the face's, the skull's, the regions' and the band's per-vertex arrays match their
/// meshes.
fn check_lengths(data: &PageData) -> std::result::Result<(), String> {
    let n = data.face_pre.len();
    if data.face_post.len() != n {
        return Err(format!(
            "face_post has {} vertices, face_pre {n}",
            data.face_post.len()
        ));
    }
    if data.skull_post.len() != data.skull_pre.len()
        || data.skull_segment.len() != data.skull_pre.len()
    {
        return Err("skull_pre, skull_post and skull_segment differ in length".into());
    }
    if !data.region_of.is_empty() && data.region_of.len() != n {
        return Err(format!(
            "{} region indices for {n} face vertices",
            data.region_of.len()
        ));
    }
    if data.band_width.as_ref().is_some_and(|b| b.len() != n) {
        return Err(format!("band widths for other than {n} face vertices"));
    }
    Ok(())
}

/// The landmarks' block: each with its anchor on the face (a soft one) or its segment.
fn landmarks_json(data: &PageData) -> std::result::Result<Vec<serde_json::Value>, String> {
    let mut landmarks = Vec::new();
    for l in &data.landmarks {
        let anchor = match &l.anchor {
            Some(a) => {
                if a.triangle as usize >= data.face_triangles.len() {
                    return Err(format!("landmark '{}' anchored off the face", l.label));
                }
                serde_json::json!({
                    "triangle": a.triangle,
                    "weights": a.weights,
                    "offset": a.offset,
                })
            }
            None => serde_json::Value::Null,
        };
        landmarks.push(serde_json::json!({
            "label": l.label,
            "pre": l.pre,
            "post": l.post,
            "anchor": anchor,
            "segment": l.segment,
        }));
    }
    Ok(landmarks)
}

/// The plan basis's block: per segment its run's move (also read in the clinical frame, when
/// there is one) and its 12 columns of `n` face vertices as float32.
fn basis_json(
    b: &PageBasis,
    clinical_frame: Option<&PageClinicalFrame>,
    n: usize,
) -> std::result::Result<serde_json::Value, String> {
    let mut segs = Vec::new();
    for s in &b.segments {
        if s.columns.len() != 12 || s.columns.iter().any(|c| c.len() != n) {
            return Err(format!(
                "plan basis segment '{}': expected 12 columns of {n} vertices",
                s.name
            ));
        }
        let flat: Vec<f32> = s
            .columns
            .iter()
            .flat_map(|c| c.iter().flat_map(|p| p.map(|x| x as f32)))
            .collect();
        // The run's move read in the clinical frame: the clinical sliders' start.
        let moves = clinical_frame.map(|c| {
            let m = crate::anatomy::moves::read_back(
                &c.head_frame(),
                crate::osteotomy::rotation(s.rotate_deg),
                s.translate,
            );
            serde_json::json!({
                "advance_mm": m.advance_mm,
                "up_mm": m.up_mm,
                "left_mm": m.left_mm,
                "pitch_deg": m.pitch_deg,
                "roll_deg": m.roll_deg,
                "yaw_deg": m.yaw_deg,
            })
        });
        segs.push(serde_json::json!({
            "name": s.name,
            "pivot": s.pivot,
            "translate": s.translate,
            "rotate_deg": s.rotate_deg,
            "moves": moves,
            "columns": base64(&f32_bytes(&flat)),
        }));
    }
    Ok(serde_json::json!({ "label": b.label, "segments": segs }))
}

/// The tissue sliders' block: per model the online form as JSON numbers (f64, exact), the face
/// fields as float32 on the vertices any model moves (`vertices`, uint32): the rest of the face
/// (rigid skin, beyond the tissue region) is zero in every field and left out.
fn tissue_json(t: &PageTissue, n: usize) -> std::result::Result<serde_json::Value, String> {
    let mut moving = vec![false; n];
    for m in &t.models {
        let f = m.face;
        if f.lift.len() != n || f.columns.iter().any(|c| c.len() != n) {
            return Err(format!(
                "reduced model face fields for other than {n} face vertices"
            ));
        }
        let q = m.form.theta_bar.len();
        if f.columns.len() != m.form.loads.first().map_or(0, Vec::len)
            || m.terms.len() != q
            || m.theta_box.iter().any(|b| b.len() != q)
            || m.output_bounds.len() != t.landmarks.len()
            || !(m.duals.is_empty() || m.duals.len() == t.landmarks.len())
            || m.duals
                .iter()
                .any(|d| d.size() > 0 && !d.consistent(q, f.columns.len()))
        {
            return Err(
                "reduced model: terms, box, face columns, landmark gains or duals do not match its form"
                    .into(),
            );
        }
        for field in std::iter::once(&f.lift).chain(&f.columns) {
            for (v, p) in field.iter().enumerate() {
                moving[v] |= p.iter().any(|x| *x != 0.0);
            }
        }
    }
    let vertices: Vec<u32> = (0..n as u32).filter(|v| moving[*v as usize]).collect();
    let field = |f: &[[f64; 3]]| -> Vec<f32> {
        vertices
            .iter()
            .flat_map(|v| f[*v as usize].map(|x| x as f32))
            .collect()
    };
    let models: Vec<serde_json::Value> = t
        .models
        .iter()
        .map(|m| {
            let columns: Vec<f32> = m.face.columns.iter().flat_map(|c| field(c)).collect();
            serde_json::json!({
                "sliding": m.sliding,
                "form": m.form,
                "terms": m.terms,
                "theta_box": m.theta_box,
                "face_bound": m.face_bound,
                "output_bounds": m.output_bounds,
                "duals": m.duals.iter().map(dual_json).collect::<Vec<_>>(),
                "lift": base64(&f32_bytes(&field(&m.face.lift))),
                "columns": base64(&f32_bytes(&columns)),
            })
        })
        .collect();
    Ok(serde_json::json!({
        "tissues": crate::case::Tet::TISSUES
            .iter()
            .zip(&t.tissues)
            .map(|(name, m)| serde_json::json!({
                "name": name, "youngs_kpa": m.youngs_kpa, "poisson": m.poisson,
            }))
            .collect::<Vec<_>>(),
        "sliding": t.sliding,
        "sliding_matters": t.sliding_matters,
        "parameters": t.parameters,
        "landmarks": t.landmarks,
        "vertices": index_base64(&vertices),
        "models": models,
    }))
}

/// What the page looks like before its script has run (the bundle injects the real style sheet,
/// web/src/style.js).
const STYLE: &str = "html,body{margin:0;height:100%;font:14px/1.45 system-ui,sans-serif;\
color:#1d1d1d}body{display:flex}#side{width:330px}#view{flex:1}";

/// The head frame when the run has none: LPS (front −y, up +z, left +x) through the middle of
/// the face's bounding box.
fn lps_frame(face: &[[f64; 3]]) -> PageFrame {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in face {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let origin = if face.is_empty() {
        [0.0; 3]
    } else {
        [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]))
    };
    PageFrame {
        origin,
        front: [0.0, -1.0, 0.0],
        up: [0.0, 0.0, 1.0],
        left: [1.0, 0.0, 0.0],
    }
}

fn escape_html(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn points(p: &[[f64; 3]]) -> String {
    let flat: Vec<f32> = p.iter().flat_map(|v| v.map(|x| x as f32)).collect();
    base64(&f32_bytes(&flat))
}

fn triangles(t: &[[u32; 3]]) -> String {
    let bytes: Vec<u8> = t.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
    base64(&bytes)
}

/// How many of the face's triangles the page draws while a slider or the view is dragged.
const LOD_FRACTION: f64 = 0.25;
/// The largest surface deviation (mm) the dragging face may have from the full one.
const LOD_MAX_ERROR_MM: f32 = 0.5;

/// The triangles in an order that reuses transformed vertices (meshoptimizer's vertex cache
/// optimisation): software WebGL shades a vertex again for each triangle that misses its cache.
fn draw_order(t: &[[u32; 3]], vertices: usize) -> Vec<u32> {
    let idx: Vec<u32> = t.iter().flatten().copied().collect();
    meshopt::optimize_vertex_cache(&idx, vertices)
}

/// The face drawn while dragging: the same vertices, LOD_FRACTION of the triangles (quadric
/// simplification on face_pre, borders kept, error below LOD_MAX_ERROR_MM), in draw order. The
/// settled frame draws every triangle.
fn lod(v: &[[f64; 3]], t: &[[u32; 3]]) -> Vec<u32> {
    let pos: Vec<[f32; 3]> = v.iter().map(|p| p.map(|x| x as f32)).collect();
    let full: Vec<u32> = t.iter().flatten().copied().collect();
    let Ok(adapter) = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&pos), 12, 0) else {
        return draw_order(t, v.len());
    };
    let target = 3 * ((t.len() as f64 * LOD_FRACTION) as usize);
    let out = meshopt::simplify(
        &full,
        &adapter,
        target,
        LOD_MAX_ERROR_MM,
        meshopt::SimplifyOptions::LockBorder | meshopt::SimplifyOptions::ErrorAbsolute,
        None,
    );
    meshopt::optimize_vertex_cache(&out, v.len())
}

fn index_base64(i: &[u32]) -> String {
    base64(&i.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>())
}

/// A landmark's dual form for the page: its arrays as little-endian f64 in base64 (exact, and
/// about half the size of JSON numbers: the real CT's forms at R = 10 are 11 MB as numbers),
/// each array's parts one after another; the ragged Riesz columns with their lengths.
fn dual_json(d: &crate::reduced::dual::DualForm) -> serde_json::Value {
    let f64s = |parts: &[Vec<f64>]| -> String {
        base64(
            &parts
                .iter()
                .flatten()
                .flat_map(|x| x.to_le_bytes())
                .collect::<Vec<u8>>(),
        )
    };
    serde_json::json!({
        "m": d.size(),
        "unknowns": d.unknowns,
        "matrices": f64s(&d.matrices),
        "outputs": f64s(&d.outputs),
        "loads": f64s(&d.loads),
        "coupling": f64s(&d.coupling),
        "riesz": f64s(&d.riesz),
        "riesz_lengths": d.riesz.iter().map(Vec::len).collect::<Vec<_>>(),
        "riesz_norms": d.riesz_norms,
    })
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Standard base64 with padding (RFC 4648), what the page's `atob` reads.
pub(crate) fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn the_bundle_cannot_end_its_script_early() {
        assert!(!BUNDLE.to_ascii_lowercase().contains("</script"));
    }
}
