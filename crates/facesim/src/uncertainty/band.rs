//! The band: per value over the samples, the mean and the 5th and 95th percentiles.

use crate::error::Result;
use crate::mesh::Mesh;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Mean and 5–95 % band of one quantity over the samples (mm).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Band {
    pub mean: f64,
    pub p05: f64,
    pub p95: f64,
}

impl Band {
    /// Of `values` (one per sample, at least one).
    pub fn of(values: &[f64]) -> Band {
        let mut s = values.to_vec();
        s.sort_by(f64::total_cmp);
        Band {
            mean: mean(values),
            p05: quantile(&s, 0.05),
            p95: quantile(&s, 0.95),
        }
    }

    pub fn width(&self) -> f64 {
        self.p95 - self.p05
    }
}

/// The mean as x₀ + Σ(xᵢ − x₀)/n: equal values give that value exactly (a plain sum / n may not).
pub fn mean(v: &[f64]) -> f64 {
    let Some(&x0) = v.first() else {
        return f64::NAN;
    };
    x0 + v.iter().map(|x| x - x0).sum::<f64>() / v.len() as f64
}

/// The q-quantile of sorted values, linear between order statistics (Hyndman and Fan type 7,
/// numpy's default): position q·(n−1).
pub(crate) fn quantile(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let h = q * (n - 1) as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(n - 1);
    let f = h - lo as f64;
    sorted[lo] + f * (sorted[hi] - sorted[lo])
}

/// Per vertex, the band of the displacement magnitude; `samples[s][v]` is sample s's
/// magnitude at vertex v.
pub(crate) fn per_vertex(samples: &[Vec<f64>], vertices: usize) -> Vec<Band> {
    use rayon::prelude::*;
    (0..vertices)
        .into_par_iter()
        .map(|v| {
            let column: Vec<f64> = samples.iter().map(|s| s[v]).collect();
            Band::of(&column)
        })
        .collect()
}

/// face_band.ply: `face` (the nominal predicted face) with float vertex properties `mean`,
/// `p05`, `p95` (mm), binary little-endian, written to a temporary name and renamed.
pub(crate) fn write_ply(face: &Mesh, bands: &[Band], path: &Path) -> Result<()> {
    let mut m = face.clone();
    m.colors = None;
    m.vertex_columns.clear();
    for (name, f) in [
        ("mean", (|b: &Band| b.mean) as fn(&Band) -> f64),
        ("p05", |b| b.p05),
        ("p95", |b| b.p95),
    ] {
        m.vertex_columns.push(crate::mesh::Column {
            name: name.into(),
            values: bands.iter().map(f).collect(),
        });
    }
    crate::mesh::ply::write(&m, path, crate::mesh::ply::Encoding::BinaryLittleEndian)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_numpy_type_7() {
        // numpy.percentile([1, 2, 3, 4, 10], [5, 95]) = [1.2, 8.8].
        let b = Band::of(&[10.0, 2.0, 1.0, 4.0, 3.0]);
        assert!(
            (b.p05 - 1.2).abs() < 1e-12 && (b.p95 - 8.8).abs() < 1e-12,
            "{b:?}"
        );
        assert_eq!(b.mean, 4.0);
    }

    #[test]
    fn equal_values_give_a_zero_band_exactly() {
        for x in [0.1, 1.0 / 3.0, 4.567_891_234_5] {
            let b = Band::of(&[x; 7]);
            assert_eq!((b.mean, b.p05, b.p95), (x, x, x));
        }
    }
}
