//! The second real sample, VTK's headsq (data-samples/real-mandible, fetched from npm's
//! vtk.js@6.4.1): the vtk.js dataset folder read as it is, and the frame and HU its case states.

use crate::common;

use facesim::volume::{axes_code, read_volume};

#[test]
fn headsq_reads_as_vtkjs_ships_it() {
    let v = read_volume(&common::real_mandible_ct()).unwrap();
    assert_eq!(v.dims, [64, 64, 93]);
    assert_eq!(v.spacing, [3.2, 3.2, 1.5]);
    assert_eq!(v.origin, [0.0, 0.0, 0.0]);
    // vtk.js's own direction: a 30° turn about k (display only; the case replaces it).
    assert_eq!(v.direction[0], [0.866, 0.5, 0.0]);
    assert_eq!(v.direction[1], [-0.5, 0.866, 0.0]);
    assert_eq!(v.direction[2], [0.0, 0.0, 1.0]);
    // Stored numbers = HU + 1024: air 0, soft tissue's peak just above 1024, teeth to 3926.
    let (lo, hi) = v
        .data
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert_eq!((lo, hi), (0.0, 3926.0));
    let soft = v
        .data
        .iter()
        .filter(|x| (1024.0..1124.0).contains(*x))
        .count();
    let fat = v
        .data
        .iter()
        .filter(|x| (904.0..1004.0).contains(*x))
        .count();
    assert!(soft > 50_000 && soft > fat, "soft {soft} fat {fat}");
}

/// The anatomy behind `[ct] axes = "LAI"`: j grows toward the face (the mandible's symphysis is
/// at larger j than its rami, the spine at small j), k grows downward (the head is widest at
/// slice 0 and the chin's bone ends near the last slice).
#[test]
fn headsq_axes_point_left_anterior_inferior() {
    let v = read_volume(&common::real_mandible_ct()).unwrap();
    let hu = |i: usize, j: usize, k: usize| v.data[v.idx(i, j, k)] - 1024.0;
    // Slice 80 (z = -120 mm): the mandible's bone is in front (j > 32), the vertebra behind.
    let bone_j = |k: usize, js: std::ops::Range<usize>| {
        js.flat_map(|j| (0..64).map(move |i| (i, j)))
            .filter(|&(i, j)| hu(i, j, k) > 300.0)
            .count()
    };
    assert!(bone_j(80, 36..46) > 40, "{}", bone_j(80, 36..46));
    assert!(bone_j(80, 12..26) > 20, "{}", bone_j(80, 12..26));
    // The head's cross-section (above −500 HU) shrinks from the forehead (k = 0) to the chin.
    let area = |k: usize| {
        (0..64 * 64)
            .filter(|n| hu(n % 64, n / 64, k) > -500.0)
            .count()
    };
    assert!(area(0) > area(85) + 500, "{} {}", area(0), area(85));
    // The most anterior skin at the lips' level lies at large j, at mid-width.
    let k = 62;
    let (mut best, mut bi) = (0, 0);
    for i in 0..64 {
        if let Some(j) = (0..64).rev().find(|&j| hu(i, j, k) > -500.0)
            && j > best
        {
            (best, bi) = (j, i);
        }
    }
    assert!(best > 45 && (22..42).contains(&bi), "j {best} i {bi}");
    // "LAI" keeps the grid right-handed (no mirror): i × j = k in LPS.
    let d = axes_code("LAI").unwrap();
    let c = [
        d[0][1] * d[1][2] - d[0][2] * d[1][1],
        d[0][2] * d[1][0] - d[0][0] * d[1][2],
        d[0][0] * d[1][1] - d[0][1] * d[1][0],
    ];
    assert_eq!(c, d[2]);
}
