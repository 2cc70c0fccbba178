//! Cohorts of synthetic patients: jaws phantoms whose shape parameters (head size, soft-tissue
//! thickness, prognathism, chin, midline shift, vertical pattern) are drawn from documented
//! ranges by a seed (docs/design/phantom.md, "Cohort parameters"; docs/guide/cohort.md).

use crate::phantom_jaws::{JawsOptions, SHAPE_RANGES, Shape, write_shaped_case};
use facesim::error::{Error, Result};
use std::path::Path;

/// The ranges a seed draws each parameter from, uniformly (SHAPE_RANGES order): adult
/// variation around the standard head, inside the accepted SHAPE_RANGES. Head size ±8 %
/// (the spread of adult head breadth); soft tissue −2..+4 mm (thin to obese faces);
/// prognathism ±3 mm and midline shift ±2 mm (Class II to Class III, mild laterognathia);
/// chin −2..+3 mm; vertical pattern −5..+7 mm: the lower anterior face height (ANS to menton)
/// of adults with a normal vertical pattern spans roughly 65–75 mm (the standard head has
/// 67.5), long-face (hyperdivergent) patients have some 5–10 mm more and short-face
/// (hypodivergent) ones several mm less, an approximate adult spread.
pub(crate) const DRAW_RANGES: [(&str, f64, f64); 6] = [
    ("scale", 0.92, 1.08),
    ("soft_mm", -2.0, 4.0),
    ("mandible_mm", -3.0, 3.0),
    ("chin_mm", -2.0, 3.0),
    ("asymmetry_mm", -2.0, 2.0),
    ("vertical_mm", -5.0, 7.0),
];

/// splitmix64: a well-mixed 64-bit value of `z`.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E3779B97F4A7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from (seed, stream, index).
fn uniform(seed: u64, stream: u64, index: u64) -> f64 {
    let h = mix(mix(mix(seed) ^ stream) ^ index);
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// The shape for `seed`: each parameter `given` as is, the others drawn uniformly from
/// DRAW_RANGES (rounded to 0.01 so files and tables show them exactly). The same seed always
/// draws the same values, whichever parameters are given.
pub fn draw(seed: u64, given: [Option<f64>; 6]) -> Shape {
    let mut v = [0.0; 6];
    for (k, (_, lo, hi)) in DRAW_RANGES.iter().enumerate() {
        v[k] = given[k].unwrap_or_else(|| {
            let u = uniform(seed, 0xC0_4047, k as u64);
            cents(lo + (hi - lo) * u)
        });
    }
    Shape::from_values(v)
}

/// The given parameters over the standard head (no seed: the others keep their defaults).
pub fn given_or_default(given: [Option<f64>; 6]) -> Shape {
    let d = Shape::default().values();
    Shape::from_values(std::array::from_fn(|k| given[k].unwrap_or(d[k])))
}

/// `v` rounded to 0.01, so files and tables show a drawn value exactly.
fn cents(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

/// The centre of stratum `i` of `n` equal strata of parameter `k`'s DRAW_RANGES range, rounded
/// to 0.01 as `draw` rounds (n = 1: the range's centre).
pub(crate) fn stratum_centre(k: usize, i: usize, n: usize) -> f64 {
    let (_, lo, hi) = DRAW_RANGES[k];
    cents(lo + (hi - lo) * (i as f64 + 0.5) / n as f64)
}

/// A permutation of 0..n drawn from `seed` (Fisher–Yates on the seed's own stream).
pub(crate) fn permutation(seed: u64, n: usize) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let u = uniform(seed, 0x9E4_0A7E, i as u64);
        let j = ((u * (i + 1) as f64) as usize).min(i);
        p.swap(i, j);
    }
    p
}

/// The seed of case `k` of a cohort drawn with `seed`.
pub(crate) fn case_seed(seed: u64, k: usize) -> u64 {
    mix(seed ^ mix(k as u64 + 1))
}

/// One case of a written cohort.
#[derive(Clone, Debug)]
pub struct CohortCase {
    /// The sub-directory name (`case001`, …).
    pub name: String,
    pub seed: u64,
    pub shape: Shape,
}

