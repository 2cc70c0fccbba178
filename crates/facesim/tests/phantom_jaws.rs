//! The jaws phantom against its own analytic definition (docs/phantom.md, "Jaws"): the CT's
//! segmentation finds the bone pieces and the vestibule where `tissue_at` puts them, with the
//! volumes quadrature gives; landmarks lie where their definitions say; the osteotomy boxes
//! move exactly their segment; the capsule head is unchanged.

use facesim::case::Case;
use facesim::osteotomy::Plan;
use facesim::phantom::PhantomOptions;
use facesim::phantom_jaws::{self as pj, Piece, Tissue};
use facesim::segment::{self, AIR, BONE, FAT_BRIGHT, FAT_DARK, MUSCLE, SKIN, Segmentation};
use facesim::volume::Volume;
use rayon::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// The whole-head CT at 2 mm (the coarsest spacing the bundled cases use: the hardest for
/// keeping the bone pieces apart) and its segmentation with the default tissue parameters.
fn head() -> &'static (Volume, Segmentation) {
    static H: OnceLock<(Volume, Segmentation)> = OnceLock::new();
    H.get_or_init(|| {
        let opts = PhantomOptions {
            spacing: [2.0; 3],
            ..Default::default()
        };
        let vol = pj::ct(&opts);
        let seg = segment::segment(&vol, &Case::default().tissue, Path::new("ct.nii.gz")).unwrap();
        (vol, seg)
    })
}

fn centre(vol: &Volume, a: usize) -> [f64; 3] {
    let [nx, ny, _] = vol.dims;
    let ijk = [a % nx, (a / nx) % ny, a / (nx * ny)];
    [0, 1, 2].map(|d| vol.origin[d] + ijk[d] as f64 * vol.spacing[d])
}

/// Points spread over a voxel's cube (4 per axis, corners included): the voxel is "pure" when
/// `tissue_at` is the same at all of them.
fn pure_tissue(vol: &Volume, a: usize) -> Option<Tissue> {
    let c = centre(vol, a);
    let mut first = None;
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..4 {
                let o = [i, j, k];
                let p = [0, 1, 2].map(|d| c[d] + (o[d] as f64 / 3.0 - 0.5) * vol.spacing[d]);
                let t = pj::tissue_at(p);
                match first {
                    None => first = Some(t),
                    Some(f) if f != t => return None,
                    _ => {}
                }
            }
        }
    }
    first
}

fn piece_index(p: Piece) -> usize {
    match p {
        Piece::Cranium => 0,
        Piece::Maxilla => 1,
        Piece::Mandible => 2,
    }
}

#[test]
fn segmentation_finds_cranium_maxilla_and_mandible_as_separate_bone() {
    let (vol, seg) = head();
    assert_eq!(seg.report.bone_components_kept, 3, "{:?}", seg.report);
    let bone: Vec<bool> = seg.labels.iter().map(|&l| l == BONE).collect();
    let (comp, sizes) = segment::components(&bone, vol.dims, true);
    assert_eq!(sizes.len(), 3, "26-connected bone pieces: {sizes:?}");
    // Every voxel lying wholly inside one piece is bone, in that piece's component.
    let mut owner = [None::<u32>; 3];
    let mut deep = [0usize; 3];
    for a in 0..vol.len() {
        let Some(t @ (Tissue::Bone | Tissue::Tooth)) = pure_tissue(vol, a) else {
            continue;
        };
        let piece = pj::piece_at(centre(vol, a)).unwrap();
        assert!(
            bone[a],
            "{t:?} voxel at {:?} not labelled bone",
            centre(vol, a)
        );
        let k = piece_index(piece);
        deep[k] += 1;
        match owner[k] {
            None => owner[k] = Some(comp[a]),
            Some(c) => assert_eq!(c, comp[a], "{piece:?} split at {:?}", centre(vol, a)),
        }
    }
    println!("voxels wholly inside cranium, maxilla, mandible: {deep:?}; components {sizes:?}");
    let owners: Vec<u32> = owner.iter().map(|o| o.unwrap()).collect();
    assert!(owners[0] != owners[1] && owners[1] != owners[2] && owners[0] != owners[2]);
}

