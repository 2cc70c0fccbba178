//! `[[surgery]]` entries as osteotomies (docs/guide/planning.md): each entry's segment cut from the
//! CT (`cuts`), its moves read in the clinical head frame (`moves`), its pivot a landmark.
//!
//! Segments are disjoint, each with the whole move of its bone: a chin cut from a mandible that
//! a BSSO or an autorotation also moves is taken out of that segment and moved by the genioplasty
//! after the mandible's move.

use super::bone::{Bone, LANDMARKS};
use super::cuts::{self, Cut, Found, Segment};
use super::moves::{self, Moves};
use crate::case::{Osteotomy, Pivot, Surgery, SurgeryKind};
use crate::landmarks::HeadFrame;
use crate::vec3::{add, norm, scale, sub};

use crate::case::MAX_TURN_DEG;

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
    /// How its cut was placed where the user should know (run warnings).
    pub notes: Vec<String>,
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

/// The landmark a pivot name means: a label of `LANDMARKS`, or one of the spoken names.
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
            _ => Err(format!(
                "pivot \"condyles\" was not found: {}, {}",
                f.why("Co-R"),
                f.why("Co-L")
            )),
        };
    }
    let label = pivot_label(name);
    if !LANDMARKS.contains(&label) {
        return Err(format!(
            "pivot \"{name}\" is not a landmark (one of {}, upper-incisor, lower-incisor, pogonion, menton, gnathion, a-point, b-point, anterior-nasal-spine, posterior-nasal-spine, condyles) or a point [x, y, z]",
            LANDMARKS.join(", ")
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

/// What `[[surgery]]` entries can be told wrong without the CT (`crate::case`'s checks, at
/// load) and pivot names that are no landmark. Err: one line naming the entry (1-based).
pub(crate) fn check_entries(surgeries: &[Surgery]) -> Result<(), String> {
    crate::case::check_surgeries(surgeries)?;
    for (i, s) in surgeries.iter().enumerate() {
        if let Some(Pivot::Landmark(n)) = &s.pivot
            && n != "condyles"
            && !LANDMARKS.contains(&pivot_label(n))
        {
            return Err(format!(
                "[[surgery]] {} ({}): pivot \"{n}\" is not a landmark (one of {}, upper-incisor, lower-incisor, pogonion, menton, gnathion, a-point, b-point, anterior-nasal-spine, posterior-nasal-spine, condyles) or a point [x, y, z]",
                i + 1,
                s.kind.key(),
                LANDMARKS.join(", ")
            ));
        }
    }
    Ok(())
}

/// The closing turn of the mandible about the condylar axis that keeps the lower incisal edge
/// at its height below the moved upper one (degrees, right-handed about Co-R → Co-L).
fn closing_turn(f: &Found, frame: &HeadFrame, maxilla: &Rigid) -> Result<Rigid, String> {
    let need = |l: &str| {
        f.at(l)
            .ok_or_else(|| format!("autorotation needs {}", f.why(l)))
    };
    let (co_r, co_l, l1) = (need("Co-R")?, need("Co-L")?, need("L1")?);
    // The maxilla's move at the upper incisal edge; without it (a field of view ending in the
    // crowns) at the lower one, where the edges meet.
    let u1 = f.at("U1").unwrap_or(l1);
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

/// One segment's move, before its bone is cut: what `replan` needs (the run's segments are
/// reused) and what [`plan`] cuts the bone for.
pub struct Move {
    pub what: &'static str,
    pub name: String,
    pub stated: Moves,
    pub pivot: [f64; 3],
    pub pivot_label: String,
    /// The whole move (a chin on a moved mandible: the mandible's, then its own).
    rigid: Rigid,
    /// The cut, or for the autorotation the mandible's two parts.
    cuts: Vec<Cut>,
    /// The segment (index in the list) the chin is taken out of.
    parent: Option<usize>,
    /// The entry (1-based) that asked for it.
    entry: usize,
}

impl Move {
    /// The osteotomy of this move over `region` (a run's segment, for `replan`).
    pub(crate) fn osteotomy_over(&self, region: crate::case::Region) -> Osteotomy {
        Osteotomy {
            name: self.name.clone(),
            region,
            translate: self.rigid.t,
            rotate_deg: moves::lps_angles(self.rigid.r),
            pivot: self.rigid.pivot,
        }
    }
}

/// The moves of `surgeries` in the frame, in order (the autorotation's mandible after its Le
/// Fort I, a chin last), each with its cut. Err: one line naming the entry (1-based) and the
/// problem.
pub(crate) fn moves_of(
    surgeries: &[Surgery],
    f: &Found,
    frame: &HeadFrame,
) -> Result<Vec<Move>, String> {
    check_entries(surgeries)?;
    let mut out: Vec<Move> = Vec::new();
    // The mandible's move a genioplasty's chin follows.
    let mut carrier: Option<(usize, Rigid)> = None;
    let mut chin: Option<Move> = None;
    for (i, s) in surgeries.iter().enumerate() {
        let at = |e: String| format!("[[surgery]] {} ({}): {e}", i + 1, s.kind.key());
        let m = stated(s);
        let cut = cuts::cut(s.kind, f, frame).map_err(at)?;
        let turns = [m.pitch_deg, m.roll_deg, m.yaw_deg]
            .iter()
            .any(|a| *a != 0.0);
        let (pivot, pivot_label) = match pivot_of(s, f) {
            Ok(p) => p,
            // Without a turn the pivot does not matter: any landmark the segment has.
            Err(_) if !turns && s.pivot.is_none() => {
                let any = ["U1", "A", "ANS", "L1", "B", "Pog", "Me"]
                    .iter()
                    .find_map(|l| f.at(l))
                    .unwrap_or(frame.origin);
                (any, "point".into())
            }
            Err(e) => return Err(at(e)),
        };
        let rigid = Rigid::of(frame, &m, pivot);
        let mv = Move {
            what: s.kind.key(),
            name: s
                .name
                .clone()
                .unwrap_or_else(|| default_name(s.kind).into()),
            stated: m,
            pivot,
            pivot_label,
            rigid,
            cuts: vec![cut],
            parent: None,
            entry: i + 1,
        };
        match s.kind {
            SurgeryKind::Genioplasty => {
                chin = Some(mv);
                continue;
            }
            SurgeryKind::Bsso => carrier = Some((out.len(), rigid)),
            SurgeryKind::LeFortI => {}
        }
        out.push(mv);
        if s.autorotate {
            let turn = closing_turn(f, frame, &rigid).map_err(at)?;
            let (body, rami) = cuts::mandible(f, frame).map_err(at)?;
            carrier = Some((out.len(), turn));
            out.push(Move {
                what: "autorotation",
                name: "mandible".into(),
                stated: moves::read_back(frame, turn.r, turn.t),
                pivot: turn.pivot,
                pivot_label: "condyles".into(),
                rigid: turn,
                cuts: vec![body, rami],
                parent: None,
                entry: i + 1,
            });
        }
    }
    if let Some(mut c) = chin {
        if let Some((k, first)) = carrier {
            // The chin leaves the mandible's segment and moves with it, then by its own moves
            // about the moved pivot.
            let own = Rigid {
                pivot: first.apply(c.rigid.pivot),
                ..c.rigid
            };
            c.rigid = own.after(&first);
            c.parent = Some(k);
        }
        out.push(c);
    }
    let mut names: Vec<&str> = out.iter().map(|p| p.name.as_str()).collect();
    names.sort();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(format!(
            "[[surgery]]: two segments are named '{}'; give one a `name`",
            w[0]
        ));
    }
    Ok(out)
}

/// The planned segments of `surgeries` ([`moves_of`]), each cut from the CT's bone.
pub fn plan(
    surgeries: &[Surgery],
    f: &Found,
    frame: &HeadFrame,
    bone: &Bone,
) -> Result<Vec<Planned>, String> {
    let moves = moves_of(surgeries, f, frame)?;
    let mut segments = Vec::with_capacity(moves.len());
    for m in &moves {
        let at = |e: String| format!("[[surgery]] {} ({}): {e}", m.entry, m.what);
        let refs: Vec<&Cut> = m.cuts.iter().collect();
        let seg = cuts::segment(bone, &refs, &m.name).map_err(at)?;
        segments.push(seg);
    }
    for (k, m) in moves.iter().enumerate() {
        if let Some(p) = m.parent {
            segments[p] = segments[p].minus(&segments[k]);
        }
    }
    Ok(moves
        .into_iter()
        .zip(segments)
        .map(|(m, segment)| Planned {
            notes: m.cuts.iter().filter_map(|c| c.note.clone()).collect(),
            what: m.what,
            osteotomy: m.rigid.osteotomy(&m.name, &segment),
            name: m.name,
            stated: m.stated,
            pivot: m.pivot,
            pivot_label: m.pivot_label,
            segment,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::Case;
    use crate::landmarks::{Kind, Landmark, Source};
    use crate::osteotomy::Plan;
    use crate::vec3::dot;
    use std::path::Path;
    use std::sync::OnceLock;

    struct Phantom {
        vol: Volume,
        labels: Vec<u8>,
    }
    use crate::volume::Volume;

    /// The jaws phantom at 1.5 mm with its default tissue windows.
    fn phantom() -> &'static Phantom {
        static P: OnceLock<Phantom> = OnceLock::new();
        P.get_or_init(|| {
            let vol = crate::test_phantoms::jaws_ct();
            let seg = crate::segment::segment(&vol, &Case::default().tissue, Path::new("phantom"))
                .unwrap();
            Phantom {
                vol,
                labels: seg.labels,
            }
        })
    }

    /// The upright frame of the phantom (left +x, up +z, forward −y).
    fn frame() -> HeadFrame {
        HeadFrame::with_up([0.0, -70.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.0)
    }

    /// The landmarks the cuts need, on the phantom: its analytic incisor tips, A, B, pogonion,
    /// menton and condyles (`phantom_jaws::landmarks`), and the rest placed on its geometry
    /// (docs/design/phantom.md "Jaws"): apices 23.5 and 21 mm from the edges (the phantom has crowns
    /// and no roots), the piriform rim and ANS at the maxilla's top (z 1, under the Le Fort I
    /// gap at 1.5–4.5), the pterygomaxillary junctions behind the maxilla (y −12), the first
    /// molars on the upper arch at z −23, the mental foramina on the lower arch's labial face.
    fn fixture() -> Vec<Landmark> {
        let at = |n: &str| facesim_validate::phantom_jaws::landmark(n).unwrap();
        let up = |p: [f64; 3], d: f64| [p[0], p[1], p[2] + d];
        let u1 = at("upper incisor tip");
        let l1 = at("lower incisor tip");
        let (pog, me) = (at("pogonion"), at("menton"));
        let points: Vec<(&str, [f64; 3])> = vec![
            ("ANS", [0.0, -71.0, 1.0]),
            ("A", at("A point")),
            ("PNS", [0.0, -14.0, -4.0]),
            ("Pir-R", [-10.0, -68.0, 1.0]),
            ("Pir-L", [10.0, -68.0, 1.0]),
            ("PTM-R", [-33.0, -12.0, -5.0]),
            ("PTM-L", [33.0, -12.0, -5.0]),
            ("U1", u1),
            ("U1-apex", up(u1, 23.5)),
            ("L1", l1),
            ("L1-apex", up(l1, -21.0)),
            ("U6-R", [-29.0, -42.0, -23.0]),
            ("U6-L", [29.0, -42.0, -23.0]),
            ("B", at("B point")),
            ("Pog", pog),
            ("Gn", scale(add(pog, me), 0.5)),
            ("Me", me),
            ("MF-R", [-22.0, -54.0, -46.0]),
            ("MF-L", [22.0, -54.0, -46.0]),
            ("Go-R", [-43.0, 15.0, -56.0]),
            ("Go-L", [43.0, 15.0, -56.0]),
            ("Co-R", up(at("condyle right"), 4.0)),
            ("Co-L", up(at("condyle left"), 4.0)),
        ];
        points
            .into_iter()
            .map(|(l, p)| Landmark {
                label: l.into(),
                kind: Kind::Bone,
                position: Some(p),
                source: Source::Detected,
                missing: None,
            })
            .collect()
    }

    fn surgery(kind: SurgeryKind) -> Surgery {
        Surgery {
            kind,
            advance_mm: 0.0,
            up_mm: 0.0,
            left_mm: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
            yaw_deg: 0.0,
            pivot: None,
            autorotate: false,
            name: None,
        }
    }

    fn planned(s: &[Surgery], lms: &[Landmark]) -> Result<Vec<Planned>, String> {
        let p = phantom();
        let bone = Bone {
            vol: &p.vol,
            labels: &p.labels,
        };
        plan(s, &Found { landmarks: lms }, &frame(), &bone)
    }

    /// The share of the phantom's bone voxels satisfying `part` that `seg` holds.
    fn share(seg: &Planned, part: impl Fn([f64; 3]) -> bool) -> f64 {
        let p = phantom();
        let region = seg.segment.region("");
        let (mut n, mut inside) = (0usize, 0usize);
        for idx in 0..p.labels.len() {
            if p.labels[idx] != crate::labels::BONE {
                continue;
            }
            let c = p.vol.ijk(idx);
            let w = p.vol.to_world([c[0] as f64, c[1] as f64, c[2] as f64]);
            if part(w) {
                n += 1;
                inside += region.contains(w) as usize;
            }
        }
        assert!(n > 100, "the phantom has bone there");
        inside as f64 / n as f64
    }

    #[test]
    fn each_cut_frees_the_phantoms_bone_of_its_segment_and_nothing_else() {
        let lms = fixture();
        let all = planned(
            &[
                surgery(SurgeryKind::LeFortI),
                surgery(SurgeryKind::Bsso),
                surgery(SurgeryKind::Genioplasty),
            ],
            &lms,
        )
        .unwrap();
        let [maxilla, mandible, chin] = [&all[0], &all[1], &all[2]];
        // Maxilla and upper teeth: below the Le Fort I gap, above the occlusion, in front of
        // the skull base's plates.
        assert!(share(maxilla, |p| p[2] < 1.0 && p[2] > -23.5 && p[1] < -14.0) > 0.98);
        assert_eq!(share(maxilla, |p| p[2] > 5.0), 0.0, "no cranium");
        assert_eq!(share(maxilla, |p| p[2] < -26.0), 0.0, "no mandible");
        // The distal segment: the tooth-bearing body in front of the split, without the chin.
        assert!(share(mandible, |p| p[2] < -26.0 && p[2] > -45.0 && p[1] < -35.0) > 0.98);
        // The rami (y −8..18) stay: the split is at their anterior border.
        assert_eq!(share(mandible, |p| p[1] > -8.0), 0.0, "no ramus or condyle");
        assert_eq!(
            share(mandible, |p| p[2] < -61.0 && p[1] < -50.0),
            0.0,
            "no chin"
        );
        // The chin: below the cut under the apices and foramina.
        assert!(share(chin, |p| p[2] < -59.0 && p[1] < -50.0) > 0.98);
        assert_eq!(
            share(chin, |p| p[2] > -45.0),
            0.0,
            "nothing at the foramina's level or above"
        );
    }

    /// The moved position of p under the plan of `all`.
    fn moved(all: &[Planned], p: [f64; 3]) -> [f64; 3] {
        let steps: Vec<Osteotomy> = all.iter().map(|p| p.osteotomy.clone()).collect();
        Plan::new(&steps).apply(&[p], 1.0).0[0]
    }

    fn close(a: [f64; 3], b: [f64; 3]) {
        assert!(norm(sub(a, b)) < 1e-9, "{a:?} vs {b:?}");
    }

    #[test]
    fn the_plan_moves_each_pivot_landmark_exactly_as_stated_in_the_head_frame() {
        let lms = fixture();
        let f = Found { landmarks: &lms };
        let fr = frame();
        let lf = Surgery {
            advance_mm: 5.0,
            up_mm: 2.0,
            pitch_deg: 3.0,
            ..surgery(SurgeryKind::LeFortI)
        };
        let bsso = Surgery {
            advance_mm: -4.0,
            yaw_deg: 2.0,
            ..surgery(SurgeryKind::Bsso)
        };
        let genio = Surgery {
            advance_mm: 6.0,
            up_mm: 2.0,
            ..surgery(SurgeryKind::Genioplasty)
        };
        let all = planned(&[lf, bsso, genio], &lms).unwrap();
        let u1 = f.at("U1").unwrap();
        close(
            moved(&all, u1),
            add(u1, add(scale(fr.anterior, 5.0), scale(fr.vertical, 2.0))),
        );
        let l1 = f.at("L1").unwrap();
        close(moved(&all, l1), sub(l1, scale(fr.anterior, 4.0)));
        // The chin rides on the distal segment's setback, then moves by its own.
        // Menton: in the chin (pogonion sits at this phantom's cut, under the canine apices).
        let pog = f.at("Me").unwrap();
        let bsso_turn = Rigid::of(&fr, &all[1].stated, l1);
        let expect = add(
            bsso_turn.apply(pog),
            add(scale(fr.anterior, 6.0), scale(fr.vertical, 2.0)),
        );
        close(moved(&all, pog), expect);
        // Read back in the frame, each segment's moves are the stated ones.
        let back = moves::read_back(
            &fr,
            crate::osteotomy::rotation(all[0].osteotomy.rotate_deg),
            all[0].osteotomy.translate,
        );
        assert!(
            (back.pitch_deg - 3.0).abs() < 1e-9 && (back.advance_mm - 5.0).abs() < 1e-9,
            "{back:?}"
        );
        // A 3° clockwise turn about the incisor lifts the maxilla behind it (a point in the
        // alveolar bone 25 mm behind the incisors).
        let u6 = [-22.0, -48.0, -5.0];
        let d = sub(
            moved(&all, u6),
            add(u6, add(scale(fr.anterior, 5.0), scale(fr.vertical, 2.0))),
        );
        assert!(dot(d, fr.vertical) > 1.0, "{d:?}");
    }

    #[test]
    fn an_impaction_with_autorotation_closes_the_mandible_until_the_incisors_meet_again() {
        let lms = fixture();
        let f = Found { landmarks: &lms };
        let fr = frame();
        let lf = Surgery {
            up_mm: 4.0,
            autorotate: true,
            ..surgery(SurgeryKind::LeFortI)
        };
        let all = planned(&[lf], &lms).unwrap();
        assert_eq!(all.len(), 2);
        assert_eq!(all[1].what, "autorotation");
        let (u1, l1) = (f.at("U1").unwrap(), f.at("L1").unwrap());
        let rise = |p: [f64; 3]| fr.coords(moved(&all, p))[1] - fr.coords(p)[1];
        assert!((rise(u1) - 4.0).abs() < 1e-9);
        assert!((rise(l1) - 4.0).abs() < 1e-6, "{}", rise(l1));
        // Closing about the condyles: the chin comes forward, the condyles stay.
        assert!(
            fr.coords(moved(&all, f.at("Pog").unwrap()))[2] > fr.coords(f.at("Pog").unwrap())[2]
        );
        let co = f.at("Co-R").unwrap();
        assert!(norm(sub(moved(&all, co), co)) < 0.5);
        assert!(
            all[1].stated.pitch_deg < -1.0,
            "closing is a negative pitch: {:?}",
            all[1].stated
        );
    }

    #[test]
    fn bad_plans_are_one_line_naming_the_entry_and_what_is_missing() {
        let lms = fixture();
        let err = |s: Surgery, lms: &[Landmark]| planned(&[s], lms).err().unwrap();
        // No mandible.
        let upper: Vec<Landmark> = lms
            .iter()
            .map(|l| {
                if [
                    "L1", "L1-apex", "B", "Pog", "Gn", "Me", "MF-R", "MF-L", "Go-R", "Go-L",
                    "Co-R", "Co-L",
                ]
                .contains(&l.label.as_str())
                {
                    Landmark::missing(
                        &l.label,
                        Kind::Bone,
                        "the CT's field of view ends above the mandible".into(),
                    )
                } else {
                    l.clone()
                }
            })
            .collect();
        let e = err(surgery(SurgeryKind::Bsso), &upper);
        assert!(e.starts_with("[[surgery]] 1 (bsso): a BSSO needs the mandible; needs L1 (the CT's field of view ends above the mandible)"), "{e}");
        let e = err(surgery(SurgeryKind::Genioplasty), &upper);
        assert!(e.contains("L1-apex (the CT's field of view"), "{e}");
        // A pivot that was not found, or is no landmark.
        let e = err(
            Surgery {
                pivot: Some(Pivot::Landmark("menton".into())),
                ..surgery(SurgeryKind::LeFortI)
            },
            &upper,
        );
        assert!(
            e.contains("pivot \"menton\" was not found: Me (the CT's field of view"),
            "{e}"
        );
        let e = err(
            Surgery {
                pivot: Some(Pivot::Landmark("nose".into())),
                ..surgery(SurgeryKind::LeFortI)
            },
            &lms,
        );
        assert!(e.contains("pivot \"nose\" is not a landmark"), "{e}");
        // Too far, too much.
        let e = err(
            Surgery {
                advance_mm: 16.0,
                up_mm: 14.0,
                ..surgery(SurgeryKind::LeFortI)
            },
            &lms,
        );
        assert!(e.contains("21.3 mm, more than 20 mm"), "{e}");
        let e = err(
            Surgery {
                yaw_deg: -31.0,
                ..surgery(SurgeryKind::Genioplasty)
            },
            &lms,
        );
        assert!(e.contains("-31 degrees, more than 30"), "{e}");
        // Autorotation with a split.
        let rot = Surgery {
            up_mm: 3.0,
            autorotate: true,
            ..surgery(SurgeryKind::LeFortI)
        };
        let e = planned(&[rot, surgery(SurgeryKind::Bsso)], &lms)
            .err()
            .unwrap();
        assert!(e.contains("autorotate with a bsso"), "{e}");
        // A Le Fort I level under an orbit's floor.
        let mut low_orbits = lms.clone();
        for (l, x) in [("Or-R", -30.0), ("Or-L", 30.0)] {
            low_orbits.push(Landmark {
                label: l.into(),
                kind: Kind::Bone,
                position: Some([x, -60.0, 10.0]),
                source: Source::Detected,
                missing: None,
            });
        }
        let e = err(surgery(SurgeryKind::LeFortI), &low_orbits);
        assert!(e.contains("orbit's floor"), "{e}");
        // Roots too close to menton for a chin.
        let mut short = lms.clone();
        for l in short.iter_mut().filter(|l| l.label == "L1-apex") {
            l.position = l.position.map(|p| [p[0], p[1], -60.0]);
        }
        let e = err(surgery(SurgeryKind::Genioplasty), &short);
        assert!(e.contains("through the roots"), "{e}");
        assert!(!e.contains('\n'));
    }
}
