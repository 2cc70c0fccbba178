//! The clinic's measured soft-to-hard movement ratios per surgery type and soft landmark, with
//! their sources (docs/guide/validation.md, "The published ratios"): what `facesim validate` holds each
//! prediction against. Encoded once, here.
//!
//! Ratio = the soft landmark's displacement along the bone's move ÷ the move: a pure translation
//! moves every bone point by the plan's translation, so the hard displacement is the plan's.
//! The ranges are the spread of study means, not of patients, as the sources print them: where
//! a source gives one value (one study, or "≈ x") the row holds that value (`low == high`) and a
//! prediction is read by its distance to it; where several ranges exist the row holds the
//! primary one (the largest sample) and its note lists the others. Each row carries the
//! source's evidence level.

use serde::{Deserialize, Serialize};

/// The surgery types of the published table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Surgery {
    LeFortAdvance,
    LeFortImpaction,
    LeFortSetback,
    BssoAdvance,
    BssoSetback,
    Genioplasty,
    Bimaxillary,
}

impl Surgery {
    pub const ALL: [Surgery; 7] = [
        Surgery::LeFortAdvance,
        Surgery::LeFortImpaction,
        Surgery::LeFortSetback,
        Surgery::BssoAdvance,
        Surgery::BssoSetback,
        Surgery::Genioplasty,
        Surgery::Bimaxillary,
    ];

    /// The name on the command line and in validation.csv.
    pub fn key(self) -> &'static str {
        match self {
            Surgery::LeFortAdvance => "lefort-advance",
            Surgery::LeFortImpaction => "lefort-impaction",
            Surgery::LeFortSetback => "lefort-setback",
            Surgery::BssoAdvance => "bsso-advance",
            Surgery::BssoSetback => "bsso-setback",
            Surgery::Genioplasty => "genioplasty",
            Surgery::Bimaxillary => "bimax",
        }
    }

    pub fn title(self) -> &'static str {
        match self {
            Surgery::LeFortAdvance => "Le Fort I advancement",
            Surgery::LeFortImpaction => "Le Fort I impaction",
            Surgery::LeFortSetback => "Le Fort I setback",
            Surgery::BssoAdvance => "BSSO advancement",
            Surgery::BssoSetback => "BSSO setback",
            Surgery::Genioplasty => "advancement genioplasty",
            Surgery::Bimaxillary => "bimaxillary advancement",
        }
    }

    pub fn from_key(key: &str) -> Option<Surgery> {
        Surgery::ALL.into_iter().find(|s| s.key() == key)
    }
}

/// The axis a published ratio is measured along (the bone's move is along it; for `Lateral`,
/// a width's change across the face over the bone's forward move).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    Horizontal,
    Vertical,
    /// Across the face (the head frame's lateral axis): the soft terms' widening, over the
    /// segment's move along the horizontal (anterior) axis.
    Lateral,
}

impl Axis {
    pub fn name(self) -> &'static str {
        match self {
            Axis::Horizontal => "horizontal",
            Axis::Vertical => "vertical",
            Axis::Lateral => "lateral",
        }
    }
}

/// A predicted ratio's band against its published range (docs/guide/validation.md, "The
/// protocol"): the band lies within the range, overlaps it, or is clear of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    Inside,
    Consistent,
    Outside,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Inside => "inside",
            Verdict::Consistent => "consistent",
            Verdict::Outside => "outside",
        }
    }
}

/// One row of the published table.
#[derive(Clone, Copy, Debug)]
pub struct Published {
    pub surgery: Surgery,
    /// The soft-tissue quantity, as the table names it.
    pub soft: &'static str,
    /// The soft displacement measured: Σ weight × (post − pre) of these landmarks, along the move.
    pub terms: &'static [(&'static str, f64)],
    /// The hard reference as published.
    pub hard: &'static str,
    /// The moved segment whose translation is the hard move.
    pub segment: &'static str,
    pub axis: Axis,
    pub low: f64,
    pub high: f64,
    /// How the range was read from the literature, when not taken as printed.
    pub range_note: &'static str,
    pub source: &'static str,
    /// The source's evidence, as it states it (how many studies or patients; "low evidence").
    pub evidence: &'static str,
    /// Why facesim cannot measure it, when it cannot.
    pub unmeasured: Option<&'static str>,
}

impl Published {
    /// A ratio inside the published range, to the table's printed precision (0.01: a ratio
    /// that rounds to the range's end is inside). A single published value is a range of
    /// no width: only a ratio that rounds to it is inside.
    pub fn contains(&self, ratio: f64) -> bool {
        ratio >= self.low - 5e-3 && ratio <= self.high + 5e-3
    }