/// Volume and Crofton measure ∫(|n_x| + |n_y| + |n_z|) dA of one piece inside [lo, hi], by
/// midpoint quadrature of `piece_at` on a grid of steps h (crossings between grid neighbours
/// along axis a, times the cell face normal to a). The phantom's flat faces lie on multiples of
/// 0.5 mm in x, y and z, so with h = (0.5, 0.5, 0.25) and `lo` on that lattice they fall on
/// cell faces and are integrated exactly.
fn quadrature(piece: Piece, lo: [f64; 3], hi: [f64; 3], h: [f64; 3]) -> (f64, f64) {
    let n = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / h[a]).round() as usize);
    let inside = |i: usize, j: usize, k: usize| {
        let p = [i, j, k];
        pj::piece_at([0, 1, 2].map(|a| lo[a] + (p[a] as f64 + 0.5) * h[a])) == Some(piece)
    };
    let (vol, cross) = (0..n[2])
        .into_par_iter()
        .map(|k| {
            let (mut v, mut c) = (0usize, [0usize; 3]);
            for j in 0..n[1] {
                let mut prev = false;
                for i in 0..n[0] {
                    let here = inside(i, j, k);
                    v += here as usize;
                    c[0] += (i > 0 && here != prev) as usize;
                    c[1] += (j > 0 && here != inside(i, j - 1, k)) as usize;
                    c[2] += (k > 0 && here != inside(i, j, k - 1)) as usize;
                    prev = here;
                }
            }
            (v, c)
        })
        .reduce(
            || (0, [0; 3]),
            |a, b| {
                (
                    a.0 + b.0,
                    [a.1[0] + b.1[0], a.1[1] + b.1[1], a.1[2] + b.1[2]],
                )
            },
        );
    let dv = h[0] * h[1] * h[2];
    let area = [h[1] * h[2], h[0] * h[2], h[0] * h[1]];
    (
        vol as f64 * dv,
        (0..3).map(|a| cross[a] as f64 * area[a]).sum(),
    )
}

const H_QUAD: [f64; 3] = [0.5, 0.5, 0.25];

#[test]
fn bone_volumes_match_quadrature_within_the_partial_volume_bound() {
    let (vol, seg) = head();
    let h = vol.spacing[0];
    let vv = vol.voxel_volume();
    let bone: Vec<bool> = seg.labels.iter().map(|&l| l == BONE).collect();
    let (comp, sizes) = segment::components(&bone, vol.dims, true);
    // Which component is which piece: the one holding the piece's reference point.
    let at = |p: [f64; 3]| {
        let ijk = [0, 1, 2].map(|d| ((p[d] - vol.origin[d]) / vol.spacing[d]).round() as usize);
        comp[ijk[0] + vol.dims[0] * (ijk[1] + vol.dims[1] * ijk[2])] as usize
    };
    let refs = [
        (Piece::Cranium, [0.0, 63.5, 20.0]),
        (Piece::Maxilla, [0.0, -70.0, -8.0]),
        (Piece::Mandible, [0.0, -66.0, -52.0]),
    ];
    // Voxels extend half a voxel beyond the first and last centres.
    let top = pj::FOV_HI[2] + 0.5 * h;
    let boxes = [
        ([-93.0, -93.0, pj::Z_SKULL_BASE], [93.0, 93.0, top]),
        ([-31.0, -76.0, -24.0], [31.0, -17.0, 2.0]),
        ([-60.0, -78.0, -67.0], [60.0, 17.0, 2.0]),
    ];
    for ((piece, p), (lo, hi)) in refs.into_iter().zip(boxes) {
        assert_eq!(pj::piece_at(p), Some(piece));
        let got = sizes[at(p)] as f64 * vv;
        let (truth, crofton) = quadrature(piece, lo, hi, H_QUAD);
        // A 300 HU threshold counts a boundary voxel as bone when its bone fraction exceeds
        // f* = (300 − HU_other)/(HU_bone − HU_other): 0.46 against soft tissue, 0.57 against
        // fat, 0.81 against air; teeth (1500 HU) 0.18 against soft tissue, 0.52 against air.
        // The thresholded boundary then moves by up to |f* − ½| of the voxel's extent along
        // the normal, h (|n_x| + |n_y| + |n_z|): |ΔV| ≤ max |f* − ½| · h · ∫(|n_x| + |n_y| +
        // |n_z|) dA = 0.32 h × the Crofton measure. (The grid's quantisation of a face adds up
        // to ±h/2 locally but averages out over curved faces; the flat faces aligned with the
        // grid — skull base, Le Fort I and occlusal cuts — are a small part of each surface.)
        let bound = 0.32 * h * crofton;
        let rel = got / truth - 1.0;
        println!(
            "{piece:?}: segmented {got:.0} mm³, quadrature {truth:.0} mm³ ({:+.2} %), bound ±{bound:.0} mm³ ({:.1} %)",
            100.0 * rel,
            100.0 * bound / truth
        );
        assert!((got - truth).abs() <= bound, "{piece:?}");
    }
    // The cranium also has a closed form: the cylinder shell and the skull-base plate.
    let pi = std::f64::consts::PI;
    let closed = pi * (67f64.powi(2) - 60f64.powi(2)) * (top - pj::Z_SKULL_BASE)
        + pi * 60f64.powi(2) * (pj::Z_BRAIN - pj::Z_SKULL_BASE);
    let (quad, _) = quadrature(Piece::Cranium, boxes[0].0, boxes[0].1, H_QUAD);
    assert!((quad / closed - 1.0).abs() < 2e-3, "{quad} vs {closed}");
}

