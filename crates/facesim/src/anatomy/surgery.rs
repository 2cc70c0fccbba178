//! `[[surgery]]` entries as osteotomies (docs/planning.md): each entry's segment cut from the
//! CT (`cuts`), its moves read in the clinical head frame (`moves`), its pivot a landmark.
//!
//! Segments are disjoint, each with the whole move of its bone: a chin cut from a mandible that
//! a BSSO or an autorotation also moves is taken out of that segment and moved by the genioplasty
//! after the mandible's move.

use super::cuts::{self, Cut, Found, Segment};
use super::moves::{self, Moves};
use super::Bone;
use crate::case::{Osteotomy, Pivot, Surgery, SurgeryKind};
use crate::landmarks::HeadFrame;
use crate::vec3::{add, norm, scale, sub};

/// The largest translation (mm) and rotation (degrees) a surgery may state.
pub const MAX_MOVE_MM: f64 = 20.0;
pub const MAX_TURN_DEG: f64 = 30.0;

/// One planned segment.
pub struct Planned {
    /// "le-fort-i", "bsso", "genioplasty" or "autorotation".
    pub what: &'static str,
    pub name: String,
    /// The moves as stated (for autorotation: the closing turn).
    pub stated: Moves,
    pub pivot: [f64; 3],
    /// The pivot's landmark, or "point".
    pub pivot_label: String,
    /// The segment's whole move, as an LPS osteotomy over the found segment.
    pub osteotomy: Osteotomy,
    pub segment: Segment,
}

/// A rigid transform p' = R (p − pivot) + pivot + t.
#[derive(Clone, Copy)]
struct Rigid {
    r: [[f64; 3]; 3],
    pivot: [f64; 3],
    t: [f64; 3],
}

impl Rigid {
    fn of(frame: &HeadFrame, m: &Moves, pivot: [f64; 3]) -> Rigid {
        Rigid {
            r: moves::rotation(frame, m),
            pivot,
            t: moves::translation(frame, m),
        }
    }

    fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let d = sub(p, self.pivot);
        let rd = [0, 1, 2].map(|i| (0..3).map(|k| self.r[i][k] * d[k]).sum::<f64>());
        add(add(rd, self.pivot), self.t)
    }

    /// `self` after `first`, about `first`'s pivot.
    fn after(&self, first: &Rigid) -> Rigid {
        let mut r = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                r[i][j] = (0..3).map(|k| self.r[i][k] * first.r[k][j]).sum();
            }
        }
        // p' = self(first(p)); at p = first.pivot, first gives pivot + t.
        let t = sub(self.apply(add(first.pivot, first.t)), first.pivot);
        Rigid {
            r,
            pivot: first.pivot,
            t,
        }
    }

    fn osteotomy(&self, name: &str, segment: &Segment) -> Osteotomy {
        Osteotomy {
            name: name.into(),
            region: segment.region(&format!("segment_{name}.nii.gz")),
            translate: self.t,
            rotate_deg: moves::lps_angles(self.r),
            pivot: self.pivot,
        }
    }
}

/// The segment name a kind takes by default.
pub fn default_name(kind: SurgeryKind) -> &'static str {
    match kind {
        SurgeryKind::LeFortI => "maxilla",
        SurgeryKind::Bsso => "mandible",
        SurgeryKind::Genioplasty => "chin",
    }
}

fn key(kind: SurgeryKind) -> &'static str {
    match kind {
        SurgeryKind::LeFortI => "le-fort-i",
        SurgeryKind::Bsso => "bsso",
        SurgeryKind::Genioplasty => "genioplasty",
    }
}

/// The landmark a pivot name means: a label of `super::LANDMARKS`, or one of the spoken names.
fn pivot_label(name: &str) -> &str {
    match name {
        "upper-incisor" => "U1",
        "lower-incisor" => "L1",
        "pogonion" => "Pog",
        "menton" => "Me",
        "gnathion" => "Gn",
        "a-point" => "A",
        "b-point" => "B",
        "anterior-nasal-spine" => "ANS",
        "posterior-nasal-spine" => "PNS",
        other => other,
    }
}