    /// The source printed one value (one study, or "≈ x"), not a range.
    pub fn single_value(&self) -> bool {
        self.low == self.high
    }

    /// How far a ratio lies from the published range (0 inside it), or from the single value.
    pub fn distance(&self, ratio: f64) -> f64 {
        (self.low - ratio).max(ratio - self.high).max(0.0)
    }

    /// Where a prediction's band [lo, hi] lies against the range, at the table's precision as
    /// [`Published::contains`] (docs/guide/validation.md "The protocol"): inside it, overlapping
    /// it (consistent), or clear of it. Against a single published value: inside when the band
    /// holds it, else outside.
    pub fn verdict(&self, lo: f64, hi: f64) -> Verdict {
        if hi < self.low - 5e-3 || lo > self.high + 5e-3 {
            Verdict::Outside
        } else if self.single_value() || (self.contains(lo) && self.contains(hi)) {
            Verdict::Inside
        } else {
            Verdict::Consistent
        }
    }

    /// The range as the source prints it: "0.24–0.6", or one value "0.28".
    pub fn printed(&self) -> String {
        if self.single_value() {
            format!("{}", self.low)
        } else {
            format!("{}–{}", self.low, self.high)
        }
    }
}

// One argument per column of the table, in its order.
#[allow(clippy::too_many_arguments)]
const fn row(
    surgery: Surgery,
    soft: &'static str,
    terms: &'static [(&'static str, f64)],
    hard: &'static str,
    segment: &'static str,
    axis: Axis,
    range: (f64, f64),
    range_note: &'static str,
    source: &'static str,
    evidence: &'static str,
) -> Published {
    Published {
        surgery,
        soft,
        terms,
        hard,
        segment,
        axis,
        low: range.0,
        high: range.1,
        range_note,
        source,
        evidence,
        unmeasured: None,
    }
}

use Axis::{Horizontal as H, Vertical as V};
use Surgery::*;

