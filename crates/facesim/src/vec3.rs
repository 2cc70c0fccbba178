//! 3-vectors as `[f64; 3]` (points, displacements, normals in LPS millimetres): the one set of
//! helpers the whole library, the CLI and the lab use, so every copy computes the same bits.
//! It imports nothing from the crate, so any module may use it without adding an import cycle.

/// a − b.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a + b.
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Each point moved by its displacement (`points` and `d` in the same order).
pub(crate) fn displaced(points: &[[f64; 3]], d: &[[f64; 3]]) -> Vec<[f64; 3]> {
    points.iter().zip(d).map(|(p, d)| add(*p, *d)).collect()
}

/// a·s.
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// The dot product, summed x, y, z in that order.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The cross product a × b (right-handed).
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The Euclidean length.
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_of_the_axes() {
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        assert_eq!(cross(x, y), z);
        assert_eq!(cross(y, x), scale(z, -1.0));
        assert_eq!(dot(x, y), 0.0);
        assert_eq!(add(sub(z, x), x), z);
        assert_eq!(norm([3.0, 4.0, 12.0]), 13.0);
    }
}
