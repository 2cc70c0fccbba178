//! A run held against the clinic (report.json `published_ratios`, the page's
//! "against the clinic" table): the plan read as a surgery type of the published table
//! (`published`), and each of that type's soft-tissue ratios as this run predicts it, beside
//! the published range and its source.
//!
//! The surgery type comes from the `[[surgery]]` entries that cut the segments (their kinds), or
//! for `[[osteotomy]]` segments from their names, and their moves in the head frame
//! (docs/guide/validation.md, "In every run"): a segment named for the maxilla (maxilla, Le Fort), the
//! mandible (mandible, BSSO, sagittal split) or the chin (chin, genioplasty), moving forward, back
//! or up at the jaw's bony landmark (A or ANS for the maxilla, B or Pog for the mandible, Pog for
//! the chin; the pivot when none is located), so a rotation reads as the move it gives the jaw. An
//! impaction whose mandible turns up with it (the autorotation, as `facesim validate` plans it)
//! is an impaction. A plan with any other segment, or a combination the table has no row for, is
//! reported as such, with no ratios.
//!
//! The ratio is as `facesim validate` measures it and the studies publish it: the soft
//! landmark's move along the head's anterior (horizontal rows) or vertical (vertical rows) axis
//! over the segment's move along the same axis. The hard move is taken where the table takes it:
//! at the bony landmark it names when facesim locates it (A, ANS, B, Pog, Me), else (the
//! incisors, "impaction") at the soft landmark itself; for a pure translation both are the
//! translation, as in `facesim validate`.

use super::frame::HeadFrame;
use super::landmark::Carried;
use super::measure::along;
use super::published::{Axis, Published, Surgery, Verdict, rows_of};
use crate::case::Osteotomy;
use crate::plan::basis::{displace, matrix};
use crate::vec3::dot;
use serde::{Deserialize, Serialize};

/// The plan read as a surgery type, and that type's published rows as this run predicts them.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Clinic {
    /// The surgery type (`facesim validate --surgery`'s key); None when the plan is none of the
    /// table's.
    pub surgery: Option<String>,
    pub title: Option<String>,
    /// How the plan was read, or why it matches no surgery type of the table.
    pub reading: String,
    pub rows: Vec<ClinicRow>,
}

/// One published row beside this run's prediction.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ClinicRow {
    /// The soft-tissue quantity, as the table names it.
    pub soft: String,
    /// "horizontal" (the head's anterior axis) or "vertical".
    pub axis: String,
    /// The plan's segment whose move is the hard move.
    pub segment: String,
    /// The hard reference as published, and where this run took the hard move.
    pub hard: String,
    pub hard_at: String,
    /// The soft and hard moves along the axis (mm, + forward or up).
    pub soft_mm: Option<f64>,
    pub hard_mm: Option<f64>,
    pub predicted: Option<f64>,
    pub low: f64,
    pub high: f64,
    /// Predicted inside [low, high] (to the table's 0.01); None when not predicted.
    pub inside: Option<bool>,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub range_note: String,
    pub source: String,
    /// The source's evidence level, as it states it.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub evidence: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
    /// With `[uncertainty] samples`: the ratio's 5th and 95th percentiles over the sampled
    /// tissue parameters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tissue_band: Option<[f64; 2]>,
    /// With `[tet] error_estimate`: the ratio on the mesh of twice the element size.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_mesh: Option<f64>,
    /// The prediction's band: the smallest interval holding the tissue band, the predicted ratio
    /// and the coarse mesh's (docs/guide/validation.md, "The protocol"); with neither, absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band: Option<[f64; 2]>,
    /// The band against the range: inside, consistent (overlapping) or outside.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
}