/// The published table (docs/guide/validation.md, "The published ratios").
pub const PUBLISHED: [Published; 23] = [
    row(
        LeFortAdvance,
        "Prn",
        &[("Prn", 1.0)],
        "A / U1",
        "maxilla",
        H,
        (0.17, 0.36),
        "",
        "systematic review of Le Fort I (15 studies, 419 pts: 0.24–0.35); Dann 1976 0.28; Hack 1993 0.36; Proffit & Epker 1980 0.17; Jung 2018 (3D, n 32, Head Face Med 14:21) 0.17",
        "systematic review: 15 studies, 419 patients",
    ),
    row(
        LeFortAdvance,
        "Sn",
        &[("Sn", 1.0)],
        "A",
        "maxilla",
        H,
        (0.24, 0.60),
        "",
        "Rosen 1988 Plast Reconstr Surg 81:171 (0.51 ± 0.13, n 41); Gupta & Schendel 2022 (Peterson's Principles of OMFS, 4th ed., ch. 67)",
        "range of study means (Gupta & Schendel 2022's table); one study with n 41",
    ),
    row(
        LeFortAdvance,
        "Ls",
        &[("Ls", 1.0)],
        "U1",
        "maxilla",
        H,
        (0.5, 0.9),
        "the 2D range; 3D studies report lower ratios (0.21–0.52)",
        "Rosen 1988 (0.82 ± 0.13); Gupta & Schendel 2022; Jung 2018; 3D meta-analysis (4 studies, 105 pts)",
        "2D studies (Gupta & Schendel 2022's table); 3D studies lower",
    ),
    row(
        LeFortAdvance,
        "alar base width",
        &[("Al-L", 1.0), ("Al-R", -1.0)],
        "advance",
        "maxilla",
        Axis::Lateral,
        (0.6, 1.33),
        "widening ÷ advance, from 3–4 mm for a 3–5 mm advance; measured at alare (Al-R, Al-L: the alae's widest points), the published figure is the alar base's",
        "prospective and 3D studies (Jung 2018)",
        "prospective and 3D studies; the range is the printed widening over the printed advances",
    ),
    row(
        LeFortImpaction,
        "upper lip Sn–Sto shortening",
        &[("Sto", 1.0), ("Sn", -1.0)],
        "impaction",
        "maxilla",
        V,
        (0.2, 0.4),
        "read as the shortening of the lip's height Sn–Sto (Sto rising more than Sn)",
        "Schendel 1976; Radney & Jacobs 1981; Rosen 1988 (without muscle re-orientation)",
        "three 2D studies",
    ),
    row(
        LeFortImpaction,
        "Prn",
        &[("Prn", 1.0)],
        "impaction",
        "maxilla",
        V,
        (0.15, 0.2),
        "≈ 0.15–0.2 as printed",
        "Schendel 1976; Radney & Jacobs 1981; Rosen 1988",
        "three 2D studies",
    ),
    row(
        LeFortImpaction,
        "Sn",
        &[("Sn", 1.0)],
        "impaction",
        "maxilla",
        V,
        (0.28, 0.28),
        "one value: ≈ 0.28 as printed",
        "Schendel 1976; Radney & Jacobs 1981; Rosen 1988",
        "three 2D studies, one value",
    ),
    row(
        LeFortSetback,
        "Ls",
        &[("Ls", 1.0)],
        "U1",
        "maxilla",
        H,
        (0.66, 0.76),
        "published −0.66 to −0.76 on a forward-positive axis: the lip follows the bone back; 2D (3D: 0.14, Jung 2018)",
        "2D studies; Jung 2018 (3D); JKAOMS 46(6), n 50: the ratio roughly doubles beyond a 4 mm setback",
        "2D studies",
    ),
    row(
        LeFortSetback,
        "Sn",
        &[("Sn", 1.0)],
        "A",
        "maxilla",
        H,
        (0.33, 0.33),
        "one value: ≈ −0.33 as printed (forward-positive axis: the lip follows the bone back)",
        "2D studies",
        "2D studies, one value",
    ),
    row(
        BssoAdvance,
        "Li",
        &[("Li", 1.0)],
        "lower incisor",
        "mandible",
        H,
        (0.26, 0.85),
        "",
        "Gupta & Schendel 2022 (9 studies); Eur J Orthod 2017 (doi 10.1093/ejo/cjx003) 0.76 (n 109); Jung 2018 3D 0.66 (n 32)",
        "9 studies",
    ),
    row(
        BssoAdvance,
        "B'",
        &[("B'", 1.0)],
        "B",
        "mandible",
        H,
        (0.86, 1.19),
        "",
        "Gupta & Schendel 2022 (8 studies)",
        "8 studies",
    ),
    row(
        BssoAdvance,
        "Pog'",
        &[("Pog'", 1.0)],
        "Pog",
        "mandible",
        H,
        (0.80, 1.33),
        "the primary range: 20 articles, the largest sample; others: 0.94–1.10 (8 studies), ≈ 1:1 (n 61)",
        "Hallulli & Sjöström 2026 BMC Oral Health; Gupta & Schendel 2022; Mobarak 2001 AJODO 119:353 (n 61)",
        "systematic review: 20 articles",
    ),
    row(
        BssoAdvance,
        "Me'",
        &[("Me'", 1.0)],
        "Me",
        "mandible",
        H,
        (0.87, 1.04),
        "",
        "Gupta & Schendel 2022",
        "range of study means (Gupta & Schendel 2022's table)",
    ),
    row(
        BssoSetback,
        "Li",
        &[("Li", 1.0)],
        "lower incisor",
        "mandible",
        H,
        (0.75, 1.02),
        "the primary range: Joss 2010's review of 8 studies; other: 0.92–1.05 (2016 meta-analysis)",
        "Joss et al. 2010 J Oral Maxillofac Surg 68:2792 (8 studies); J Craniomaxillofac Surg 2016 (PMID 26874555)",
        "review: 8 studies",
    ),
    row(
        BssoSetback,
        "B'",
        &[("B'", 1.0)],
        "B",
        "mandible",
        H,
        (1.0, 1.09),
        "the primary range: Joss 2010's review of 8 studies; other: 0.92–1.05 (2016 meta-analysis)",
        "Joss et al. 2010; J Craniomaxillofac Surg 2016 (PMID 26874555)",
        "review: 8 studies",
    ),
    row(
        BssoSetback,
        "Pog'",
        &[("Pog'", 1.0)],
        "Pog",
        "mandible",
        H,
        (0.83, 1.04),
        "the primary range: Joss 2010's review of 8 studies; other: 0.92–1.05 (2016 meta-analysis); ≈ 1:1 short term, lower long term",
        "Joss et al. 2010; J Craniomaxillofac Surg 2016 (PMID 26874555)",
        "review: 8 studies",
    ),
    row(
        Genioplasty,
        "Pog'",
        &[("Pog'", 1.0)],
        "Pog",
        "chin",
        H,
        (0.57, 1.0),
        "the primary range: 2D, 8 studies; other: 0.77–0.91 at ≥ 2 years (systematic review)",
        "2D studies (8); systematic review doi 10.1007/s10006-021-00991-7",
        "2D, 8 studies",
    ),
    row(
        Genioplasty,
        "Li",
        &[("Li", 1.0)],
        "Pog",
        "chin",
        H,
        (0.44, 0.44),
        "one value: ≈ 0.44 as printed",
        "Busquets & Sassouni 1981",
        "one study",
    ),
    row(
        Bimaxillary,
        "Sn",
        &[("Sn", 1.0)],
        "ANS",
        "maxilla",
        H,
        (0.60, 0.90),
        "",
        "systematic review \"Part III: double jaw\" (16 studies, low evidence)",
        "systematic review: 16 studies, low evidence",
    ),
    row(
        Bimaxillary,
        "Ls",
        &[("Ls", 1.0)],
        "U1",
        "maxilla",
        H,
        (0.60, 1.00),
        "",
        "systematic review \"Part III: double jaw\" (16 studies, low evidence)",
        "systematic review: 16 studies, low evidence",
    ),
    row(
        Bimaxillary,
        "Li",
        &[("Li", 1.0)],
        "lower incisor",
        "mandible",
        H,
        (0.73, 0.73),
        "one value: Jensen 1992's lower lip 0.73",
        "Jensen 1992 AJODO 101:266 (lower lip 0.73, rising to 1.0 at pogonion)",
        "one study",
    ),
    row(
        Bimaxillary,
        "B'",
        &[("B'", 1.0)],
        "B",
        "mandible",
        H,
        (1.0, 1.0),
        "one value: 1.00 as printed",
        "systematic review \"Part III: double jaw\" (16 studies, low evidence)",
        "systematic review: 16 studies, low evidence; one value",
    ),
    row(
        Bimaxillary,
        "Pog'",
        &[("Pog'", 1.0)],
        "Pog",
        "mandible",
        H,
        (0.90, 1.00),
        "",
        "systematic review \"Part III: double jaw\" (16 studies, low evidence); Jensen 1992 AJODO 101:266 ≈ 1.0 at pogonion",
        "systematic review: 16 studies, low evidence",
    ),
];

