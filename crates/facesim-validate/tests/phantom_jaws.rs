//! The jaws phantom against its own analytic definition (docs/design/phantom.md, "Jaws"): the CT's
//! segmentation finds the bone pieces and the vestibule where `tissue_at` puts them, with the
//! volumes quadrature gives; landmarks lie where their definitions say; the osteotomy boxes
//! move exactly their segment; the capsule head is unchanged.

use facesim::case::Case;
use facesim::osteotomy::Plan;
use facesim::segment::{self, AIR, BONE, FAT_BRIGHT, FAT_DARK, MUSCLE, SKIN, Segmentation};
use facesim::volume::Volume;
use facesim_validate::phantom::PhantomOptions;
use facesim_validate::phantom_jaws::{self as pj, Piece, Tissue};
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
        // The cylinder, and in front the bony glabella and the nasal bones (to y = −74).
        ([-68.0, -76.0, pj::Z_SKULL_BASE], [68.0, 68.0, top]),
        ([-36.0, -76.0, -24.0], [36.0, -12.0, 2.0]),
        ([-60.0, -78.0, -67.0], [60.0, 22.0, 2.0]),
    ];
    let mut cranium = 0.0;
    for ((piece, p), (lo, hi)) in refs.into_iter().zip(boxes) {
        assert_eq!(pj::piece_at(p), Some(piece));
        let got = sizes[at(p)] as f64 * vv;
        let (truth, crofton) = quadrature(piece, lo, hi, H_QUAD);
        if piece == Piece::Cranium {
            cranium = truth;
        }
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
    // The cranium also has a near-closed form: the cylinder shell, the skull-base plate and,
    // in front, the bumps R_o(φ, z) > 67 of the glabella and nasal bones, ∫∫ (R_o² − 67²)/2 dφ dz
    // (a 2-D midpoint rule: the bumps are smooth).
    let pi = std::f64::consts::PI;
    let (nphi, nz) = (4000, 4000);
    let (dphi, dz) = (2.0 * pi / nphi as f64, (top - pj::Z_SKULL_BASE) / nz as f64);
    let mut bumps = 0.0;
    for i in 0..nphi {
        let phi = -pi + (i as f64 + 0.5) * dphi;
        for k in 0..nz {
            let z = pj::Z_SKULL_BASE + (k as f64 + 0.5) * dz;
            bumps += 0.5 * (pj::cranium_outer(phi, z).powi(2) - 67f64.powi(2)) * dphi * dz;
        }
    }
    let closed = pi * (67f64.powi(2) - 60f64.powi(2)) * (top - pj::Z_SKULL_BASE)
        + pi * 60f64.powi(2) * (pj::Z_BRAIN - pj::Z_SKULL_BASE)
        + bumps;
    println!(
        "cranium: quadrature {cranium:.0} mm³, closed form {closed:.0} mm³ (bumps {bumps:.0})"
    );
    assert!(
        (cranium / closed - 1.0).abs() < 2e-3,
        "{cranium} vs {closed}"
    );
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

#[test]
fn the_nasal_passages_segment_as_a_cavity_inside_the_head() {
    // `Shape::nasal_passages` (the validation's phantoms): the nose's passages are air
    // the segmentation keeps out of the head, not connected to the air outside, with the
    // septum and walls tissue; the solid nose of the standard head has no cavity there.
    let hollow = pj::Shape {
        nasal_passages: true,
        ..Default::default()
    };
    let opts = PhantomOptions {
        spacing: [1.0; 3],
        ..Default::default()
    };
    let (lo, hi) = ([-24.0, -108.0, -4.0], [24.0, -60.0, 44.0]);
    let seg_of =
        |vol: &Volume| segment::segment(vol, &Case::default().tissue, Path::new("nose")).unwrap();
    let vol = hollow.ct_box(&opts, lo, hi);
    let seg = seg_of(&vol);
    let solid = seg_of(&pj::ct_box(&opts, lo, hi));
    let (mut passage, mut walls) = (0usize, 0usize);
    for a in 0..vol.len() {
        let c = centre(&vol, a);
        // Voxels wholly inside a passage (4 points per axis over the cube, as `pure_tissue`).
        let wholly_passage = (0..64).all(|n| {
            let o = [n % 4, (n / 4) % 4, n / 16];
            let p = [0, 1, 2].map(|d| c[d] + (o[d] as f64 / 3.0 - 0.5) * vol.spacing[d]);
            hollow.tissue_at(p) == Tissue::Air && pj::tissue_at(p) != Tissue::Air
        });
        if !wholly_passage {
            continue;
        }
        passage += 1;
        assert_eq!(seg.labels[a], AIR, "{c:?}");
        assert!(!seg.head[a], "{c:?}: the passage reaches the outside air");
        assert!(solid.labels[a] != AIR, "{c:?} is air in the solid nose");
        // Beside it, across the septum, tissue.
        let mirror = [0.0, c[1], c[2]];
        let i = ((mirror[0] - vol.origin[0]) / vol.spacing[0]).round() as usize;
        let b = a - (a % vol.dims[0]) + i;
        if seg.labels[b] != AIR {
            walls += 1;
        }
    }
    println!(
        "passage voxels {passage}, septum behind {walls}, cavity voxels {} (solid {})",
        seg.report.cavity_voxels, solid.report.cavity_voxels
    );
    assert!(passage > 2000, "{passage}");
    assert_eq!(walls, passage);
    assert!(seg.report.cavity_voxels >= solid.report.cavity_voxels + passage);
}

fn lm(name: &str) -> [f64; 3] {
    pj::landmark(name).unwrap_or_else(|| panic!("no landmark {name}"))
}

/// The midline skin at height z, found from `tissue_at` alone: bisection along −y for the
/// last non-air point (ρ of the skin).
fn skin_rho(z: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 120.0);
    for _ in 0..60 {
        let m = 0.5 * (lo + hi);
        if pj::tissue_at([0.0, -m, z]) == Tissue::Air {
            hi = m;
        } else {
            lo = m;
        }
    }
    0.5 * (lo + hi)
}

