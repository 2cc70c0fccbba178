//! The facial regions — nose, upper lip, lower lip, chin, cheeks, in that order ([`NAMES`]) —
//! as sets of skin vertices: the one place that names them, orders them and decides membership.
//! A vertex belongs to at most one region (the first that claims it); a region whose bounding
//! landmarks are missing is absent, with the reason.
//!
//! - [`regions`]: from the run's landmarks (docs/guide/landmarks.md "Regions"), by height v, lateral
//!   offset s and anteriority a in the head frame. Every run with landmarks uses these: the
//!   report's per-region statistics, the uncertainty study, the sweep, `compare --regions`.
//! - [`profile::regions`]: the fallback for a face without landmarks (the solver study's meshes,
//!   the sweep of a run whose report has none): the same regions from the soft-tissue profile of
//!   the skin alone, in LPS (anterior −y, superior +z), with the profile's own landmarks.

pub mod profile;

use super::frame::HeadFrame;
use super::landmark::Ordered;
use serde::{Deserialize, Serialize};

pub const NAMES: [&str; 5] = ["nose", "upper lip", "lower lip", "chin", "cheeks"];

#[derive(Clone, Debug)]
pub struct Regions {
    /// Per region of [`NAMES`]: its member flags per vertex, or None when absent.
    pub members: Vec<Option<Vec<bool>>>,
    pub absent: Vec<Option<String>>,
    pub notes: Vec<Option<String>>,
}

/// A vertex in no region (in [`Regions::index`]).
pub(crate) const NONE: u8 = 255;

impl Regions {
    /// Per vertex (of `n`), the index in [`NAMES`] of its region, or `NONE`.
    pub fn index(&self, n: usize) -> Vec<u8> {
        let mut out = vec![NONE; n];
        for (k, m) in self.members.iter().enumerate() {
            for (o, _) in out.iter_mut().zip(m.iter().flatten()).filter(|(_, b)| **b) {
                *o = k as u8;
            }
        }
        out
    }
}

/// The regions of the skin vertices `v` from landmarks (label, LPS position).
pub fn regions(v: &[[f64; 3]], frame: &HeadFrame, lms: &[(String, [f64; 3])]) -> Regions {
    let c: Vec<[f64; 3]> = v.iter().map(|p| frame.coords(*p)).collect();
    let get = |l: &str| {
        lms.iter()
            .find(|(k, _)| k == l)
            .map(|(_, p)| frame.coords(*p))
    };
    // The lowest skin height near the midline: where the scan ends.
    let bottom = c
        .iter()
        .filter(|q| q[0].abs() < 10.0)
        .map(|q| q[1])
        .fold(f64::INFINITY, f64::min);
    let (prn, sn, ls, sto, li, bs, pgs, mes, ns) = (
        get("Prn"),
        get("Sn"),
        get("Ls"),
        get("Sto"),
        get("Li"),
        get("B'"),
        get("Pog'"),
        get("Me'"),
        get("N'"),
    );
    // The lip line, or where the scan ends inside the upper lip.
    let (lip_line, cut) = match (sto, ls) {
        (Some(s), _) => (Some(s[1]), None),
        (None, Some(_)) => (
            Some(bottom - 1.0),
            Some(format!(
                "cut by the scan's end {:.0} mm below the nose tip",
                prn.map_or(0.0, |p| p[1] - bottom)
            )),
        ),
        _ => (None, None),
    };
    type Test = Box<dyn Fn(&[f64; 3]) -> bool>;
    let need = |what: &str| format!("absent: needs {what}, which the face lacks");
    let mut defs: Vec<(std::result::Result<Test, String>, Option<String>)> = Vec::new();
    defs.push(match (sn, prn) {
        (Some(sn), Some(prn)) => {
            let top = ns.map_or(prn[1] + 30.0, |n| n[1]);
            (
                Ok(Box::new(move |q: &[f64; 3]| {
                    q[1] > sn[1] && q[1] < top && q[0].abs() < 20.0 && q[2] > sn[2]
                })),
                None,
            )
        }
        _ => (Err(need("subnasale and pronasale")), None),
    });
    let band = |lo: f64, hi: f64, front: f64| -> Test {
        Box::new(move |q: &[f64; 3]| {
            q[1] > lo && q[1] <= hi && q[0].abs() < 25.0 && q[2] > front - 15.0
        })
    };
    defs.push(match (lip_line, sn, ls) {
        (Some(lo), Some(sn), Some(ls)) => (Ok(band(lo, sn[1], ls[2])), cut.clone()),
        _ => (Err(need("subnasale, labrale superius and stomion")), None),
    });
    defs.push(match (bs, sto, li) {
        (Some(b), Some(s), Some(l)) => (Ok(band(b[1], s[1], l[2])), None),
        _ => (
            Err(need("stomion, labrale inferius and soft B point")),
            None,
        ),
    });
    defs.push(match (bs, pgs) {
        (Some(b), Some(p)) => {
            let lo = mes.map_or(p[1] - 20.0, |m| m[1] - 2.0);
            (Ok(band(lo, b[1], p[2])), None)
        }
        _ => (Err(need("soft B point and soft pogonion")), None),
    });
    defs.push(match (lip_line, prn) {
        (Some(lo), Some(prn)) => (
            Ok(Box::new(move |q: &[f64; 3]| {
                q[1] > lo
                    && q[1] < prn[1] + 20.0
                    && (25.0..60.0).contains(&q[0].abs())
                    && q[2] > prn[2] - 45.0
            })),
            cut,
        ),
        _ => (
            Err(need("pronasale and stomion (or labrale superius)")),
            None,
        ),
    });
    let mut claimed = vec![false; v.len()];
    let mut members = Vec::new();
    let mut absent = Vec::new();
    let mut notes = Vec::new();
    for (test, note) in defs {
        match test {
            Ok(t) => {
                let m: Vec<bool> = c
                    .iter()
                    .zip(claimed.iter_mut())
                    .map(|(q, k)| {
                        let inside = !*k && t(q);
                        *k |= inside;
                        inside
                    })
                    .collect();
                if m.iter().any(|b| *b) {
                    members.push(Some(m));
                    absent.push(None);
                } else {
                    members.push(None);
                    absent.push(Some("absent: no skin vertex inside".into()));
                }
                notes.push(note);
            }
            Err(why) => {
                members.push(None);
                absent.push(Some(why));
                notes.push(None);
            }
        }
    }
    Regions {
        members,
        absent,
        notes,
    }
}

