//! The facial regions of a face without landmarks (the fallback of [`super`]),
//! found on the skin itself: the solver study's and the landmark-less sweep's per-region
//! statistics.
//!
//! **Head frame.** LPS: anterior is −y, superior +z (facesim reads every CT into LPS). The
//! midsagittal plane is x = x_m, the middle of the skin's x-extent (2nd–98th percentile) at the
//! level of the nose tip — the face is left–right symmetric there, whatever the rest of the scan
//! holds.
//!
//! **Profile.** The soft-tissue profile is the most anterior skin point (min y) per 1 mm slice in z
//! among the vertices within 4 mm of the midsagittal plane, not smoothed (a scan's slices are 1–3 mm apart; empty slices are skipped). Its landmarks, as in
//! soft-tissue cephalometry (Farkas 1994, Legan & Burstone 1980): the nose tip (pronasale, prn) is
//! the profile's most anterior point; walking down from it, the profile's concavities (local
//! maxima of y) and convexities (local minima) alternate: the upper lip's sulcus (concave), labrale
//! superius (ls, convex), stomion (sto, concave), labrale inferius (li, convex), the labiomental
//! fold (sm, concave), pogonion (pg, convex). An extremum counts when the profile rises and falls
//! by ≥ 0.5 mm on both sides within 15 mm; one at the end of the profile does not (that is where the
//! scan stops, not an anatomical point). Subnasale (sn) is where the columella turns into the
//! lip: under the tip, past the steep underside of the nose (|dy/dz| > 1 over 3 mm), the first slice
//! where the profile runs more down than forward again (|dy/dz| < 1); at the latest the sulcus.
//!
//! **Regions** (on vertices; a vertex belongs to at most one, the first that claims it):
//!
//! | region | z range | lateral | depth |
//! |---|---|---|---|
//! | nose | z_sn < z < z_prn + 30 | |x − x_m| < 20 | anterior to the subnasale's coronal plane |
//! | upper lip | z_sto < z ≤ z_sn | |x − x_m| < 25 | within 15 mm of the profile's y at that z |
//! | lower lip | z_sm < z ≤ z_sto | |x − x_m| < 25 | same |
//! | chin | z_pg − 20 < z ≤ z_sm | |x − x_m| < 25 | same |
//! | cheeks | z_sto < z < z_prn + 20 | 25 ≤ |x − x_m| < 60 | within 45 mm of the nose tip's y |
//!
//! A region whose bounding landmarks the profile does not have is **absent** (reported as such,
//! not guessed): on the real CT the field of view ends at the lower teeth, so the lower lip and
//! the chin are absent; where the scan ends inside the upper lip (its labrale superius found, its
//! stomion not) the upper lip and the cheeks end at the scan's last slice, and say so. A profile with no concavity under the nose at all (the phantom: a capsule
//! with a Gaussian nose, no mouth) gets the landmarks at adult mean vertical distances from the
//! nose tip instead (Farkas 1994: prn–sn 18 mm, sn–sto 22 mm, sto–sm 20 mm, sm–pg 12 mm), and the
//! regions say so (`Rule::Proportional`).

/// The region names in report order: the same regions as from the landmarks.
pub use super::NAMES;
use serde::Serialize;

/// How the landmarks under the nose were found.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// From the profile's concavities and convexities.
    Profile,
    /// The profile has none: adult mean distances below the nose tip.
    Proportional,
}

/// The profile's landmarks (z in mm; None where the profile has no such point).
#[derive(Clone, Debug, Serialize)]
pub struct Landmarks {
    pub midsagittal_x: f64,
    /// The nose tip (LPS mm).
    pub pronasale: [f64; 3],
    pub subnasale_z: Option<f64>,
    pub labrale_superius_z: Option<f64>,
    pub stomion_z: Option<f64>,
    pub labrale_inferius_z: Option<f64>,
    pub labiomental_z: Option<f64>,
    pub pogonion_z: Option<f64>,
    /// The lowest slice of the profile (where the skin ends).
    pub profile_bottom_z: f64,
    pub rule: Rule,
}