/// The rows of one surgery type, in table order.
pub fn rows_of(surgery: Surgery) -> impl Iterator<Item = &'static Published> {
    PUBLISHED.iter().filter(move |p| p.surgery == surgery)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A band within a printed range is inside, across its end consistent, beyond it outside;
    /// a single printed value is inside a band that holds it and outside one that does not.
    #[test]
    fn a_band_reads_inside_consistent_or_outside() {
        let range = PUBLISHED
            .iter()
            .find(|p| !p.single_value() && p.unmeasured.is_none())
            .unwrap();
        let (l, h) = (range.low, range.high);
        let w = h - l;
        assert_eq!(range.verdict(l + 0.1 * w, h - 0.1 * w), Verdict::Inside);
        assert_eq!(range.verdict(l - 0.004, h + 0.004), Verdict::Inside);
        assert_eq!(range.verdict(l - 0.1, l + 0.1 * w), Verdict::Consistent);
        assert_eq!(range.verdict(l - 0.1, h + 0.1), Verdict::Consistent);
        assert_eq!(range.verdict(h + 0.01, h + 0.2), Verdict::Outside);
        assert_eq!(range.verdict(l - 0.2, l - 0.01), Verdict::Outside);
        let one = PUBLISHED.iter().find(|p| p.single_value()).unwrap();
        let v = one.low;
        assert_eq!(one.verdict(v - 0.05, v + 0.05), Verdict::Inside);
        assert_eq!(one.verdict(v, v), Verdict::Inside);
        assert_eq!(one.verdict(v + 0.01, v + 0.2), Verdict::Outside);
        assert_eq!(one.verdict(v - 0.2, v - 0.01), Verdict::Outside);
    }

    #[test]
    fn every_surgery_has_rows_and_every_range_is_ordered() {
        for s in Surgery::ALL {
            assert!(rows_of(s).count() > 0, "{s:?}");
            assert_eq!(Surgery::from_key(s.key()), Some(s));
        }
        for p in &PUBLISHED {
            assert!(0.0 < p.low && p.low <= p.high && p.high < 2.0, "{p:?}");
            assert!(!p.evidence.is_empty(), "{p:?}");
            // A single value is shown as itself; its distance is the ratio's from it.
            if p.single_value() {
                assert!(p.range_note.starts_with("one value"), "{p:?}");
                assert_eq!(p.printed(), format!("{}", p.low));
                assert!((p.distance(p.low + 0.1) - 0.1).abs() < 1e-12);
            }
            assert_eq!(p.terms.is_empty(), p.unmeasured.is_some(), "{p:?}");
        }
    }
}
