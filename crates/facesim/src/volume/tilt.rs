//! Gantry tilt: a series whose slices are not stacked straight along their normal.
//!
//! A CT scanner whose gantry is tilted (routine in head CT, to keep the eye lenses out of the
//! beam) acquires planes that are each orthogonal images but are shifted across their plane from
//! one slice to the next, by tan(tilt) × slice spacing: the voxel grid is sheared, and a `Volume`
//! describes an orthogonal one. Each slice is therefore shifted back in its own plane onto the
//! grid through the first slice (bilinear interpolation; where no slice data falls, the series'
//! lowest value, which is air or the scanner's padding). Positions along the normal are kept, so
//! the slice spacing is the distance between the planes, not between their origins.

use rayon::prelude::*;

/// The in-plane offset of each slice from the first, in pixels along the rows (i) and columns
/// (j), given each slice's ImagePositionPatient, the row and column directions and the pixel
/// spacing (along i, along j).
pub(crate) fn drift_pixels(
    positions: &[[f64; 3]],
    row: [f64; 3],
    col: [f64; 3],
    spacing: [f64; 2],
) -> Vec<[f64; 2]> {
    let first = positions[0];
    positions
        .iter()
        .map(|p| {
            let d = [0, 1, 2].map(|a| p[a] - first[a]);
            let along = |u: [f64; 3]| d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
            [along(row) / spacing[0], along(col) / spacing[1]]
        })
        .collect()
}

/// Shift each slice of `data` (`dims` = [ni, nj, nk], i fastest) back by its drift (di, dj):
/// output pixel (i, j) of slice k lies where input pixel (i − di, j − dj) of that slice does
/// (the slice's origin is di, dj pixels from the grid's), read bilinearly; `fill` where that
/// point lies outside the slice.
pub(crate) fn resample(data: &mut [f32], dims: [usize; 3], drift: &[[f64; 2]], fill: f32) {
    let [ni, nj, _] = dims;
    // Positions are decimal strings of limited precision: a drift within 1e-4 pixel (0.1 µm) of
    // a whole number is that number, so whole-pixel shifts copy values exactly.
    let snap = |x: f64| {
        if (x - x.round()).abs() < 1e-4 {
            x.round()
        } else {
            x
        }
    };
    data.par_chunks_mut(ni * nj)
        .zip(drift)
        .for_each(|(slice, d)| {
            let d = d.map(snap);
            if d[0] == 0.0 && d[1] == 0.0 {
                return;
            }
            let src = slice.to_vec();
            let at = |i: isize, j: isize| -> Option<f32> {
                (i >= 0 && j >= 0 && (i as usize) < ni && (j as usize) < nj)
                    .then(|| src[j as usize * ni + i as usize])
            };
            for j in 0..nj {
                for i in 0..ni {
                    let (x, y) = (i as f64 - d[0], j as f64 - d[1]);
                    let (x0, y0) = (x.floor(), y.floor());
                    let (fx, fy) = (x - x0, y - y0);
                    let (x0, y0) = (x0 as isize, y0 as isize);
                    // Corners with zero weight may lie outside (an exact pixel shift at an edge).
                    let mut v = 0.0f64;
                    let mut inside = true;
                    for (dx, dy, w) in [
                        (0, 0, (1.0 - fx) * (1.0 - fy)),
                        (1, 0, fx * (1.0 - fy)),
                        (0, 1, (1.0 - fx) * fy),
                        (1, 1, fx * fy),
                    ] {
                        if w == 0.0 {
                            continue;
                        }
                        match at(x0 + dx, y0 + dy) {
                            Some(s) => v += w * s as f64,
                            None => inside = false,
                        }
                    }
                    slice[j * ni + i] = if inside { v as f32 } else { fill };
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_pixel_shifts_are_exact_and_half_pixels_average() {
        // Two 4 × 3 slices; the second drifted by one pixel along j and half a pixel along i.
        let mut data: Vec<f32> = (0..24).map(|v| v as f32).collect();
        let drift = drift_pixels(
            &[[0.0, 0.0, 0.0], [0.5 * 0.8, 1.0 * 1.2, 2.0]],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.8, 1.2],
        );
        assert_eq!(drift, vec![[0.0, 0.0], [0.5, 1.0]]);
        resample(&mut data, [4, 3, 2], &drift, -1.0);
        // First slice untouched.
        assert_eq!(
            &data[..12],
            &(0..12).map(|v| v as f32).collect::<Vec<_>>()[..]
        );
        // Second: (i, j) ← mean of input (i − 1, j − 1) and (i, j − 1); before the edges, the
        // fill.
        let input = |i: usize, j: usize| (12 + j * 4 + i) as f32;
        for j in 0..3 {
            for i in 0..4 {
                let want = if i >= 1 && j >= 1 {
                    0.5 * (input(i - 1, j - 1) + input(i, j - 1))
                } else {
                    -1.0
                };
                assert_eq!(data[12 + j * 4 + i], want, "({i}, {j})");
            }
        }
    }
}