/// The first point along `dir` from `p` where `tissue_at` stops being `from` (0.01 mm steps).
fn exit(p: [f64; 3], dir: [f64; 3], from: impl Fn(Tissue) -> bool) -> f64 {
    let mut d = 0.0;
    while d < 100.0 && from(pj::tissue_at([0, 1, 2].map(|a| p[a] + d * dir[a]))) {
        d += 0.01;
    }
    d
}

/// z of the extreme of ρ over [a, b] on a 0.01 mm grid.
fn scan(a: f64, b: f64, max: bool) -> f64 {
    let n = ((b - a) / 0.01) as usize;
    let zs = (0..=n).map(|i| a + i as f64 * 0.01);
    let key = |z: &f64| if max { skin_rho(*z) } else { -skin_rho(*z) };
    zs.max_by(|x, y| key(x).total_cmp(&key(y))).unwrap()
}

#[test]
fn soft_tissue_landmarks_lie_where_their_definitions_say() {
    // Pronasale: the most anterior skin point of the whole midline profile.
    let prn = lm("pronasale");
    assert!((scan(-95.0, 40.0, true) - prn[2]).abs() < 0.05, "{prn:?}");
    assert!((skin_rho(prn[2]) + prn[1]).abs() < 0.01);
    // Labrale superius / inferius: the most anterior points of the lips; stomion the deepest
    // point between them, subnasale the deepest between the upper lip and the nose.
    let (ls, li, sto, sn) = (
        lm("labrale superius"),
        lm("labrale inferius"),
        lm("stomion"),
        lm("subnasale"),
    );
    assert!((scan(sto[2], sn[2], true) - ls[2]).abs() < 0.05);
    assert!((scan(li[2], ls[2], false) - sto[2]).abs() < 0.05);
    assert!((scan(li[2] - 8.0, sto[2], true) - li[2]).abs() < 0.05);
    assert!((scan(ls[2], prn[2], false) - sn[2]).abs() < 0.05);
    for p in [prn, ls, li, sto, sn] {
        assert!(
            (skin_rho(p[2]) + p[1]).abs() < 0.01,
            "{p:?} not on the skin"
        );
    }
    // Proportions (module docs): nose projection from subnasale ≈ 20 mm; nasolabial angle
    // ≈ 100° between the columella tangent from subnasale and the subnasale–labrale superius
    // line; lip thickness from the vestibule to the skin.
    let projection = sn[1] - prn[1];
    // The upper lip line's angle from straight down (towards anterior), and the columella's
    // lowest elevation above anterior seen from subnasale.
    let lip = (sn[1] - ls[1]).atan2(sn[2] - ls[2]);
    let columella = (1..1000)
        .map(|i| sn[2] + (prn[2] - sn[2]) * i as f64 / 1000.0)
        .map(|z| (z - sn[2]).atan2(skin_rho(z) + sn[1]))
        .fold(f64::INFINITY, f64::min);
    let nasolabial = (90f64.to_radians() + columella - lip).to_degrees();
    println!("nose projection {projection:.1} mm, nasolabial angle {nasolabial:.1}°");
    assert!((18.0..=22.0).contains(&projection), "{projection}");
    assert!((92.0..=108.0).contains(&nasolabial), "{nasolabial}");
    // Lip thickness: from the vestibule's front to the skin, along −y.
    for (name, p, range) in [("upper", ls, 12.0..=15.0), ("lower", li, 13.0..=15.0)] {
        let mut d = 0.0;
        while !pj::in_vestibule([0.0, p[1] + d, p[2]]) {
            d += 0.01;
            assert!(d < 30.0, "no vestibule behind the {name} lip");
        }
        println!("{name} lip thickness {d:.2} mm");
        assert!(range.contains(&d), "{name} lip {d}");
    }
    // Stomion: the lips touch (no air between the skin and the vestibule at its height).
    let start = [0.0, sto[1] + 0.05, sto[2]];
    let to_vestibule = exit(start, [0.0, 1.0, 0.0], |t| t != Tissue::Air);
    assert!(pj::in_vestibule([
        0.0,
        start[1] + to_vestibule + 0.01,
        sto[2]
    ]));
    // Soft tissue over the chin: horizontally at pogonion, vertically below menton.
    let pog = lm("pogonion");
    let chin = exit(pog, [0.0, -1.0, 0.0], |t| t != Tissue::Air);
    let me = lm("menton");
    let me_soft = lm("soft tissue menton");
    println!(
        "soft tissue chin {chin:.2} mm at pogonion, {:.2} mm below menton",
        me[2] - me_soft[2]
    );
    assert!((10.0..=12.0).contains(&chin), "{chin}");
    assert_eq!(
        pj::tissue_at([0.0, me_soft[1], me_soft[2] + 0.05]),
        Tissue::Skin
    );
    assert_eq!(
        pj::tissue_at([0.0, me_soft[1], me_soft[2] - 0.05]),
        Tissue::Air
    );
    // Soft pogonion: the most anterior skin point of the chin.
    let spg = lm("soft tissue pogonion");
    assert!((scan(me_soft[2], li[2] - 6.0, true) - spg[2]).abs() < 0.05);
}