impl ClinicRow {
    /// The band and verdict from the tissue band and the coarse mesh's ratio (either may be
    /// absent); nothing without a predicted ratio.
    fn set_band(&mut self, p: &Published) {
        let Some(r) = self.predicted else {
            return;
        };
        if self.tissue_band.is_none() && self.coarse_mesh.is_none() {
            return;
        }
        let [lo, hi] = self.tissue_band.unwrap_or([r, r]);
        let c = self.coarse_mesh.unwrap_or(r);
        let band = [lo.min(r).min(c), hi.max(r).max(c)];
        self.band = Some(band);
        self.verdict = Some(p.verdict(band[0], band[1]));
    }
}

/// The bands of a run's published rows: `samples`, the clinic as each sampled tissue's face
/// gives it, and `coarse`, as the coarse mesh's gives it (each with the run's rows, in their
/// order: the plan and the landmarks before are the run's); `p05_p95` reduces a row's sampled
/// ratios to their 5th and 95th percentiles (the uncertainty band's rule).
pub(crate) fn with_bands(
    clinic: &mut Clinic,
    samples: &[Clinic],
    coarse: Option<&Clinic>,
    p05_p95: &dyn Fn(&[f64]) -> [f64; 2],
) {
    let Some(surgery) = clinic.surgery.as_deref().and_then(Surgery::from_key) else {
        return;
    };
    let published: Vec<&Published> = rows_of(surgery).collect();
    for (i, row) in clinic.rows.iter_mut().enumerate() {
        let Some(p) = published
            .iter()
            .find(|p| p.soft == row.soft && p.axis.name() == row.axis)
        else {
            continue;
        };
        let ratios: Vec<f64> = samples
            .iter()
            .filter_map(|c| c.rows.get(i)?.predicted)
            .collect();
        if !samples.is_empty() && ratios.len() == samples.len() {
            row.tissue_band = Some(p05_p95(&ratios));
        }
        row.coarse_mesh = coarse.and_then(|c| c.rows.get(i)?.predicted);
        row.set_band(p);
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Jaw {
    Maxilla,
    Mandible,
    Chin,
}

impl Jaw {
    /// The bony landmarks a jaw's move is read at, in order of preference.
    fn reference(self) -> &'static [&'static str] {
        match self {
            Jaw::Maxilla => &["A", "ANS"],
            Jaw::Mandible => &["B", "Pog"],
            Jaw::Chin => &["Pog"],
        }
    }

    /// The segment name `published` gives this jaw.
    fn key(self) -> &'static str {
        match self {
            Jaw::Maxilla => "maxilla",
            Jaw::Mandible => "mandible",
            Jaw::Chin => "chin",
        }
    }
}

/// The jaw a segment's name says it is (case-insensitive; the chin before the mandible, since
/// a genioplasty segment is part of the mandible).
fn jaw_by_name(name: &str) -> Option<Jaw> {
    let n = name.to_ascii_lowercase();
    let has = |words: &[&str]| words.iter().any(|w| n.contains(w));
    if has(&["chin", "genio"]) {
        Some(Jaw::Chin)
    } else if has(&["mandib", "bsso", "sagittal"]) {
        Some(Jaw::Mandible)
    } else if has(&["maxill", "lefort", "le fort", "le_fort", "le-fort"]) {
        Some(Jaw::Maxilla)
    } else {
        None
    }
}

/// Moves smaller than this (mm, along the deciding axis) give no surgery type.
const LEAST_MOVE_MM: f64 = 0.5;

/// The displacement of `x` under the segment's rigid move (the plan basis's M·[x; 1]).
fn displacement(o: &Osteotomy, x: [f64; 3]) -> [f64; 3] {
    displace(&matrix(o), x)
}

/// A plan read as a surgery type: the type, how it was read, and each jaw's segment (index).
type Reading = (Surgery, String, Vec<(Jaw, usize)>);