/// The regions of one face: per region, its member vertices (None when absent) and why absent.
#[derive(Clone, Debug, Serialize)]
pub struct Regions {
    pub landmarks: Landmarks,
    #[serde(skip)]
    pub members: Vec<Option<Vec<bool>>>,
    /// Per region: vertex count, or why it is absent.
    pub summary: Vec<RegionInfo>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RegionInfo {
    pub region: String,
    pub vertices: usize,
    pub absent: Option<String>,
    /// A remark on a present region (cut by the scan's end).
    pub note: Option<String>,
}

const BAND_MM: f64 = 4.0;
const SMOOTH_BINS: usize = 1;
const PROMINENCE_MM: f64 = 0.5;
const REACH_BINS: usize = 15;

/// The most anterior y per 1 mm z-slice near the midsagittal plane, smoothed: (z0, y per slice;
/// NaN where the slice is empty).
fn profile(v: &[[f64; 3]], xm: f64) -> Option<(f64, Vec<f64>)> {
    let near: Vec<&[f64; 3]> = v.iter().filter(|p| (p[0] - xm).abs() < BAND_MM).collect();
    let z0 = near.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
    let z1 = near.iter().map(|p| p[2]).fold(f64::NEG_INFINITY, f64::max);
    if !(z1 > z0) {
        return None;
    }
    let n = (z1 - z0).floor() as usize + 1;
    let mut y = vec![f64::INFINITY; n];
    for p in near {
        let b = ((p[2] - z0).floor() as usize).min(n - 1);
        y[b] = y[b].min(p[1]);
    }
    let h = SMOOTH_BINS / 2;
    let smooth = (0..n)
        .map(|i| {
            let w: Vec<f64> = y[i.saturating_sub(h)..(i + h + 1).min(n)]
                .iter()
                .copied()
                .filter(|v| v.is_finite())
                .collect();
            if w.is_empty() {
                f64::NAN
            } else {
                w.iter().sum::<f64>() / w.len() as f64
            }
        })
        .collect();
    Some((z0, smooth))
}

/// Is slice `i` an extremum of y (a maximum when `concave`) standing out by PROMINENCE_MM on
/// both sides within REACH_BINS? Slices at the profile's ends never are.
fn is_extremum(y: &[f64], i: usize, concave: bool) -> bool {
    let s = if concave { 1.0 } else { -1.0 };
    let v = s * y[i];
    if !v.is_finite() {
        return false;
    }
    let side = |range: &mut dyn Iterator<Item = usize>| {
        let mut drop: f64 = 0.0;
        for j in range {
            let w = s * y[j];
            if !w.is_finite() {
                continue;
            }
            if w > v {
                return false;
            }
            drop = drop.max(v - w);
            if drop >= PROMINENCE_MM {
                return true;
            }
        }
        false
    };
    let lo = i.saturating_sub(REACH_BINS);
    let hi = (i + REACH_BINS).min(y.len() - 1);
    side(&mut (lo..i).rev()) && side(&mut (i + 1..=hi))
}

/// The alternating extrema below slice `top` (walking down): concave first.
fn extrema_below(y: &[f64], top: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut concave = true;
    let mut i = top;
    while i > 0 {
        i -= 1;
        if is_extremum(y, i, concave) {
            // The deepest slice of a flat-bottomed extremum: keep walking while it deepens.
            let s = if concave { 1.0 } else { -1.0 };
            let mut best = i;
            while best > 0 && s * y[best - 1] > s * y[best] {
                best -= 1;
            }
            out.push(best);
            i = best;
            concave = !concave;
            if out.len() == 6 {
                break;
            }
        }
    }
    out
}

fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(((v.len().saturating_sub(1)) as f64 * q) as usize)
        .copied()
        .unwrap_or(0.0)
}