fn bone(p: [f64; 3]) -> bool {
    matches!(pj::tissue_at(p), Tissue::Bone | Tissue::Tooth)
}

/// The most anterior bone point on the midline at height z (ρ of the labial bone face): the
/// first bone met coming from the front in 0.05 mm steps, refined by bisection.
fn bone_front(z: f64) -> f64 {
    let Some(r) = (0..800)
        .map(|i| 90.0 - i as f64 * 0.05)
        .find(|&r| bone([0.0, -r, z]))
    else {
        return f64::NAN;
    };
    let (mut lo, mut hi) = (r, r + 0.05);
    for _ in 0..40 {
        let m = 0.5 * (lo + hi);
        if bone([0.0, -m, z]) {
            lo = m;
        } else {
            hi = m;
        }
    }
    lo
}

#[test]
fn bone_landmarks_and_proportions() {
    // Pogonion: the most anterior point of the symphysis; B point the deepest of its labial
    // face between pogonion and the alveolar crest; A point likewise on the maxilla.
    let zs = |a: f64, b: f64| (0..=((b - a) / 0.05) as usize).map(move |i| a + i as f64 * 0.05);
    let extreme = |a: f64, b: f64, max: bool| {
        zs(a, b)
            .max_by(|x, y| {
                let (fx, fy) = (bone_front(*x), bone_front(*y));
                if max {
                    fx.total_cmp(&fy)
                } else {
                    fy.total_cmp(&fx)
                }
            })
            .unwrap()
    };
    let (pog, b, a) = (lm("pogonion"), lm("B point"), lm("A point"));
    assert!((extreme(-62.0, -45.0, true) - pog[2]).abs() < 0.1);
    assert!((bone_front(pog[2]) + pog[1]).abs() < 0.02);
    assert!((extreme(pog[2], pj::Z_LOWER_CEJ - 0.5, false) - b[2]).abs() < 0.1);
    assert!((bone_front(b[2]) + b[1]).abs() < 0.02);
    assert!((extreme(pj::Z_UPPER_CEJ + 0.5, pj::Z_MAXILLA_TOP - 0.5, false) - a[2]).abs() < 0.1);
    assert!((bone_front(a[2]) + a[1]).abs() < 0.02);
    // Menton: the lowest bone point of the mandible.
    let me = lm("menton");
    let lowest = (0..1000)
        .map(|i| me[2] - 2.0 + i as f64 * 0.004)
        .find(|&z| (0..2000).any(|j| bone([0.0, -80.0 + j as f64 * 0.02, z])))
        .unwrap();
    assert!((lowest - me[2]).abs() < 0.01, "{lowest} vs {}", me[2]);
    assert!(bone([me[0], me[1], me[2] + 0.01]));
    // Symphysis height: alveolar crest (the top of the midline bone under the incisors) to
    // menton.
    let crest = (0..2000)
        .map(|i| pj::Z_LOWER_EDGE + 2.0 - i as f64 * 0.01)
        .find(|&z| pj::tissue_at([0.0, me[1], z]) == Tissue::Bone)
        .unwrap();
    let height = crest - me[2];
    println!("symphysis height {height:.2} mm");
    assert!((29.0..=31.0).contains(&height), "{height}");
    // Incisor tips and canine cusps: tooth just above (upper) or below (lower), none beyond.
    for (name, up) in [
        ("upper incisor tip", true),
        ("lower incisor tip", false),
        ("upper canine right", true),
        ("upper canine left", true),
    ] {
        let p = lm(name);
        let s = if up { 1.0 } else { -1.0 };
        assert_eq!(
            pj::tissue_at([p[0], p[1], p[2] + 0.05 * s]),
            Tissue::Tooth,
            "{name}"
        );
        assert_ne!(
            pj::tissue_at([p[0], p[1], p[2] - 0.05 * s]),
            Tissue::Tooth,
            "{name}"
        );
    }
    let width = lm("upper canine left")[0] - lm("upper canine right")[0];
    println!("intercanine width {width:.1} mm");
    // Adult maxillary intercanine widths (cusp tips): 34 ± 2 mm.
    assert!((31.0..=37.0).contains(&width), "{width}");
    // The condyles: bone at their centres, and the joint space above them is not bone for
    // 3.5 mm (the cranium's skull base starts there).
    for name in ["condyle left", "condyle right"] {
        let c = lm(name);
        assert_eq!(pj::piece_at(c), Some(Piece::Mandible));
        let top = c[2] + 4.0;
        assert_eq!(
            pj::piece_at([c[0], c[1], top - 0.01]),
            Some(Piece::Mandible)
        );
        assert_eq!(pj::piece_at([c[0], c[1], top + 3.49]), None);
        assert_eq!(pj::piece_at([c[0], c[1], top + 3.51]), Some(Piece::Cranium));
    }
}