/// The pivot of a surgery: its named landmark (default per kind), or its point.
fn pivot_of(s: &Surgery, f: &Found) -> Result<([f64; 3], String), String> {
    let name = match &s.pivot {
        Some(Pivot::Point(p)) => return Ok((*p, "point".into())),
        Some(Pivot::Landmark(n)) => n.as_str(),
        None => match s.kind {
            SurgeryKind::LeFortI => "upper-incisor",
            SurgeryKind::Bsso => "lower-incisor",
            SurgeryKind::Genioplasty => "pogonion",
        },
    };
    if name == "condyles" {
        return match (f.at("Co-R"), f.at("Co-L")) {
            (Some(r), Some(l)) => Ok((scale(add(r, l), 0.5), "condyles".into())),
            _ => Err(format!("pivot \"condyles\" was not found: {}, {}", f.why("Co-R"), f.why("Co-L"))),
        };
    }
    let label = pivot_label(name);
    if !super::LANDMARKS.contains(&label) {
        return Err(format!(
            "pivot \"{name}\" is not a landmark (one of {}, upper-incisor, lower-incisor, pogonion, menton, gnathion, a-point, b-point, anterior-nasal-spine, posterior-nasal-spine, condyles) or a point [x, y, z]",
            super::LANDMARKS.join(", ")
        ));
    }
    f.at(label)
        .map(|p| (p, label.to_string()))
        .ok_or_else(|| format!("pivot \"{name}\" was not found: {}", f.why(label)))
}

fn stated(s: &Surgery) -> Moves {
    Moves {
        advance_mm: s.advance_mm,
        up_mm: s.up_mm,
        left_mm: s.left_mm,
        pitch_deg: s.pitch_deg,
        roll_deg: s.roll_deg,
        yaw_deg: s.yaw_deg,
    }
}

/// A stated move within the limits, finite.
fn check_size(m: &Moves) -> Result<(), String> {
    let t = [m.advance_mm, m.up_mm, m.left_mm];
    let a = [m.pitch_deg, m.roll_deg, m.yaw_deg];
    if t.iter().chain(&a).any(|v| !v.is_finite()) {
        return Err("its moves must be finite numbers".into());
    }
    let len = norm(t);
    if len > MAX_MOVE_MM {
        return Err(format!(
            "it moves the segment {len:.1} mm, more than {MAX_MOVE_MM} mm: check the units (mm) and the signs"
        ));
    }
    if let Some(x) = a.iter().find(|x| x.abs() > MAX_TURN_DEG) {
        return Err(format!(
            "it turns the segment {x} degrees, more than {MAX_TURN_DEG}: check the units (degrees)"
        ));
    }
    Ok(())
}

/// The closing turn of the mandible about the condylar axis that keeps the lower incisal edge
/// at its height below the moved upper one (degrees, right-handed about Co-R → Co-L).
fn closing_turn(f: &Found, frame: &HeadFrame, maxilla: &Rigid) -> Result<Rigid, String> {
    let need = |l: &str| f.at(l).ok_or_else(|| format!("autorotation needs {}", f.why(l)));
    let (co_r, co_l, u1, l1) = (need("Co-R")?, need("Co-L")?, need("U1")?, need("L1")?);
    let axis = sub(co_l, co_r);
    let axis = scale(axis, 1.0 / norm(axis).max(1e-12));
    let pivot = scale(add(co_r, co_l), 0.5);
    let height = |p: [f64; 3]| frame.coords(p)[1];
    let target = height(l1) + height(maxilla.apply(u1)) - height(u1);
    let turn = |deg: f64| Rigid {
        r: moves::about_axis(axis, deg),
        pivot,
        t: [0.0; 3],
    };
    let g = |deg: f64| height(turn(deg).apply(l1)) - target;
    let (mut lo, mut hi) = (-MAX_TURN_DEG, MAX_TURN_DEG);
    if g(lo).signum() == g(hi).signum() {
        return Err(format!(
            "autorotation cannot bring the lower incisors back to the upper ones within {MAX_TURN_DEG} degrees"
        ));
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid).signum() == g(lo).signum() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(turn(0.5 * (lo + hi)))
}