/// The landmarks of the skin with vertices `v` (LPS mm); None for an empty skin.
pub fn landmarks(v: &[[f64; 3]]) -> Option<Landmarks> {
    if v.is_empty() {
        return None;
    }
    // A first midline: the middle of the whole skin's x-extent; the nose tip near it; then the
    // midline at the nose tip's level.
    let xs = |pts: &mut dyn Iterator<Item = &[f64; 3]>| pts.map(|p| p[0]).collect::<Vec<f64>>();
    let all = xs(&mut v.iter());
    let x0 = 0.5 * (percentile(all.clone(), 0.02) + percentile(all, 0.98));
    let tip0 = v
        .iter()
        .filter(|p| (p[0] - x0).abs() < 20.0)
        .min_by(|a, b| a[1].total_cmp(&b[1]))?;
    let level = xs(&mut v.iter().filter(|p| (p[2] - tip0[2]).abs() < 10.0));
    let xm = 0.5 * (percentile(level.clone(), 0.02) + percentile(level, 0.98));
    let (z0, y) = profile(v, xm)?;
    let top = (0..y.len())
        .filter(|i| y[*i].is_finite())
        .min_by(|a, b| y[*a].total_cmp(&y[*b]))?;
    let prn_z = z0 + top as f64 + 0.5;
    let pronasale = *v
        .iter()
        .filter(|p| (p[0] - xm).abs() < BAND_MM)
        .min_by(|a, b| a[1].total_cmp(&b[1]))?;
    let bottom = (0..y.len()).find(|i| y[*i].is_finite()).unwrap_or(0);
    let ext = extrema_below(&y, top);
    let z_of = |k: usize| ext.get(k).map(|i| z0 + *i as f64 + 0.5);
    // Subnasale: where the columella (steep: the profile runs more forward than down) turns
    // into the lip, |dy/dz| < 1 walking down from the tip, no lower than the first concavity.
    let subnasale = |c1: usize| {
        let mut steep = false;
        for i in (c1..top).rev() {
            // The slope over ≥ 3 mm (a scan's slices are unevenly binned at 1 mm).
            let Some(j) = (i + 3..=top).find(|j| y[*j].is_finite()) else {
                continue;
            };
            if !y[i].is_finite() {
                continue;
            }
            let s = (y[i] - y[j]).abs() / (j - i) as f64;
            if steep && s < 1.0 {
                return i;
            }
            steep |= s > 1.0;
        }
        c1
    };
    let (rule, zs) = if ext.is_empty() {
        // No concavity under the nose (Farkas 1994 adult means, rounded).
        let sn = prn_z - 18.0;
        let sto = sn - 22.0;
        let sm = sto - 20.0;
        let pg = sm - 12.0;
        let bottom_z = z0 + bottom as f64;
        let inside = |z: f64| (z >= bottom_z).then_some(z);
        (
            Rule::Proportional,
            [
                inside(sn),
                inside(0.5 * (sn + sto)),
                inside(sto),
                inside(0.5 * (sto + sm)),
                inside(sm),
                inside(pg),
            ],
        )
    } else {
        let mut zs = [0, 1, 2, 3, 4, 5].map(z_of);
        zs[0] = Some(z0 + subnasale(ext[0]) as f64 + 0.5);
        (Rule::Profile, zs)
    };
    Some(Landmarks {
        midsagittal_x: xm,
        pronasale: [pronasale[0], pronasale[1], prn_z],
        subnasale_z: zs[0],
        labrale_superius_z: zs[1],
        stomion_z: zs[2],
        labrale_inferius_z: zs[3],
        labiomental_z: zs[4],
        pogonion_z: zs[5],
        profile_bottom_z: z0 + bottom as f64,
        rule,
    })
}