/// Bone sample points on a 1 mm grid over the jaws, with their piece.
fn bone_samples() -> Vec<([f64; 3], Piece)> {
    let mut v = Vec::new();
    for k in 0..80 {
        for j in 0..110 {
            for i in 0..130 {
                let p = [-65.0 + i as f64, -85.0 + j as f64, -70.0 + k as f64];
                if let Some(piece) = pj::piece_at(p) {
                    v.push((p, piece));
                }
            }
        }
    }
    v
}

fn in_box(b: [[f64; 3]; 2], p: [f64; 3]) -> bool {
    (0..3).all(|a| p[a] >= b[0][a] && p[a] <= b[1][a])
}

#[test]
fn osteotomy_boxes_select_exactly_their_segment_and_the_plans_move_it_rigidly() {
    let samples = bone_samples();
    let mandible = |p| in_box(pj::MANDIBLE_FRONT_BOX, p) || in_box(pj::MANDIBLE_BACK_BOX, p);
    let maxilla = |p| in_box(pj::MAXILLA_BOX, p);
    // Every bone point within 1.4 mm of a piece (where the skull surface's vertices may lie)
    // is in that piece's boxes only.
    let offsets = [
        [0.0; 3],
        [1.4, 0.0, 0.0],
        [-1.4, 0.0, 0.0],
        [0.0, 1.4, 0.0],
        [0.0, -1.4, 0.0],
        [0.0, 0.0, 1.4],
        [0.0, 0.0, -1.4],
    ];
    let mut counts = [0usize; 3];
    for (p, piece) in &samples {
        counts[piece_index(*piece)] += 1;
        for o in offsets {
            let q = [p[0] + o[0], p[1] + o[1], p[2] + o[2]];
            let (m, x) = (mandible(q), maxilla(q));
            match piece {
                Piece::Mandible => assert!(m && !x, "{q:?}"),
                Piece::Maxilla => assert!(x && !m, "{q:?}"),
                Piece::Cranium => assert!(!m && !x || q[2] < pj::Z_SKULL_BASE, "{q:?}"),
            }
        }
        if *piece == Piece::Cranium {
            assert!(!mandible(*p) && !maxilla(*p));
        }
    }
    println!("bone samples (cranium, maxilla, mandible): {counts:?}");
    // Each plan moves every point of its segment by one rigid motion and nothing else.
    let rot = |p: [f64; 3]| {
        let (s, c) = (-5f64).to_radians().sin_cos();
        let c0 = pj::CONDYLAR_PIVOT;
        let d = [p[0] - c0[0], p[1] - c0[1], p[2] - c0[2]];
        [
            p[0],
            c0[1] + c * d[1] - s * d[2],
            c0[2] + s * d[1] + c * d[2],
        ]
    };
    type Motion = Box<dyn Fn([f64; 3]) -> [f64; 3]>;
    let shift = |d: [f64; 3]| -> Motion {
        Box::new(move |p: [f64; 3]| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
    };
    let plans: Vec<(&str, Piece, Motion)> = vec![
        ("case.toml", Piece::Mandible, shift([0.0, -5.0, 0.0])),
        ("case_setback.toml", Piece::Mandible, shift([0.0, 4.0, 0.0])),
        ("case_rotation.toml", Piece::Mandible, Box::new(rot)),
        ("case_maxilla.toml", Piece::Maxilla, shift([0.0, -4.0, 0.0])),
    ];
    let files = pj::case_files(None);
    let points: Vec<[f64; 3]> = samples.iter().map(|s| s.0).collect();
    for (file, piece, motion) in plans {
        let text = &files.iter().find(|f| f.0 == file).unwrap().1;
        assert!(!text.contains("[solve]"));
        let case = Case::parse(text, Path::new(file)).unwrap();
        let (moved, _) = Plan::new(&case.osteotomy).apply(&points, 1.0);
        // The setback (a sagittal split) moves the tooth-bearing front of the mandible only.
        let [lo, hi] = pj::MANDIBLE_FRONT_BOX;
        let in_front = |p: &[f64; 3]| (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]);
        for ((p, pc), q) in samples.iter().zip(&moved) {
            let moves = *pc == piece && (file != "case_setback.toml" || in_front(p));
            let want = if moves { motion(*p) } else { *p };
            let err = (0..3).map(|a| (q[a] - want[a]).abs()).fold(0.0, f64::max);
            assert!(
                err < 1e-9,
                "{file}: {pc:?} point {p:?} went to {q:?}, not {want:?}"
            );
        }
    }
    // The rotation is counter-clockwise seen from the patient's right: the chin goes up and
    // forwards.
    let pog = lm("pogonion");
    let r = rot(pog);
    println!(
        "pogonion moves by {:?} in the rotation",
        [r[1] - pog[1], r[2] - pog[2]]
    );
    assert!(r[1] < pog[1] - 3.0 && r[2] > pog[2] + 2.0);
    // The model line is written only when asked for.
    let tet = pj::case_files(Some("tet"));
    assert!(
        tet.iter()
            .all(|(_, t)| t.contains("[solve]\nmodel = \"tet\""))
    );
}