/// The surgery type of a plan, with how it was read, and each jaw's segment.
fn surgery_of(
    plan: &[Osteotomy],
    carried: &[Carried],
    frame: &HeadFrame,
    jaw_of: &dyn Fn(&Osteotomy) -> Option<Jaw>,
) -> std::result::Result<Reading, String> {
    if plan.is_empty() {
        return Err("the plan moves no bone".into());
    }
    let mut jaws = Vec::new();
    let mut read = Vec::new();
    for (i, o) in plan.iter().enumerate() {
        let Some(j) = jaw_of(o) else {
            return Err(format!(
                "segment '{}' is not named for a jaw (maxilla / Le Fort, mandible / BSSO, chin / genioplasty): the published ratios are per surgery type",
                o.name
            ));
        };
        if jaws.iter().any(|(k, _, _)| *k == j) {
            return Err(format!(
                "two segments are the {}: the table's surgery types move each jaw as one piece",
                j.key()
            ));
        }
        let (at, x) = j
            .reference()
            .iter()
            .find_map(|l| pre_of(carried, l).map(|x| (l.to_string(), x)))
            .unwrap_or_else(|| ("its pivot".to_string(), o.pivot));
        let d = displacement(o, x);
        let (f, u) = (dot(d, frame.anterior), dot(d, frame.vertical));
        // Rounded to the 0.1 mm printed, + 0.0 turning a −0.0 into 0.0.
        let mm = |x: f64| (x * 10.0).round() / 10.0 + 0.0;
        read.push(format!(
            "'{}' ({}) moves {:+.1} mm forward, {:+.1} mm up at {at}",
            o.name,
            j.key(),
            mm(f),
            mm(u)
        ));
        jaws.push((j, i, (f, u)));
    }
    let reading = read.join("; ");
    let along = |j: Jaw| jaws.iter().find(|(k, _, _)| *k == j).map(|(_, _, m)| *m);
    let none = |why: &str| Err(format!("{reading}: {why}"));
    let forward = |(f, u): (f64, f64)| f.abs() >= u.abs();
    // The mandible's autorotation after an impaction: turned (not only moved), its chin rising
    // and not going back. The published impaction ratios come from such patients.
    let closing = |j: Jaw, (f, u): (f64, f64)| {
        let turned = jaws
            .iter()
            .find(|(k, _, _)| *k == j)
            .is_some_and(|(_, i, _)| plan[*i].rotate_deg.iter().any(|d| d.abs() > 0.1));
        turned && u >= LEAST_MOVE_MM && f > -LEAST_MOVE_MM
    };
    let s = match (along(Jaw::Maxilla), along(Jaw::Mandible), along(Jaw::Chin)) {
        (Some(m), None, None) if forward(m) && m.0 >= LEAST_MOVE_MM => Surgery::LeFortAdvance,
        (Some(m), None, None) if forward(m) && m.0 <= -LEAST_MOVE_MM => Surgery::LeFortSetback,
        (Some(m), None, None) if !forward(m) && m.1 >= LEAST_MOVE_MM => Surgery::LeFortImpaction,
        (Some(_), None, None) => {
            return none(
                "a maxillary move the table has no ratios for (down-graft, or under 0.5 mm)",
            );
        }
        (None, Some(b), None) if b.0 >= LEAST_MOVE_MM => Surgery::BssoAdvance,
        (None, Some(b), None) if b.0 <= -LEAST_MOVE_MM => Surgery::BssoSetback,
        (None, None, Some(c)) if c.0 >= LEAST_MOVE_MM => Surgery::Genioplasty,
        (Some(m), Some(b), None)
            if !forward(m) && m.1 >= LEAST_MOVE_MM && closing(Jaw::Mandible, b) =>
        {
            Surgery::LeFortImpaction
        }
        (Some(m), Some(b), None) if forward(m) && m.0 >= LEAST_MOVE_MM && b.0 >= LEAST_MOVE_MM => {
            Surgery::Bimaxillary
        }
        _ => {
            return none(
                "a combination the published table has no ratios for (it has Le Fort I advance, impaction and setback; BSSO advance and setback; advancement genioplasty; bimaxillary advancement)",
            );
        }
    };
    Ok((
        s,
        reading,
        jaws.into_iter().map(|(j, i, _)| (j, i)).collect(),
    ))
}