/// The regions of the skin with vertices `v`; None when it has no profile.
pub fn regions(v: &[[f64; 3]]) -> Option<Regions> {
    let lm = landmarks(v)?;
    let xm = lm.midsagittal_x;
    let (_, y) = profile(v, xm)?;
    let z0 = v
        .iter()
        .filter(|p| (p[0] - xm).abs() < BAND_MM)
        .map(|p| p[2])
        .fold(f64::INFINITY, f64::min);
    let profile_y = |z: f64| {
        let i = (z - z0).floor();
        if i < 0.0 || i as usize >= y.len() {
            f64::NAN
        } else {
            y[i as usize]
        }
    };
    let prn = lm.pronasale;
    let front = |p: &[f64; 3], depth: f64| {
        let py = profile_y(p[2]);
        py.is_finite() && p[1] < py + depth
    };
    let sn_y = lm.subnasale_z.map(profile_y);
    let miss = |what: &str| {
        Some(format!(
            "absent: the profile has no {what} (the skin ends at z = {:.0} mm)",
            lm.profile_bottom_z
        ))
    };
    // (name, membership test, why absent)
    type Test<'t> = Box<dyn Fn(&[f64; 3]) -> bool + 't>;
    let band = |lo: f64, hi: f64| -> Test {
        Box::new(move |p: &[f64; 3]| {
            p[2] > lo && p[2] <= hi && (p[0] - xm).abs() < 25.0 && front(p, 15.0)
        })
    };
    let mut defs: Vec<(Option<Test>, Option<String>)> = Vec::new();
    defs.push(match (lm.subnasale_z, sn_y) {
        (Some(sn), Some(sy)) if sy.is_finite() => (
            Some(Box::new(move |p: &[f64; 3]| {
                p[2] > sn && p[2] < prn[2] + 30.0 && (p[0] - xm).abs() < 20.0 && p[1] < sy
            }) as Test),
            None,
        ),
        _ => (None, miss("subnasale")),
    });
    // Where the scan ends inside the upper lip (its most anterior point found, the stomion
    // not), the lip is what the scan holds of it, and the cheeks end there too.
    let lip_cut = lm
        .labrale_superius_z
        .filter(|_| lm.stomion_z.is_none())
        .map(|_| lm.profile_bottom_z - 1.0);
    let cut_note =
        lip_cut.map(|_| format!("cut by the scan's end at z = {:.0} mm", lm.profile_bottom_z));
    defs.push(match (lm.stomion_z.or(lip_cut), lm.subnasale_z) {
        (Some(sto), Some(sn)) => (Some(band(sto, sn)), None),
        _ => (None, miss("stomion")),
    });
    defs.push(match (lm.labiomental_z, lm.stomion_z) {
        (Some(sm), Some(sto)) => (Some(band(sm, sto)), None),
        _ => (None, miss("labiomental fold")),
    });
    defs.push(match (lm.pogonion_z, lm.labiomental_z) {
        (Some(pg), Some(sm)) => (Some(band(pg - 20.0, sm)), None),
        _ => (None, miss("pogonion")),
    });
    defs.push(match lm.stomion_z.or(lip_cut) {
        Some(sto) => (
            Some(Box::new(move |p: &[f64; 3]| {
                let dx = (p[0] - xm).abs();
                p[2] > sto
                    && p[2] < prn[2] + 20.0
                    && (25.0..60.0).contains(&dx)
                    && p[1] < prn[1] + 45.0
            }) as Test),
            None,
        ),
        None => (None, miss("stomion")),
    });
    let mut claimed = vec![false; v.len()];
    let mut members = Vec::new();
    let mut summary = Vec::new();
    for (k, ((test, absent), name)) in defs.into_iter().zip(NAMES).enumerate() {
        let m = test.map(|t| {
            v.iter()
                .zip(claimed.iter_mut())
                .map(|(p, c)| {
                    let inside = !*c && t(p);
                    *c |= inside;
                    inside
                })
                .collect::<Vec<bool>>()
        });
        let n = m.as_ref().map_or(0, |m| m.iter().filter(|b| **b).count());
        summary.push(RegionInfo {
            region: name.into(),
            vertices: n,
            note: cut_note.clone().filter(|_| k == 1 || k == 4),
            absent: match (&m, absent) {
                (Some(_), _) if n == 0 => Some("absent: no skin vertex inside".into()),
                (_, a) => a,
            },
        });
        members.push(m.filter(|_| n > 0));
    }
    Some(Regions {
        landmarks: lm,
        members,
        summary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A face profile built from known landmarks: a cylinder of radius 80 around the z axis
    /// with a Gaussian nose at z = 0 and lips/chin as bumps at known heights.
    fn face(bumps: &[(f64, f64, f64)], z_range: (f64, f64)) -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        let mut z = z_range.0;
        while z <= z_range.1 {
            for k in -60..=60 {
                let phi = f64::from(k) * 1.5f64.to_radians();
                let mut r = 80.0;
                for &(zc, amp, sz) in bumps {
                    r += amp
                        * (-phi * phi / (2.0 * 0.13 * 0.13) - (z - zc).powi(2) / (2.0 * sz * sz))
                            .exp();
                }
                v.push([r * phi.sin() + 3.0, -r * phi.cos(), z]);
            }
            z += 0.5;
        }
        v
    }

    #[test]
    fn the_profile_finds_the_nose_lips_and_chin_where_they_were_put() {
        // Nose at 0, upper lip at −28, lower lip at −42, chin at −62: concavities between them.
        let bumps = [
            (0.0, 18.0, 6.0),
            (-28.0, 8.0, 4.0),
            (-42.0, 7.0, 4.0),
            (-62.0, 9.0, 5.0),
        ];
        let v = face(&bumps, (-90.0, 40.0));
        let lm = landmarks(&v).unwrap();
        println!("{lm:?}");
        assert_eq!(lm.rule, Rule::Profile);
        assert!((lm.midsagittal_x - 3.0).abs() < 0.5, "{}", lm.midsagittal_x);
        assert!(lm.pronasale[2].abs() < 1.5);
        let near = |z: Option<f64>, want: f64, tol: f64| {
            assert!(z.is_some_and(|z| (z - want).abs() < tol), "{z:?} vs {want}")
        };
        near(lm.labrale_superius_z, -28.0, 1.5);
        near(lm.labrale_inferius_z, -42.0, 1.5);
        near(lm.pogonion_z, -62.0, 1.5);
        // The concavities lie between their convexities.
        let sn = lm.subnasale_z.unwrap();
        assert!(sn < -5.0 && sn > -27.0, "subnasale {sn}");
        near(lm.stomion_z, -35.0, 3.0);
        near(lm.labiomental_z, -52.0, 4.0);
        let r = regions(&v).unwrap();
        for info in &r.summary {
            assert!(info.absent.is_none() && info.vertices > 10, "{info:?}");
        }
    }

    #[test]
    fn a_profile_cut_below_the_upper_lip_has_no_lower_lip_and_no_chin() {
        let bumps = [
            (0.0, 18.0, 6.0),
            (-28.0, 8.0, 4.0),
            (-42.0, 7.0, 4.0),
            (-62.0, 9.0, 5.0),
        ];
        let v = face(&bumps, (-38.0, 40.0));
        let r = regions(&v).unwrap();
        println!("{:?}\n{:?}", r.landmarks, r.summary);
        assert_eq!(r.landmarks.rule, Rule::Profile);
        let absent: Vec<&str> = r
            .summary
            .iter()
            .filter(|i| i.absent.is_some())
            .map(|i| i.region.as_str())
            .collect();
        assert!(
            absent.contains(&"lower lip") && absent.contains(&"chin"),
            "{absent:?}"
        );
        assert!(r.summary[0].absent.is_none(), "the nose is there");
    }

    #[test]
    fn a_profile_without_a_mouth_falls_back_to_mean_proportions() {
        let v = face(&[(0.0, 18.0, 12.0)], (-90.0, 70.0));
        let r = regions(&v).unwrap();
        assert_eq!(r.landmarks.rule, Rule::Proportional);
        assert!(
            r.landmarks
                .stomion_z
                .is_some_and(|z| (z + 40.0).abs() < 1.5)
        );
        assert!(
            r.summary.iter().all(|i| i.absent.is_none()),
            "{:?}",
            r.summary
        );
    }
}