/// The bundled sample in `data-samples/NAME` (2 mm voxels, 3 mm scan) is what `ct` and `scan`
/// make now.
fn regenerates(
    name: &str,
    ct: impl Fn(&PhantomOptions) -> facesim::volume::Volume,
    scan: impl Fn(f64) -> facesim::mesh::Mesh,
) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data-samples")
        .join(name);
    let bundled = facesim::volume::read_volume(&dir.join("ct.nii.gz")).unwrap();
    let opts = PhantomOptions {
        spacing: [2.0; 3],
        ..Default::default()
    };
    let now = ct(&opts);
    assert_eq!(bundled.dims, now.dims, "{name}");
    assert_eq!(bundled.origin, now.origin, "{name}");
    assert!(bundled.data == now.data, "{name}: CT voxels changed");
    let bundled = facesim::mesh::read_mesh(&dir.join("face.ply")).unwrap();
    let again = scan(3.0);
    assert_eq!(bundled.triangles, again.triangles, "{name}");
    assert_eq!(bundled.vertices.len(), again.vertices.len(), "{name}");
}

#[test]
fn the_first_sample_is_the_jaws_phantom() {
    // data-samples/jaws (README's first command): `facesim phantom DIR --anatomy jaws --spacing 2
    // --slice 2`, regenerated; its case.toml is its own (a BSSO advancement).
    regenerates("jaws", pj::ct, pj::face_scan);
}