/// The landmark's pre-operative position, when located.
fn pre_of(carried: &[Carried], label: &str) -> Option<[f64; 3]> {
    carried.iter().find(|c| c.label == label)?.pre
}

/// A hard move under 0.1 mm along the axis gives no ratio (as `measure`'s soft/hard pairs).
const LEAST_HARD_MM: f64 = 0.1;

fn row_of(p: &Published, o: &Osteotomy, carried: &[Carried], frame: &HeadFrame) -> ClinicRow {
    // The soft terms along the row's axis; the hard move along it too, except that a width
    // (lateral) is over the forward move.
    let (dir, hard_dir) = match p.axis {
        Axis::Horizontal => (frame.anterior, frame.anterior),
        Axis::Vertical => (frame.vertical, frame.vertical),
        Axis::Lateral => (frame.lateral, frame.anterior),
    };
    let mut row = ClinicRow {
        soft: p.soft.into(),
        axis: p.axis.name().into(),
        segment: o.name.clone(),
        hard: p.hard.into(),
        hard_at: String::new(),
        soft_mm: None,
        hard_mm: None,
        predicted: None,
        low: p.low,
        high: p.high,
        inside: None,
        range_note: p.range_note.into(),
        source: p.source.into(),
        evidence: p.evidence.into(),
        missing: p.unmeasured.map(str::to_string),
        tissue_band: None,
        coarse_mesh: None,
        band: None,
        verdict: None,
    };
    if p.unmeasured.is_some() {
        return row;
    }
    // The bony landmark the table names, else the (first) soft landmark itself.
    let named = p
        .hard
        .split(|c: char| c == '/' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .find_map(|t| pre_of(carried, t).map(|x| (t.to_string(), x)));
    let soft_at = p.terms.first().and_then(|(l, _)| {
        pre_of(carried, l).map(|x| (format!("{l} (the segment's move there)"), x))
    });
    let Some((at, x)) = named.or(soft_at) else {
        row.missing = Some(format!(
            "{} not found: no point to take the hard move at",
            p.soft
        ));
        return row;
    };
    row.hard_at = at;
    let hard = dot(displacement(o, x), hard_dir);
    row.hard_mm = Some(hard);
    match along(carried, p.terms, dir) {
        Ok(soft) => {
            row.soft_mm = Some(soft);
            if hard.abs() >= LEAST_HARD_MM {
                let r = soft / hard;
                row.predicted = Some(r);
                row.inside = Some(p.contains(r));
            } else {
                row.missing = Some(format!(
                    "the segment moves {hard:.2} mm along the {} axis at {}: under {LEAST_HARD_MM} mm",
                    p.axis.name(),
                    row.hard_at
                ));
            }
        }
        Err(why) => row.missing = Some(why),
    }
    row
}

/// The plan's surgery type and its published rows as this run predicts them.
pub(crate) fn against_published(
    plan: &[Osteotomy],
    carried: &[Carried],
    frame: &HeadFrame,
) -> Clinic {
    against_published_as(plan, carried, frame, &|o| jaw_by_name(&o.name))
}

/// [`against_published`] of a plan whose `[[surgery]]` entries say which jaw each of their
/// segments is (`surgeries`: segment name and kind — "le-fort-i", "bsso", "genioplasty",
/// "autorotation"), read in the clinical frame; its other segments by name.
pub(crate) fn against_published_planned(
    plan: &[Osteotomy],
    carried: &[Carried],
    frame: &HeadFrame,
    surgeries: &[(String, &str)],
) -> Clinic {
    against_published_as(plan, carried, frame, &|o| match surgeries
        .iter()
        .find(|(n, _)| *n == o.name)
        .map(|(_, k)| *k)
    {
        Some("le-fort-i") => Some(Jaw::Maxilla),
        Some("bsso" | "autorotation") => Some(Jaw::Mandible),
        Some("genioplasty") => Some(Jaw::Chin),
        _ => jaw_by_name(&o.name),
    })
}

fn against_published_as(
    plan: &[Osteotomy],
    carried: &[Carried],
    frame: &HeadFrame,
    jaw_of: &dyn Fn(&Osteotomy) -> Option<Jaw>,
) -> Clinic {
    match surgery_of(plan, carried, frame, jaw_of) {
        Err(reading) => Clinic {
            reading,
            ..Clinic::default()
        },
        Ok((s, reading, jaws)) => Clinic {
            surgery: Some(s.key().into()),
            title: Some(s.title().into()),
            reading,
            rows: rows_of(s)
                .filter_map(|p| {
                    let (_, i) = jaws.iter().find(|(j, _)| j.key() == p.segment)?;
                    Some(row_of(p, &plan[*i], carried, frame))
                })
                .collect(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::Region;
    use crate::landmarks::{Kind, Source};
    use crate::vec3::sub;

    fn frame() -> HeadFrame {
        // LPS: anterior is −y, up is +z.
        HeadFrame {
            origin: [0.0; 3],
            lateral: [1.0, 0.0, 0.0],
            vertical: [0.0, 0.0, 1.0],
            anterior: [0.0, -1.0, 0.0],
            symmetry_residual_mm: 0.0,
        }
    }

    fn segment(name: &str, translate: [f64; 3], rotate_deg: [f64; 3]) -> Osteotomy {
        Osteotomy {
            name: name.into(),
            region: Region::Sphere {
                center: [0.0; 3],
                radius: 1.0,
            },
            translate,
            rotate_deg,
            pivot: [0.0, 0.0, 0.0],
        }
    }

    fn lm(label: &str, pre: [f64; 3], post: [f64; 3]) -> Carried {
        Carried {
            label: label.into(),
            kind: Kind::Soft,
            source: Source::Detected,
            pre: Some(pre),
            post: Some(post),
            change_mm: Some(crate::vec3::norm(sub(post, pre))),
            missing: None,
        }
    }

    fn p05_p95(v: &[f64]) -> [f64; 2] {
        let b = crate::uncertainty::Band::of(v);
        [b.p05, b.p95]
    }

    /// The band of a row is the hull of the sampled ratios' p05–p95, the ratio and the coarse
    /// mesh's ratio; its verdict reads the band against the range.
    #[test]
    fn a_rows_band_holds_its_samples_middle_ninety_percent_and_both_meshes() {
        let f = frame();
        let plan = [segment("maxilla", [0.0, -5.0, 0.0], [0.0; 3])];
        let carried = |sn_forward: f64| {
            vec![
                lm("Sn", [0.0, -80.0, 0.0], [0.0, -80.0 - sn_forward, 0.3]),
                lm("Ls", [0.0, -82.0, -15.0], [0.0, -86.8, -15.0]),
                lm("A", [0.0, -70.0, -5.0], [0.0, -75.0, -5.0]),
            ]
        };
        // Sn's ratio over 21 samples: (a..b) mm forward over 5 mm, evenly.
        let band_of = |a: f64, b: f64, coarse: f64| {
            let mut c = against_published(&plan, &carried(2.0), &f);
            let samples: Vec<Clinic> = (0..21)
                .map(|k| a + (b - a) * k as f64 / 20.0)
                .map(|x| against_published(&plan, &carried(x), &f))
                .collect();
            let coarse = against_published(&plan, &carried(coarse), &f);
            with_bands(&mut c, &samples, Some(&coarse), &p05_p95);
            c
        };
        let get = |c: &Clinic, s: &str| c.rows.iter().find(|r| r.soft == s).unwrap().clone();
        let close =
            |x: [f64; 2], y: [f64; 2]| (x[0] - y[0]).abs() < 1e-12 && (x[1] - y[1]).abs() < 1e-12;
        // 0.20–0.60 in steps of 0.02: p05 and p95 at positions 1 and 19 (numpy's type 7).
        let c = band_of(1.0, 3.0, 2.5);
        let sn = get(&c, "Sn");
        assert!(close(sn.tissue_band.unwrap(), [0.22, 0.58]), "{sn:?}");
        assert!((sn.coarse_mesh.unwrap() - 0.5).abs() < 1e-12, "{sn:?}");
        assert!(close(sn.band.unwrap(), [0.22, 0.58]), "{sn:?}");
        // Published 0.24–0.60: the band reaches below it.
        assert_eq!(sn.verdict, Some(Verdict::Consistent), "{sn:?}");
        // Ls does not depend on Sn: a band of no width, clear of 0.5–0.9.
        let ls = get(&c, "Ls");
        assert!(close(ls.band.unwrap(), [0.96, 0.96]), "{ls:?}");
        assert_eq!(ls.verdict, Some(Verdict::Outside), "{ls:?}");
        // A narrower tissue band with the coarse mesh beyond it: the hull reaches the coarse.
        let sn = get(&band_of(1.5, 2.5, 2.75), "Sn");
        assert!(close(sn.tissue_band.unwrap(), [0.31, 0.49]), "{sn:?}");
        assert!(close(sn.band.unwrap(), [0.31, 0.55]), "{sn:?}");
        assert_eq!(sn.verdict, Some(Verdict::Inside), "{sn:?}");
        // Without samples or a coarse mesh, no band.
        let mut c = against_published(&plan, &carried(2.0), &f);
        with_bands(&mut c, &[], None, &p05_p95);
        assert!(
            c.rows
                .iter()
                .all(|r| r.band.is_none() && r.verdict.is_none())
        );
    }

    #[test]
    fn plans_read_as_the_tables_surgery_types() {
        let f = frame();
        let key = |plan: &[Osteotomy]| {
            surgery_of(plan, &[], &f, &|o| jaw_by_name(&o.name)).map(|(s, _, _)| s.key())
        };
        let fwd = [0.0, -5.0, 0.0];
        assert_eq!(
            key(&[segment("Maxilla", fwd, [0.0; 3])]),
            Ok("lefort-advance")
        );
        assert_eq!(
            key(&[segment("le_fort_1", [0.0, 4.0, 0.0], [0.0; 3])]),
            Ok("lefort-setback")
        );
        assert_eq!(
            key(&[segment("maxilla", [0.0, -1.0, 4.0], [0.0; 3])]),
            Ok("lefort-impaction")
        );
        assert_eq!(key(&[segment("BSSO", fwd, [0.0; 3])]), Ok("bsso-advance"));
        assert_eq!(
            key(&[segment("mandible", [0.0, 4.0, 0.0], [0.0; 3])]),
            Ok("bsso-setback")
        );
        assert_eq!(
            key(&[segment("genioplasty", fwd, [0.0; 3])]),
            Ok("genioplasty")
        );
        assert_eq!(
            key(&[
                segment("mandible", fwd, [0.0; 3]),
                segment("maxilla", fwd, [0.0; 3])
            ]),
            Ok("bimax")
        );
        // Not the table's: a down-graft, an unnamed segment, a chin setback.
        assert!(key(&[segment("maxilla", [0.0, 0.0, -4.0], [0.0; 3])]).is_err());
        assert!(
            key(&[segment("piece-1", fwd, [0.0; 3])])
                .unwrap_err()
                .contains("not named for a jaw")
        );
        assert!(key(&[segment("chin", [0.0, 3.0, 0.0], [0.0; 3])]).is_err());
    }

    #[test]
    fn an_impaction_with_the_mandible_closing_after_it_is_an_impaction() {
        let f = frame();
        // B 80 mm in front of and 60 mm below the pivot (the condyles): a −3° turn about x
        // takes it 3.0 mm forward and 4.3 mm up.
        let b = [0.0, -80.0, -60.0];
        let carried = [lm("B", b, b)];
        let key = |plan: &[Osteotomy]| {
            surgery_of(plan, &carried, &f, &|o| jaw_by_name(&o.name)).map(|(s, _, _)| s.key())
        };
        let maxilla = segment("maxilla", [0.0, -1.1, 3.8], [0.0; 3]);
        let closing = segment("mandible", [0.0; 3], [-3.0, 0.0, 0.0]);
        assert_eq!(
            key(&[maxilla.clone(), closing.clone()]),
            Ok("lefort-impaction")
        );
        // Not a bimaxillary advance, though both jaws move forward a little; and the mandible
        // only translated up, or opening, is no impaction's.
        let lifted = segment("mandible", [0.0, 0.0, 4.0], [0.0; 3]);
        assert!(key(&[maxilla.clone(), lifted]).is_err());
        let opening = segment("mandible", [0.0; 3], [3.0, 0.0, 0.0]);
        assert!(key(&[maxilla, opening]).is_err());
    }

    #[test]
    fn the_ratio_is_the_soft_move_over_the_bone_move_at_the_named_landmark() {
        let f = frame();
        // A 5 mm advance: Sn forward 2 mm (0.40, inside 0.24–0.60), Ls 4.8 mm (0.96, above
        // 0.5–0.9), Prn not located.
        let plan = [segment("maxilla", [0.0, -5.0, 0.0], [0.0; 3])];
        let carried = vec![
            lm("Sn", [0.0, -80.0, 0.0], [0.0, -82.0, 0.3]),
            lm("Ls", [0.0, -82.0, -15.0], [0.0, -86.8, -15.0]),
            lm("A", [0.0, -70.0, -5.0], [0.0, -75.0, -5.0]),
        ];
        let c = against_published(&plan, &carried, &f);
        assert_eq!(c.surgery.as_deref(), Some("lefort-advance"));
        let get = |s: &str| c.rows.iter().find(|r| r.soft == s).unwrap();
        let sn = get("Sn");
        assert!((sn.predicted.unwrap() - 0.4).abs() < 1e-12, "{sn:?}");
        assert_eq!(sn.hard_at, "A");
        assert_eq!(sn.inside, Some(true));
        let ls = get("Ls");
        assert!((ls.predicted.unwrap() - 0.96).abs() < 1e-12, "{ls:?}");
        assert_eq!(ls.inside, Some(false));
        let prn = get("Prn");
        assert!(prn.predicted.is_none() && prn.missing.is_some(), "{prn:?}");
    }

    #[test]
    fn a_rotated_segment_is_measured_by_its_move_at_the_hard_landmark() {
        let f = frame();
        // A −10° turn about x through the origin: a point at z = −60 swings forward (−y) by
        // 60 sin 10°, and B there is the hard reference of B'.
        let plan = [segment("mandible", [0.0; 3], [-10.0, 0.0, 0.0])];
        let b = [0.0, 0.0, -60.0];
        let hard = dot(displacement(&plan[0], b), f.anterior);
        assert!(
            (hard - 60.0 * 10f64.to_radians().sin()).abs() < 1e-9,
            "{hard}"
        );
        // Nothing moves at the pivot, but the jaw moves forward at B: a BSSO advance, and B'
        // forward 8 mm is 8 / 10.42 = 0.77, below 0.86–1.19.
        let c = against_published(
            &plan,
            &[
                lm("B", b, b),
                lm("B'", [0.0, -12.0, -60.0], [0.0, -20.0, -60.0]),
            ],
            &f,
        );
        assert_eq!(c.surgery.as_deref(), Some("bsso-advance"), "{c:?}");
        let row = c.rows.iter().find(|r| r.soft == "B'").unwrap();
        assert!(
            (row.predicted.unwrap() - 8.0 / hard).abs() < 1e-12,
            "{row:?}"
        );
        assert_eq!((row.hard_at.as_str(), row.inside), ("B", Some(false)));
    }
}
