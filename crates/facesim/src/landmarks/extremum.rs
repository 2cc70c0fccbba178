//! Extrema of a profile (docs/guide/landmarks.md "Profiles"): a convexity or concavity counts when the
//! profile rises and falls by PROMINENCE_MM on both sides within REACH_MM, with no gap of more
//! than GAP_MM — where a scan or section stops there is an end, never an extremum. Shared by the
//! midline landmarks (`detect`) and the paired ones (`lateral`).

use super::frame::{Profile, STEP_MM};

pub(super) const PROMINENCE_MM: f64 = 0.5;
const REACH_MM: f64 = 15.0;
pub(super) const GAP_MM: f64 = 2.0;

/// Convex: a local maximum of anteriority (a bump); concave: a local minimum (a fold).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Ext {
    Convex,
    Concave,
}

impl Ext {
    pub(super) fn sign(self) -> f64 {
        match self {
            Ext::Convex => 1.0,
            Ext::Concave => -1.0,
        }
    }
    pub(super) fn word(self) -> &'static str {
        match self {
            Ext::Convex => "convexity",
            Ext::Concave => "concavity",
        }
    }
}

/// Does the profile at i stand out as `e` by PROMINENCE_MM on both sides within REACH_MM?
pub(super) fn is_extremum(p: &Profile, i: usize, e: Ext) -> bool {
    let s = e.sign();
    let v = s * p.a[i];
    if !v.is_finite() {
        return false;
    }
    let reach = (REACH_MM / STEP_MM) as usize;
    let gap = (GAP_MM / STEP_MM) as usize;
    let side = |idx: &mut dyn Iterator<Item = usize>| {
        let mut hole = 0;
        for j in idx {
            let w = s * p.a[j];
            if !w.is_finite() {
                hole += 1;
                if hole > gap {
                    return false;
                }
                continue;
            }
            hole = 0;
            if w > v {
                return false;
            }
            if v - w >= PROMINENCE_MM {
                return true;
            }
        }
        false
    };
    let lo = i.saturating_sub(reach);
    let hi = (i + reach).min(p.a.len() - 1);
    side(&mut (lo..i).rev()) && side(&mut (i + 1..=hi))
}