/// A 0.75 mm CT of the mouth, fine enough to hold voxels wholly inside the 2 mm vestibule.
fn mouth() -> &'static (Volume, Segmentation) {
    static M: OnceLock<(Volume, Segmentation)> = OnceLock::new();
    M.get_or_init(|| {
        let opts = PhantomOptions {
            spacing: [0.75; 3],
            supersample: 2,
            ..Default::default()
        };
        let vol = pj::ct_box(&opts, [-40.0, -100.0, -50.0], [40.0, -30.0, 2.0]);
        let seg = segment::segment(&vol, &Case::default().tissue, Path::new("mouth")).unwrap();
        (vol, seg)
    })
}

#[test]
fn labels_are_the_analytic_tissues_away_from_boundaries_and_the_vestibule_is_enclosed_air() {
    let (vol, seg) = mouth();
    let mut checked = std::collections::BTreeMap::new();
    let mut vestibule = 0usize;
    for a in 0..vol.len() {
        let Some(t) = pure_tissue(vol, a) else {
            continue;
        };
        let l = seg.labels[a];
        let ok = match t {
            Tissue::Air => l == AIR,
            Tissue::Skin => l == SKIN,
            Tissue::Fat => l == FAT_DARK || l == FAT_BRIGHT,
            Tissue::Soft | Tissue::Brain => l == MUSCLE,
            Tissue::Bone | Tissue::Tooth => l == BONE,
        };
        assert!(ok, "{t:?} at {:?} labelled {l}", centre(vol, a));
        *checked.entry(format!("{t:?}")).or_insert(0usize) += 1;
        if t == Tissue::Air && pj::in_vestibule(centre(vol, a)) {
            vestibule += 1;
            // Air inside the head: not connected to the outside air (a cavity).
            assert!(!seg.head[a]);
        }
    }
    println!(
        "pure voxels checked: {checked:?}; in the vestibule {vestibule}; cavity voxels {}",
        seg.report.cavity_voxels
    );
    assert!(vestibule > 500, "{vestibule}");
    assert!(seg.report.cavity_voxels >= vestibule);
    for t in ["Skin", "Fat", "Soft", "Bone", "Tooth"] {
        assert!(checked.get(t).copied().unwrap_or(0) > 100, "{t}");
    }
}
