//! Tissue segmentation by intensity (docs/design/pipeline.md §1, Koch 1996 §2.3 and Table 1).
//!
//! 1. Head = the largest 6-connected component of HU > `head_threshold` (drops the CT table and
//!    head rest, which touch the head only through air).
//! 2. Outside air = non-head voxels connected to the volume border; other non-head voxels are
//!    cavities (sinuses, airway).
//! 3. HU windows (fixed, or fitted: a Gaussian mixture on the head's histogram, bounds where
//!    neighbouring weighted components cross).
//! 4. Bone = head voxels ≥ the bone bound, 26-connected pieces smaller than
//!    `min_bone_component_mm3` dropped (they become soft tissue).
//! 5. Skin = non-bone head voxels within `skin_thickness_mm` of the outside air (Euclidean
//!    distance transform), and every non-bone voxel touching outside air (partial-volume
//!    voxels whose HU fall below the fat window).

pub mod distance;
pub mod runs;

pub use distance::{distance_sq, distance_sq_within};
pub use runs::{Runs, components};

use crate::case::{Tissue, TissueMethod};
use crate::error::{Error, Result};
use crate::volume::Volume;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use crate::labels::{AIR, BONE, FAT_BRIGHT, FAT_DARK, LABEL_NAMES, MUSCLE, SKIN};