/// Write `n` distinct jaws phantoms into `dir/case001`, `dir/case002`, … (each a complete
/// case with its four plans and phantom.toml), their shapes drawn from `seed`, and
/// `dir/phantoms.csv` (case, seed, the parameters). Writes nothing when `n` is 0.
pub fn write_cohort(
    dir: &Path,
    n: usize,
    seed: u64,
    opts: &JawsOptions,
    given: [Option<f64>; 6],
    nasal_passages: bool,
) -> Result<Vec<CohortCase>> {
    if n == 0 {
        return Err(Error::config("phantom-cohort: --cases must be at least 1"));
    }
    let width = n.to_string().len().max(3);
    let cases: Vec<CohortCase> = (0..n)
        .map(|k| {
            let s = case_seed(seed, k);
            CohortCase {
                name: format!("case{:0width$}", k + 1),
                seed: s,
                shape: Shape {
                    nasal_passages,
                    ..draw(s, given)
                },
            }
        })
        .collect();
    for c in &cases {
        c.shape.validate()?;
    }
    facesim::output::create_dir_guarded(dir)?;
    for c in &cases {
        write_shaped_case(&dir.join(&c.name), opts, &c.shape)?;
    }
    let mut csv = String::from("case,seed");
    for (name, _, _) in SHAPE_RANGES {
        csv.push(',');
        csv.push_str(name);
    }
    csv.push('\n');
    for c in &cases {
        csv.push_str(&format!("{},{}", c.name, c.seed));
        for v in c.shape.values() {
            csv.push_str(&format!(",{v}"));
        }
        csv.push('\n');
    }
    facesim::output::write_bytes_atomic(&dir.join("phantoms.csv"), |w| {
        w.write_all(csv.as_bytes())
    })?;
    Ok(cases)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_stay_in_their_ranges_and_keep_given_values() {
        for seed in 0..200 {
            let s = draw(seed, [None, Some(1.5), None, None, None, None]);
            assert_eq!(s.soft_mm, 1.5);
            for ((_, lo, hi), v) in DRAW_RANGES.iter().zip(s.values()) {
                assert!(v >= *lo && v <= *hi, "{v} not in [{lo}, {hi}]");
            }
            assert!(s.validate().is_ok());
        }
        // Distinct seeds draw distinct heads; the same seed the same one.
        assert_ne!(draw(1, [None; 6]), draw(2, [None; 6]));
        assert_eq!(draw(7, [None; 6]), draw(7, [None; 6]));
        assert_ne!(case_seed(1, 0), case_seed(1, 1));
        // Giving one parameter leaves the others' draws as they are.
        let given_vertical = draw(3, [None, None, None, None, None, Some(2.0)]);
        assert_eq!(
            given_vertical.values()[..5],
            draw(3, [None; 6]).values()[..5]
        );
    }

    #[test]
    fn strata_and_permutations() {
        for n in 1..12 {
            let mut p = permutation(5, n);
            p.sort();
            assert_eq!(p, (0..n).collect::<Vec<_>>());
            for k in 0..DRAW_RANGES.len() {
                let (_, lo, hi) = DRAW_RANGES[k];
                let w = (hi - lo) / n as f64;
                for i in 0..n {
                    let c = stratum_centre(k, i, n);
                    let mid = lo + w * (i as f64 + 0.5);
                    assert!((c - mid).abs() <= 0.005 + 1e-12, "{k} {i} {n}: {c}");
                }
            }
        }
        assert_eq!(stratum_centre(5, 0, 1), 1.0);
        assert_eq!(stratum_centre(1, 0, 1), 1.0);
        // Different seeds pair the strata differently.
        assert_ne!(permutation(1, 8), permutation(2, 8));
    }

    #[test]
    fn draw_ranges_lie_inside_the_accepted_ranges() {
        for ((n, lo, hi), (m, a, b)) in DRAW_RANGES.iter().zip(SHAPE_RANGES.iter()) {
            assert_eq!(n, m);
            assert!(lo >= a && hi <= b, "{n}");
        }
    }
}