#[test]
fn the_capsule_phantom_is_unchanged() {
    // The previous bundled sample (data-samples/phantom) regenerated.
    regenerates(
        "phantom",
        facesim_validate::phantom::ct,
        facesim_validate::phantom::face_scan,
    );
}

#[test]
fn the_first_samples_face_has_all_fourteen_soft_landmarks_its_corners_where_built() {
    // The bundled face scan, read as any 3D photo (frame from its shape). The
    // mouth's corners where the lips and crease end (26 mm either side of stomion by
    // construction, docs/design/phantom.md) and the alae where the wings meet the cheek (17 mm).
    use facesim::landmarks::scan::{FrameFrom, landmarks_of};
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let face = facesim::mesh::read_mesh(&dir.join("face.ply")).unwrap();
    let f = landmarks_of(&face, FrameFrom::Shape).unwrap();
    let missing: Vec<_> = f
        .landmarks
        .iter()
        .filter(|l| l.position.is_none())
        .map(|l| format!("{}: {:?}", l.label, l.missing))
        .collect();
    assert!(missing.is_empty(), "{missing:?}");
    assert_eq!(f.landmarks.len(), 14, "{:?}", f.landmarks);
    let at = |l: &str| {
        f.landmarks
            .iter()
            .find(|x| x.label == l)
            .and_then(|x| x.position)
            .unwrap()
    };
    let sto = lm("stomion");
    for (label, side) in [("Ch-R", -1.0), ("Ch-L", 1.0), ("Al-R", -1.0), ("Al-L", 1.0)] {
        let p = at(label);
        let half = if label.starts_with("Ch") { 26.0 } else { 17.3 };
        assert!(
            (side * p[0] - half).abs() < 1.5,
            "{label} at x = {:.1}, built at ±{half}",
            p[0]
        );
        if label.starts_with("Ch") {
            assert!((p[2] - sto[2]).abs() < 2.0, "{label} {p:?} vs Sto {sto:?}");
        }
    }
}
