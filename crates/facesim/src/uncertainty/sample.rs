//! A seeded quasi-random sequence: the Halton sequence (one prime base per dimension) with
//! random digit permutations (a permutation of {0..b-1} per dimension and digit position, drawn
//! from the seed). Each permutation is a bijection of a digit, so the scrambled points keep the
//! Halton sequence's stratification: of the first b^m points, exactly one lies in each interval
//! [j/b^m, (j+1)/b^m) of its dimension, and of the first 2^a·3^c points exactly one in each box of
//! the 2^a × 3^c grid of dimensions 0 and 1. Scrambling removes the correlation of the plain
//! sequence's higher bases and makes every seed a different, equally good sample.

/// The bases of the dimensions (the first primes).
pub(crate) const BASES: [u64; 8] = [2, 3, 5, 7, 11, 13, 17, 19];

/// SplitMix64 (Steele, Lea and Flood 2014): a tiny seeded generator for the permutations.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n (n ≤ 2^32; the modulo bias is below 2^-32).
    fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}

/// The scrambled Halton sequence in `dims` dimensions.
#[derive(Clone, Debug)]
pub(crate) struct ScrambledHalton {
    /// Per dimension, per digit position: the digit permutation.
    perms: Vec<Vec<Vec<u8>>>,
}

impl ScrambledHalton {
    /// `dims` ≤ [`BASES`].len() dimensions, scrambled by `seed`.
    pub fn new(dims: usize, seed: u64) -> ScrambledHalton {
        let mut rng = SplitMix64::new(seed);
        let perms = BASES[..dims.min(BASES.len())]
            .iter()
            .map(|&b| {
                (0..digits(b))
                    .map(|_| {
                        // Fisher–Yates.
                        let mut p: Vec<u8> = (0..b as u8).collect();
                        for i in (1..p.len()).rev() {
                            p.swap(i, rng.below(i as u64 + 1) as usize);
                        }
                        p
                    })
                    .collect()
            })
            .collect();
        ScrambledHalton { perms }
    }

    // Only the unit tests use it (a reference the production path does not need).
    #[cfg(test)]
    pub fn dims(&self) -> usize {
        self.perms.len()
    }

    /// Point `index` (0, 1, 2, …), coordinate `dim`, in [0, 1).
    pub fn at(&self, index: u64, dim: usize) -> f64 {
        let b = BASES[dim];
        let mut i = index;
        let mut x = 0.0;
        let mut scale = 1.0 / b as f64;
        // Every digit position up to double precision is permuted, the zeros past the index's
        // last digit too (else the points would cluster at the permuted zero's value).
        for perm in &self.perms[dim] {
            x += perm[(i % b) as usize] as f64 * scale;
            i /= b;
            scale /= b as f64;
        }
        // Rounding of the sum may reach 1.0 only when every digit is b−1 to double precision.
        x.min(1.0 - f64::EPSILON / 2.0)
    }

    // Only the unit tests use it (a reference the production path does not need).
    #[cfg(test)]
    /// Point `index` in every dimension.
    pub fn point(&self, index: u64) -> Vec<f64> {
        (0..self.dims()).map(|d| self.at(index, d)).collect()
    }
}

/// Digits of base `b` that reach double precision: b^-k < 2^-53.
fn digits(b: u64) -> usize {
    (53.0 / (b as f64).log2()).ceil() as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_dimension_is_stratified_for_every_seed() {
        for seed in [1, 2, 12345] {
            let h = ScrambledHalton::new(5, seed);
            for (d, &b) in BASES[..5].iter().enumerate() {
                for m in 1..=3 {
                    let n = b.pow(m);
                    let mut hit = vec![0; n as usize];
                    for i in 0..n {
                        let x = h.at(i, d);
                        assert!((0.0..1.0).contains(&x));
                        hit[(x * n as f64) as usize] += 1;
                    }
                    assert!(hit.iter().all(|c| *c == 1), "seed {seed} dim {d} b^{m}");
                }
            }
        }
    }

    #[test]
    fn two_dimensions_fill_the_mixed_radix_grid_once() {
        // 2^3 · 3^2 = 72 points: one in each of the 8 × 9 boxes (Chinese remainder theorem).
        let h = ScrambledHalton::new(2, 7);
        let mut hit = [[0; 9]; 8];
        for i in 0..72 {
            hit[(h.at(i, 0) * 8.0) as usize][(h.at(i, 1) * 9.0) as usize] += 1;
        }
        assert!(hit.iter().flatten().all(|c| *c == 1), "{hit:?}");
    }

    /// L2-star discrepancy (Warnock's formula) of points in [0,1)^d.
    fn l2_star(p: &[Vec<f64>]) -> f64 {
        let n = p.len() as f64;
        let d = p[0].len() as i32;
        let a = 3f64.powi(-d);
        let b: f64 = p
            .iter()
            .map(|x| x.iter().map(|v| (1.0 - v * v) / 2.0).product::<f64>())
            .sum::<f64>()
            * 2.0
            / n;
        let mut c = 0.0;
        for x in p {
            for y in p {
                c += x
                    .iter()
                    .zip(y)
                    .map(|(u, v)| 1.0 - u.max(*v))
                    .product::<f64>();
            }
        }
        (a - b + c / (n * n)).sqrt()
    }

    #[test]
    fn discrepancy_is_far_below_random_points() {
        // For independent uniform points E[T²] = (2^-d − 3^-d)/n; the quasi-random points of
        // every seed do better, the more so in fewer dimensions.
        let n = 1024;
        for (d, factor) in [(2, 0.2), (5, 0.5)] {
            let random_rms = ((2f64.powi(-d) - 3f64.powi(-d)) / n as f64).sqrt();
            for seed in [1, 2, 3] {
                let h = ScrambledHalton::new(d as usize, seed);
                let pts: Vec<Vec<f64>> = (0..n).map(|i| h.point(i)).collect();
                let t = l2_star(&pts);
                assert!(
                    t < factor * random_rms,
                    "d {d} seed {seed}: {t} vs random {random_rms}"
                );
            }
        }
    }

    #[test]
    fn the_seed_decides_the_points() {
        let a = ScrambledHalton::new(3, 1);
        let b = ScrambledHalton::new(3, 1);
        let c = ScrambledHalton::new(3, 2);
        let pa: Vec<_> = (0..20).map(|i| a.point(i)).collect();
        assert_eq!(pa, (0..20).map(|i| b.point(i)).collect::<Vec<_>>());
        assert_ne!(pa, (0..20).map(|i| c.point(i)).collect::<Vec<_>>());
    }
}