/// The HU window bounds actually used.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Windows {
    pub head_threshold: f64,
    pub fat_dark: f64,
    pub fat_bright: f64,
    pub soft: f64,
    pub bone: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Gaussian {
    pub name: String,
    pub weight: f64,
    pub mean: f64,
    pub sigma: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SegmentReport {
    pub method: String,
    pub windows: Windows,
    /// The fitted mixture (method = "fit").
    pub mixture: Option<Vec<Gaussian>>,
    /// Where the weighted fat/soft and soft/bone components cross (method = "fit").
    pub mixture_crossings: Option<[f64; 2]>,
    pub head_voxels: usize,
    /// Components above the head threshold that are not the head (table, head rest, ...).
    pub removed_components: usize,
    pub removed_voxels: usize,
    pub bone_components_kept: usize,
    pub bone_components_dropped: usize,
    pub bone_voxels_dropped: usize,
    pub cavity_voxels: usize,
    /// Volume (mm³) per label, in LABEL_NAMES order.
    pub volumes_mm3: Vec<(String, f64)>,
    pub warnings: Vec<String>,
}

pub struct Segmentation {
    pub labels: Vec<u8>,
    /// Head component mask.
    pub head: Vec<bool>,
    /// The air outside the head (connected to the volume border); the other non-head voxels
    /// are cavities (sinuses, airway, the oral vestibule).
    pub outside: Runs,
    pub windows: Windows,
    pub report: SegmentReport,
}

impl Segmentation {
    /// HU field for the skin iso-surface: voxels outside the head are clamped just below the
    /// head threshold (not to −1000, which would shift the partial-volume boundary).
    pub fn skin_field(&self, vol: &Volume) -> Vec<f32> {
        let t = (self.windows.head_threshold - 1.0) as f32;
        vol.data
            .par_iter()
            .zip(&self.head)
            .map(|(&v, &h)| if h { v } else { v.min(t) })
            .collect()
    }

    /// HU field for the skull iso-surface: only kept bone may exceed the bone bound.
    pub fn bone_field(&self, vol: &Volume) -> Vec<f32> {
        let t = (self.windows.bone - 1.0) as f32;
        vol.data
            .par_iter()
            .zip(&self.labels)
            .map(|(&v, &l)| if l == BONE { v } else { v.min(t) })
            .collect()
    }

    pub fn count(&self, label: u8) -> usize {
        self.labels.iter().filter(|&&l| l == label).count()
    }
}

/// Standard normal CDF (Abramowitz & Stegun 7.1.26 for erf, |error| < 1.5e-7).
fn phi_cdf(x: f64) -> f64 {
    let z = x.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.3275911 * z);
    let poly = t
        * (0.254829592
            + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    let erf = 1.0 - poly * (-z * z).exp();
    if x >= 0.0 {
        0.5 * (1.0 + erf)
    } else {
        0.5 * (1.0 - erf)
    }
}

/// Density of a partial-volume voxel mixing classes with means a < b in uniform proportion,
/// blurred by noise σ: (Φ((x−a)/σ) − Φ((x−b)/σ)) / (b − a) (Santago & Gage 1993).
fn mixel_pdf(x: f64, a: f64, b: f64, sigma: f64) -> f64 {
    let (lo, hi) = (a.min(b), a.max(b));
    ((phi_cdf((x - lo) / sigma) - phi_cdf((x - hi) / sigma)) / (hi - lo).max(1e-9)).max(0.0)
}

/// Histogram bins of the mixture fit: 5 HU wide from the head threshold to 2000 HU.
const FIT_BIN_HU: f64 = 5.0;
const FIT_TOP_HU: f64 = 2000.0;

/// Histogram of the head voxels' HU for the mixture fit (slices in parallel).
fn head_histogram(vol: &Volume, head: &Runs, t: &Tissue) -> Vec<f64> {
    let (lo, hi, bw) = (t.head_threshold, FIT_TOP_HU, FIT_BIN_HU);
    let nb = ((hi - lo) / bw) as usize;
    let [nx, ny, nz] = vol.dims;
    (0..nz)
        .into_par_iter()
        .fold(
            || vec![0f64; nb],
            |mut hist, k| {
                for j in 0..ny {
                    let r = j + ny * k;
                    for q in head.runs_in_row(r) {
                        let base = nx * r;
                        for &v in &vol.data[base + q[0] as usize..base + q[1] as usize] {
                            // Values beyond `hi` (dense enamel, metal, saturated detectors) are
                            // left out rather than piled into the last bin, where they would
                            // make a spike for a component to collapse onto.
                            let v = v as f64;
                            if v >= lo && v < hi {
                                hist[(((v - lo) / bw) as usize).min(nb - 1)] += 1.0;
                            }
                        }
                    }
                }
                hist
            },
        )
        .reduce(
            || vec![0f64; nb],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

/// EM fit of fat, soft and bone Gaussians to the histogram of head voxels, with partial-volume
/// ("mixel") components between air–soft, fat–soft and soft–bone whose ranges follow the
/// pure classes' means. Without the mixels, the many boundary voxels of a thin skull pull the
/// bone component's mean far below pure bone. Returns the three Gaussians.
fn fit_mixture(hist: &[f64], t: &Tissue) -> Vec<Gaussian> {
    let (lo, hi, bw) = (t.head_threshold, FIT_TOP_HU, FIT_BIN_HU);
    let centre = |b: usize| lo + (b as f64 + 0.5) * bw;
    // Each class's mean stays inside its literature window and its spread below a cap: the fit
    // adapts the windows to this scanner, it does not relabel tissues (on real heads the fat
    // peak is a shoulder of the brain's, and an unconstrained fit drifts onto the brain; a
    // bone σ floor keeps bone off narrow spikes of dental fillings).
    let range = [
        (t.fat_dark, t.soft, 5.0, 60.0),
        (t.soft, t.bone, 5.0, 60.0),
        (t.bone, hi, 50.0, 600.0),
    ];
    let mut g = [
        Gaussian {
            name: "fat".into(),
            weight: 0.2,
            mean: 0.5 * (t.fat_dark + t.soft),
            sigma: 40.0,
        },
        Gaussian {
            name: "soft".into(),
            weight: 0.4,
            mean: 0.5 * (t.soft + t.bone),
            sigma: 40.0,
        },
        Gaussian {
            name: "bone".into(),
            weight: 0.1,
            mean: t.bone + 600.0,
            sigma: 250.0,
        },
    ];
    // Mixel weights: air–soft, fat–soft, soft–bone.
    let mut mw = [0.1, 0.1, 0.1];
    let total: f64 = hist.iter().sum();
    for _ in 0..300 {
        let mut acc = [[0f64; 3]; 3]; // per Gaussian: Σr, Σr x, Σr x²
        let mut macc = [0f64; 3];
        let noise = g[1].sigma.max(bw);
        for (b, &h) in hist.iter().enumerate() {
            if h == 0.0 {
                continue;
            }
            let x = centre(b);
            let mut p = [0f64; 6];
            for c in 0..3 {
                p[c] = g[c].weight
                    * (-(x - g[c].mean).powi(2) / (2.0 * g[c].sigma * g[c].sigma)).exp()
                    / (g[c].sigma * (2.0 * std::f64::consts::PI).sqrt());
            }
            p[3] = mw[0] * mixel_pdf(x, lo, g[1].mean, noise);
            p[4] = mw[1] * mixel_pdf(x, g[0].mean, g[1].mean, noise);
            p[5] = mw[2] * mixel_pdf(x, g[1].mean, g[2].mean, noise);
            let s: f64 = p.iter().sum::<f64>().max(1e-300);
            for c in 0..3 {
                let r = h * p[c] / s;
                acc[c][0] += r;
                acc[c][1] += r * x;
                acc[c][2] += r * x * x;
                macc[c] += h * p[3 + c] / s;
            }
        }
        for c in 0..3 {
            if acc[c][0] > 0.0 {
                g[c].weight = acc[c][0] / total;
                g[c].mean = acc[c][1] / acc[c][0];
                g[c].sigma = (acc[c][2] / acc[c][0] - g[c].mean.powi(2))
                    .max(bw * bw)
                    .sqrt();
            }
            g[c].mean = g[c].mean.clamp(range[c].0, range[c].1);
            g[c].sigma = g[c].sigma.clamp(range[c].2, range[c].3);
            mw[c] = macc[c] / total;
        }
        // A boundary cannot hold more voxels than the classes it separates (else a flat mixel
        // swallows a broad class such as real bone, whose HU spread is wide and flat).
        mw[1] = mw[1].min(g[0].weight.min(g[1].weight));
        mw[2] = mw[2].min(g[2].weight);
    }
    g.to_vec()
}

/// Where w1 N(μ1,σ1) = w2 N(μ2,σ2), between the two means.
fn crossing(a: &Gaussian, b: &Gaussian) -> f64 {
    let f = |x: f64| {
        a.weight / a.sigma * (-(x - a.mean).powi(2) / (2.0 * a.sigma * a.sigma)).exp()
            - b.weight / b.sigma * (-(x - b.mean).powi(2) / (2.0 * b.sigma * b.sigma)).exp()
    };
    let (mut lo, mut hi) = (a.mean.min(b.mean), a.mean.max(b.mean));
    if f(lo).signum() == f(hi).signum() {
        return 0.5 * (lo + hi);
    }
    for _ in 0..100 {
        let m = 0.5 * (lo + hi);
        if f(m).signum() == f(lo).signum() {
            lo = m
        } else {
            hi = m
        }
    }
    0.5 * (lo + hi)
}

/// The head: the largest 6-connected component above the head threshold.
struct Head {
    runs: Runs,
    voxels: usize,
    removed_components: usize,
    removed_voxels: usize,
}

fn find_head(vol: &Volume, t: &Tissue, name: &std::path::Path) -> Result<Head> {
    // Masks as runs along x (src/segment/runs.rs): components without per-voxel labels.
    let above = Runs::find(vol.dims, |a| vol.data[a] as f64 > t.head_threshold);
    let (comp, sizes) = above.components(false);
    let Some((head_id, &head_voxels)) = sizes.iter().enumerate().max_by_key(|(_, s)| **s) else {
        return Err(Error::input(
            name,
            format!(
                "no tissue above {} HU: no head in this CT",
                t.head_threshold
            ),
        ));
    };
    Ok(Head {
        runs: above.filter(|q| comp[q] == head_id as u32),
        voxels: head_voxels,
        removed_components: sizes.len() - 1,
        removed_voxels: above.voxels() - head_voxels,
    })
}

/// Outside air: the components of the non-head voxels that touch the volume border; the
/// others are cavities (sinuses, airway). Returns the outside air and the cavity voxel count.
fn outside_air(head_runs: &Runs, dims: [usize; 3]) -> (Runs, usize) {
    let [nx, ny, nz] = dims;
    let air = head_runs.complement();
    let (air_comp, air_sizes) = air.components(false);
    let mut border = vec![false; air_sizes.len()];
    for r in 0..air.row_start.len() - 1 {
        let (j, k) = air.row(r);
        let edge_row = j == 0 || k == 0 || j + 1 == ny || k + 1 == nz;
        for q in air.row_start[r]..air.row_start[r + 1] {
            let [x0, x1] = air.runs[q];
            if edge_row || x0 == 0 || x1 as usize == nx {
                border[air_comp[q] as usize] = true;
            }
        }
    }
    let outside_runs = air.filter(|q| border[air_comp[q] as usize]);
    let cavity_voxels = air.voxels() - outside_runs.voxels();
    (outside_runs, cavity_voxels)
}

/// The HU windows of `t.method`, with the fitted mixture, its crossings and the fit's
/// warnings (method = "fit").
struct ChosenWindows {
    windows: Windows,
    mixture: Option<Vec<Gaussian>>,
    crossings: Option<[f64; 2]>,
    warnings: Vec<String>,
}

fn choose_windows(
    vol: &Volume,
    head_runs: &Runs,
    t: &Tissue,
    name: &std::path::Path,
) -> Result<ChosenWindows> {
    match t.method {
        TissueMethod::Windows => Ok(ChosenWindows {
            windows: Windows {
                head_threshold: t.head_threshold,
                fat_dark: t.fat_dark,
                fat_bright: t.fat_bright,
                soft: t.soft,
                bone: t.bone,
            },
            mixture: None,
            crossings: None,
            warnings: Vec::new(),
        }),
        TissueMethod::Fit => fitted_windows(vol, head_runs, t, name),
    }
}

fn fitted_windows(
    vol: &Volume,
    head_runs: &Runs,
    t: &Tissue,
    name: &std::path::Path,
) -> Result<ChosenWindows> {
    let g = fit_mixture(&head_histogram(vol, head_runs, t), t);
    // Bounds at the midpoints of neighbouring means, not where the weighted Gaussians
    // cross: at a tissue boundary a voxel that is half one class and half the other has
    // the mean of the two, so the midpoint is the unbiased partial-volume threshold. The
    // crossing is Bayes-optimal only for pure voxels; with a narrow, heavy soft-tissue
    // peak beside a broad bone component it sits near the soft peak and thickens bone
    // (docs/design/pipeline.md §1). The crossings are reported for comparison.
    let w = Windows {
        head_threshold: t.head_threshold,
        fat_dark: (g[0].mean - 3.0 * g[0].sigma).max(t.head_threshold + 1.0),
        fat_bright: g[0].mean,
        soft: 0.5 * (g[0].mean + g[1].mean),
        bone: 0.5 * (g[1].mean + g[2].mean),
    };
    let crossings = Some([crossing(&g[0], &g[1]), crossing(&g[1], &g[2])]);
    let mut warnings = Vec::new();
    let bounds = [(t.fat_dark, t.soft), (t.soft, t.bone), (t.bone, 2000.0)];
    for (c, (lo, hi)) in g.iter().zip(bounds) {
        if c.mean <= lo + 1e-9 || c.mean >= hi - 1e-9 {
            warnings.push(format!(
                "tissue fit: the {} component has no peak of its own inside [{lo}, {hi}] HU (its mean sits at the bound); its window is a guess",
                c.name
            ));
        }
    }
    let b = [w.head_threshold, w.fat_dark, w.fat_bright, w.soft, w.bone];
    if b.windows(2).any(|p| !(p[0] < p[1])) || b.iter().any(|x| !x.is_finite()) {
        return Err(Error::input(
            name,
            format!(
                "the tissue fit did not separate fat, soft tissue and bone (bounds {b:?}); use method = \"windows\""
            ),
        ));
    }
    Ok(ChosenWindows {
        windows: w,
        mixture: Some(g),
        crossings,
        warnings,
    })
}

/// The kept bone: 26-connected runs of head voxels at or above the bone bound, pieces under
/// `min_bone_component_mm3` dropped.
struct Bone {
    runs: Runs,
    kept: usize,
    dropped: usize,
    voxels_dropped: usize,
}

fn keep_bone(
    vol: &Volume,
    head: &[bool],
    bone_hu: f64,
    t: &Tissue,
    name: &std::path::Path,
) -> Result<Bone> {
    let bone_runs = Runs::find(vol.dims, |a| head[a] && vol.data[a] as f64 >= bone_hu);
    let (bcomp, bsizes) = bone_runs.components(true);
    let vv = vol.voxel_volume();
    let keep: Vec<bool> = bsizes
        .iter()
        .map(|&s| s as f64 * vv >= t.min_bone_component_mm3)
        .collect();
    let kept = keep.iter().filter(|k| **k).count();
    if kept == 0 {
        return Err(Error::input(
            name,
            format!(
                "no bone found (no piece of at least {} mm³ above {} HU): a CT with bone is needed",
                t.min_bone_component_mm3, bone_hu
            ),
        ));
    }
    let voxels_dropped: usize = bsizes
        .iter()
        .zip(&keep)
        .filter(|(_, k)| !**k)
        .map(|(s, _)| s)
        .sum();
    Ok(Bone {
        runs: bone_runs.filter(|q| keep[bcomp[q] as usize]),
        kept,
        dropped: keep.len() - kept,
        voxels_dropped,
    })
}

/// Soft-tissue labels per voxel: skin within the skin layer of the outside air (and every
/// head voxel touching it), else by the HU windows; AIR outside the head.
fn soft_labels(
    vol: &Volume,
    head: &[bool],
    outside_runs: &Runs,
    windows: &Windows,
    t: &Tissue,
) -> Vec<u8> {
    // The surface lies about half a voxel in front of the nearest outside-air voxel centre.
    let h = (vol.spacing[0] * vol.spacing[1] * vol.spacing[2]).cbrt();
    let skin_d = t.skin_thickness_mm + 0.5 * h;
    let touch = vol.spacing.iter().cloned().fold(0.0, f64::max) * 1.01;
    // Only distances up to the skin layer's depth matter: the transform is cut there.
    let band = skin_d.max(touch) * 1.001;
    let d2 = distance_sq_within(
        &outside_runs.paint(),
        vol.dims,
        vol.spacing,
        (band * band) as f32,
    );
    (0..vol.len())
        .into_par_iter()
        .map(|a| {
            if !head[a] {
                return AIR;
            }
            let hu = vol.data[a] as f64;
            let d = (d2[a] as f64).sqrt();
            if d <= touch
                || (d <= skin_d && hu >= windows.soft)
                || (d <= skin_d && hu < windows.fat_dark)
            {
                SKIN
            } else if hu < windows.fat_dark {
                AIR
            } else if hu < windows.fat_bright {
                FAT_DARK
            } else if hu < windows.soft {
                FAT_BRIGHT
            } else {
                MUSCLE
            }
        })
        .collect()
}

/// Voxels per label, in LABEL_NAMES order.
fn count_labels(labels: &[u8]) -> [usize; 6] {
    labels
        .par_chunks(1 << 16)
        .map(|c| {
            let mut k = [0usize; 6];
            for &l in c {
                k[l as usize] += 1;
            }
            k
        })
        .reduce(|| [0; 6], |a, b| std::array::from_fn(|i| a[i] + b[i]))
}

pub fn segment(vol: &Volume, t: &Tissue, name: &std::path::Path) -> Result<Segmentation> {
    let head_part = find_head(vol, t, name)?;
    let head = head_part.runs.paint();
    let (outside_runs, cavity_voxels) = outside_air(&head_part.runs, vol.dims);
    let chosen = choose_windows(vol, &head_part.runs, t, name)?;
    let windows = chosen.windows;
    let bone = keep_bone(vol, &head, windows.bone, t, name)?;
    let mut labels = soft_labels(vol, &head, &outside_runs, &windows, t);
    // Kept bone overrides the soft-tissue classes.
    bone.runs.paint_into(&mut labels, BONE);
    let counts = count_labels(&labels);
    if counts[SKIN as usize] == 0 {
        return Err(Error::input(
            name,
            "no skin found: the head touches the volume border everywhere",
        ));
    }
    let vv = vol.voxel_volume();
    let report = SegmentReport {
        method: format!("{:?}", t.method).to_lowercase(),
        windows: windows.clone(),
        mixture: chosen.mixture,
        mixture_crossings: chosen.crossings,
        head_voxels: head_part.voxels,
        removed_components: head_part.removed_components,
        removed_voxels: head_part.removed_voxels,
        bone_components_kept: bone.kept,
        bone_components_dropped: bone.dropped,
        bone_voxels_dropped: bone.voxels_dropped,
        cavity_voxels,
        warnings: chosen.warnings,
        volumes_mm3: LABEL_NAMES
            .iter()
            .zip(counts)
            .map(|(n, c)| (n.to_string(), c as f64 * vv))
            .collect(),
    };
    Ok(Segmentation {
        labels,
        head,
        outside: outside_runs,
        windows,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_count_six_versus_26() {
        // Two voxels touching only at a corner.
        let dims = [2, 2, 2];
        let mut m = vec![false; 8];
        m[0] = true;
        m[7] = true;
        assert_eq!(components(&m, dims, false).1.len(), 2);
        assert_eq!(components(&m, dims, true).1.len(), 1);
    }

    #[test]
    fn mixture_crossing_is_midpoint_for_equal_gaussians() {
        let a = Gaussian {
            name: "a".into(),
            weight: 0.5,
            mean: 0.0,
            sigma: 10.0,
        };
        let b = Gaussian {
            name: "b".into(),
            weight: 0.5,
            mean: 100.0,
            sigma: 10.0,
        };
        assert!((crossing(&a, &b) - 50.0).abs() < 1e-9);
    }
}