/// The planned segments of `surgeries`, in order; the autorotation's mandible follows its Le
/// Fort I. Err: one line naming the entry (1-based) and the problem.
pub fn plan(surgeries: &[Surgery], f: &Found, frame: &HeadFrame, bone: &Bone) -> Result<Vec<Planned>, String> {
    let count = |k: SurgeryKind| surgeries.iter().filter(|s| s.kind == k).count();
    for k in [SurgeryKind::LeFortI, SurgeryKind::Bsso, SurgeryKind::Genioplasty] {
        if count(k) > 1 {
            return Err(format!("[[surgery]]: {} appears {} times; one of each kind", key(k), count(k)));
        }
    }
    let rotating = surgeries.iter().any(|s| s.autorotate);
    if rotating && count(SurgeryKind::Bsso) > 0 {
        return Err("[[surgery]]: autorotate with a bsso: the bsso places the mandible; drop one".into());
    }
    let mut out: Vec<Planned> = Vec::new();
    // The mandible's move a genioplasty's chin follows, and the mandible's cuts.
    let mut carrier: Option<(usize, Rigid)> = None;
    let mut chin: Option<(usize, &Surgery, Rigid, Cut)> = None;
    for (i, s) in surgeries.iter().enumerate() {
        let at = |e: String| format!("[[surgery]] {} ({}): {e}", i + 1, key(s.kind));
        if s.autorotate && s.kind != SurgeryKind::LeFortI {
            return Err(at("autorotate applies to a le-fort-i".into()));
        }
        let m = stated(s);
        check_size(&m).map_err(at)?;
        let (pivot, pivot_label) = pivot_of(s, f).map_err(at)?;
        let cut = cuts::cut(s.kind, f, frame).map_err(at)?;
        let rigid = Rigid::of(frame, &m, pivot);
        let name = s.name.clone().unwrap_or_else(|| default_name(s.kind).into());
        match s.kind {
            SurgeryKind::Genioplasty => {
                chin = Some((i, s, rigid, cut));
                continue;
            }
            SurgeryKind::Bsso => carrier = Some((out.len(), rigid)),
            SurgeryKind::LeFortI => {}
        }
        let segment = cuts::segment(bone, &[&cut], &name).map_err(at)?;
        out.push(Planned {
            what: key(s.kind),
            osteotomy: rigid.osteotomy(&name, &segment),
            name,
            stated: m,
            pivot,
            pivot_label,
            segment,
        });
        if s.autorotate {
            let turn = closing_turn(f, frame, &rigid).map_err(at)?;
            let (body, rami) = cuts::mandible(f, frame).map_err(at)?;
            let segment = cuts::segment(bone, &[&body, &rami], "mandible").map_err(at)?;
            let name = "mandible".to_string();
            carrier = Some((out.len(), turn));
            out.push(Planned {
                what: "autorotation",
                osteotomy: turn.osteotomy(&name, &segment),
                name,
                stated: moves::read_back(frame, turn.r, turn.t),
                pivot: turn.pivot,
                pivot_label: "condyles".into(),
                segment,
            });
        }
    }
    if let Some((i, s, rigid, cut)) = chin {
        let at = |e: String| format!("[[surgery]] {} (genioplasty): {e}", i + 1);
        let name = s.name.clone().unwrap_or_else(|| "chin".into());
        let segment = cuts::segment(bone, &[&cut], &name).map_err(at)?;
        let whole = match &carrier {
            Some((k, first)) => {
                // The chin leaves the mandible's segment and moves with it, then by its own
                // moves about the moved pivot.
                let parent = out[*k].segment.minus(&segment);
                let moved_pivot = first.apply(rigid.pivot);
                let own = Rigid { pivot: moved_pivot, ..rigid };
                let p = &mut out[*k];
                p.osteotomy = first.osteotomy(&p.name, &parent);
                p.segment = parent;
                own.after(first)
            }
            None => rigid,
        };
        out.push(Planned {
            what: "genioplasty",
            osteotomy: whole.osteotomy(&name, &segment),
            name,
            stated: stated(s),
            pivot: rigid.pivot,
            pivot_label: pivot_of(s, f).map(|p| p.1).unwrap_or_default(),
            segment,
        });
    }
    let mut names: Vec<&str> = out.iter().map(|p| p.name.as_str()).collect();
    names.sort();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(format!("[[surgery]]: two segments are named '{}'; give one a `name`", w[0]));
    }
    Ok(out)
}