/// report.json `regions`: the displacement (mm) over each region's vertices.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RegionStats {
    pub vertices: usize,
    pub mean: Option<f64>,
    pub p90: Option<f64>,
    pub max: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub absent: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

fn p90(mut d: Vec<f64>) -> f64 {
    d.sort_by(f64::total_cmp);
    d[((0.9 * (d.len() - 1) as f64).round()) as usize]
}

/// The values of `dist` (one per vertex) at the vertices flagged in `member`.
fn in_region(member: &[bool], dist: &[f64]) -> Vec<f64> {
    dist.iter()
        .zip(member)
        .filter(|(_, b)| **b)
        .map(|(d, _)| *d)
        .collect()
}

/// Per region: count, mean, 90th percentile and max of `dist` (one value per vertex).
pub(crate) fn displacement_stats(r: &Regions, dist: &[f64]) -> Ordered<RegionStats> {
    let mut out = Ordered::default();
    for (k, name) in NAMES.iter().enumerate() {
        let d = r.members[k]
            .as_ref()
            .map(|m| in_region(m, dist))
            .unwrap_or_default();
        out.0.push((
            name.to_string(),
            stats_of(d, r.absent[k].clone(), r.notes[k].clone()),
        ));
    }
    out
}

/// Count, mean, max and 90th percentile of `d` (non-negative values, one per vertex).
pub(crate) fn stats_of(d: Vec<f64>, absent: Option<String>, note: Option<String>) -> RegionStats {
    let n = d.len();
    RegionStats {
        vertices: n,
        mean: (n > 0).then(|| d.iter().sum::<f64>() / n as f64),
        max: (n > 0).then(|| d.iter().cloned().fold(0.0, f64::max)),
        p90: (n > 0).then(|| p90(d)),
        absent,
        note,
    }
}

/// `facesim compare A B --regions OUT_DIR`: per region, A's vertices' distances to surface B
/// (mean absolute, p90, % within 2 mm, …). The regions come from the run in `out_dir`: its
/// face_pre.ply (head frame) and landmarks_pre.mrk.json; membership is decided on face_pre's
/// vertices when A has their count (A is then that run's face, e.g. face_post), else on A's.
pub fn compare_regions(
    a: &crate::mesh::Mesh,
    b: &crate::mesh::Mesh,
    out_dir: &std::path::Path,
) -> crate::error::Result<Ordered<RegionDistance>> {
    use crate::error::Error;
    let pre_path = out_dir.join("face_pre.ply");
    let pre = crate::mesh::read_mesh(&pre_path)?;
    let lms = super::markups::read(&out_dir.join("landmarks_pre.mrk.json"))?;
    let frame = super::frame::head_frame(&pre)
        .ok_or_else(|| Error::input(&pre_path, "the face has no vertices"))?;
    let on = if pre.vertices.len() == a.vertices.len() {
        &pre.vertices
    } else {
        &a.vertices
    };
    let r = regions(on, &frame, &lms);
    Ok(distance_stats(
        &r,
        &crate::compare::point_to_surface(&a.vertices, b),
    ))
}

/// Per region of `r`: its vertices' distances `dist` (one per vertex, mm) summarised
/// (`compare --regions`, `compare --landmarks`).
pub(crate) fn distance_stats(r: &Regions, dist: &[f64]) -> Ordered<RegionDistance> {
    let mut out = Ordered::default();
    for (k, name) in NAMES.iter().enumerate() {
        let d = r.members[k].as_ref().map(|m| in_region(m, dist));
        out.0.push((
            name.to_string(),
            RegionDistance {
                vertices: d.as_ref().map_or(0, Vec::len),
                stats: d.map(|d| crate::compare::stats(&d)),
                absent: r.absent[k].clone(),
            },
        ));
    }
    out
}

/// One region of `compare --regions`: A's vertices there and their distances to B (mm).
#[derive(Clone, Debug, Serialize)]
pub struct RegionDistance {
    pub vertices: usize,
    #[serde(flatten)]
    pub stats: Option<crate::compare::DistanceStats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub absent: Option<String>,
}
