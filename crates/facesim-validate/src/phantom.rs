//! The synthetic head: analytic geometry, our ground truth (docs/design/phantom.md).
//!
//! A vertical capsule (axis segment from z = −Z_HALF to +Z_HALF on the LPS z axis) carries
//! concentric layers at exact radial distances ρ from the axis segment:
//!
//! | ρ (mm)        | tissue                     | HU    |
//! |---------------|----------------------------|-------|
//! | < 60          | brain (soft)               | 35    |
//! | 60 – 67       | bone (skull), 7 mm         | 600   |
//! | 67 – 73       | muscle (soft), 6 mm        | 45    |
//! | 73 – 78 + b   | fat 5 mm (+ nose soft)     | −100  |
//! | 78+b – 80+b   | skin, 2 mm                 | 45    |
//! | > 80 + b      | air                        | −1000 |
//!
//! b(φ, z) ≥ 0 is the nose: a smooth bump of soft tissue (HU 45) between the fat and the skin,
//! on the face (−y side). Bone cuts: 3 mm soft-tissue gaps at z = −25 (occlusal plane) and z = 5
//! (Le Fort I level) on the anterior half, and at y = 0 below z = 6, so that the mandible
//! (z < −25, y < 0) and the maxilla (−25 < z < 5, y < 0) are separate bone pieces.

use facesim::error::Result;
use facesim::mesh::Mesh;
use facesim::volume::Volume;
use rayon::prelude::*;
use std::f64::consts::PI;

pub const Z_HALF: f64 = 40.0;
pub(crate) const R_BRAIN: f64 = 60.0;
pub const R_BONE: f64 = 67.0;
pub(crate) const R_MUSCLE: f64 = 73.0;
pub(crate) const R_FAT: f64 = 78.0;
pub const R_SKIN: f64 = 80.0;
pub(crate) const HU_AIR: f64 = -1000.0;
pub(crate) const HU_SOFT: f64 = 45.0;
pub(crate) const HU_BRAIN: f64 = 35.0;
pub(crate) const HU_FAT: f64 = -100.0;
pub(crate) const HU_BONE: f64 = 600.0;
/// Nose: height (mm), angular and vertical Gaussian widths, centre height.
pub(crate) const NOSE_H: f64 = 18.0;
pub(crate) const NOSE_SIG_PHI: f64 = 0.13; // rad (≈ 10 mm of arc at ρ = 80)
pub(crate) const NOSE_SIG_Z: f64 = 12.0;
pub(crate) const NOSE_Z: f64 = 0.0;
/// Half-thickness of the bone cuts.
pub(crate) const GAP_HALF: f64 = 1.5;
pub(crate) const OCCLUSAL_Z: f64 = -25.0;
pub(crate) const LEFORT_Z: f64 = 5.0;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tissue {
    Air,
    Skin,
    Fat,
    Soft,
    Bone,
}

/// φ measured from the anterior direction (−y) towards the patient's left (+x).
pub fn phi_of(p: [f64; 3]) -> f64 {
    p[0].atan2(-p[1])
}

/// The nose bump b(φ, z) (mm), smooth and compactly negligible outside the face centre.
pub fn nose(phi: f64, z: f64) -> f64 {
    let zc = z.clamp(-Z_HALF, Z_HALF);
    let g = (-(phi * phi) / (2.0 * NOSE_SIG_PHI * NOSE_SIG_PHI)
        - (zc - NOSE_Z).powi(2) / (2.0 * NOSE_SIG_Z * NOSE_SIG_Z))
        .exp();
    NOSE_H * g
}

/// Distance from the axis segment, and the nose bump at p (zero on the caps).
fn rho_b(p: [f64; 3]) -> (f64, f64) {
    let zc = p[2].clamp(-Z_HALF, Z_HALF);
    let rho = (p[0] * p[0] + p[1] * p[1] + (p[2] - zc).powi(2)).sqrt();
    let b = if p[2].abs() <= Z_HALF {
        nose(phi_of(p), p[2])
    } else {
        0.0
    };
    (rho, b)
}

fn in_gap(p: [f64; 3]) -> bool {
    let [_, y, z] = p;
    (y < 0.0 && ((z - OCCLUSAL_Z).abs() < GAP_HALF || (z - LEFORT_Z).abs() < GAP_HALF))
        || (y.abs() < GAP_HALF && z < LEFORT_Z + GAP_HALF)
}

/// Exact tissue at p (LPS mm).
pub fn tissue_at(p: [f64; 3]) -> Tissue {
    let (rho, b) = rho_b(p);
    if rho >= R_SKIN + b {
        Tissue::Air
    } else if rho >= R_FAT + b {
        Tissue::Skin
    } else if rho >= R_FAT {
        Tissue::Soft // nose
    } else if rho >= R_MUSCLE {
        Tissue::Fat
    } else if rho >= R_BONE {
        Tissue::Soft
    } else if rho >= R_BRAIN {
        if in_gap(p) {
            Tissue::Soft
        } else {
            Tissue::Bone
        }
    } else {
        Tissue::Soft
    }
}

pub(crate) fn hu_at(p: [f64; 3]) -> f64 {
    match tissue_at(p) {
        Tissue::Air => HU_AIR,
        Tissue::Skin | Tissue::Soft => {
            if rho_b(p).0 < R_BRAIN {
                HU_BRAIN
            } else {
                HU_SOFT
            }
        }
        Tissue::Fat => HU_FAT,
        Tissue::Bone => HU_BONE,
    }
}

/// Exact skin surface point along the ray from the axis at angle φ and height z.
pub fn skin_point(phi: f64, z: f64) -> [f64; 3] {
    let r = R_SKIN + nose(phi, z);
    [r * phi.sin(), -r * phi.cos(), z]
}

/// Distance from p to the analytic skin surface, measured along the radial direction from the
/// axis (exact for the cylinder and caps; on the nose slopes it over-estimates the normal
/// distance by at most 1/cos of the slope).
pub fn radial_skin_distance(p: [f64; 3]) -> f64 {
    let (rho, b) = rho_b(p);
    (rho - (R_SKIN + b)).abs()
}

/// Volumes (mm³) of each tissue class: closed forms for the layered capsule, plus the nose and
/// the bone cuts integrated from their analytic definitions (2-D quadrature for the nose,
/// 3-D midpoint quadrature at 0.1 mm over the thin cut slabs).
#[derive(Clone, Debug, Default)]
pub struct TissueVolumes {
    pub skin: f64,
    pub fat: f64,
    pub soft: f64,
    pub bone: f64,
}

fn capsule_volume(r: f64) -> f64 {
    PI * r * r * 2.0 * Z_HALF + 4.0 / 3.0 * PI * r.powi(3)
}

pub fn analytic_volumes() -> TissueVolumes {
    let shell = |a: f64, b: f64| capsule_volume(b) - capsule_volume(a);
    let mut v = TissueVolumes {
        skin: shell(R_FAT, R_SKIN),
        fat: shell(R_MUSCLE, R_FAT),
        soft: capsule_volume(R_BRAIN) + shell(R_BONE, R_MUSCLE),
        bone: shell(R_BRAIN, R_BONE),
    };
    // Nose: in cylindrical coordinates the layer [r1 + b, r2 + b] has area element r dr dφ dz,
    // so skin gains ∫∫ ((R_SKIN+b)² − (R_FAT+b)² − R_SKIN² + R_FAT²)/2 dφ dz = ∫∫ 2b·... and the
    // soft nose fills [R_FAT, R_FAT + b].
    let (nphi, nz) = (4000, 4000);
    let (dphi, dz) = (2.0 * PI / nphi as f64, 2.0 * Z_HALF / nz as f64);
    let (mut dskin, mut dsoft) = (0.0, 0.0);
    for i in 0..nphi {
        let phi = -PI + (i as f64 + 0.5) * dphi;
        for j in 0..nz {
            let z = -Z_HALF + (j as f64 + 0.5) * dz;
            let b = nose(phi, z);
            dskin +=
                ((R_SKIN + b).powi(2) - (R_FAT + b).powi(2) - R_SKIN.powi(2) + R_FAT.powi(2)) / 2.0;
            dsoft += ((R_FAT + b).powi(2) - R_FAT.powi(2)) / 2.0;
        }
    }
    v.skin += dskin * dphi * dz;
    v.soft += dsoft * dphi * dz;
    // Bone cuts: bone → soft inside the slabs.
    let h = 0.1;
    let slabs = [
        (
            [-R_BONE, -R_BONE, OCCLUSAL_Z - GAP_HALF],
            [R_BONE, 0.0, OCCLUSAL_Z + GAP_HALF],
        ),
        (
            [-R_BONE, -R_BONE, LEFORT_Z - GAP_HALF],
            [R_BONE, 0.0, LEFORT_Z + GAP_HALF],
        ),
        (
            [-R_BONE, -GAP_HALF, -Z_HALF - R_BONE],
            [R_BONE, GAP_HALF, LEFORT_Z + GAP_HALF],
        ),
    ];
    let mut seen: Vec<([f64; 3], [f64; 3])> = Vec::new();
    let mut cut = 0.0;
    for (lo, hi) in slabs {
        let n = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / h).round() as usize);
        let prior = seen.clone();
        cut += (0..n[2])
            .into_par_iter()
            .map(|k| {
                let mut c = 0usize;
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let p = [
                            lo[0] + (i as f64 + 0.5) * h,
                            lo[1] + (j as f64 + 0.5) * h,
                            lo[2] + (k as f64 + 0.5) * h,
                        ];
                        // Count each point once across overlapping slab boxes.
                        let dup = prior
                            .iter()
                            .any(|(a, b)| (0..3).all(|x| p[x] > a[x] && p[x] < b[x]));
                        let rho = rho_b(p).0;
                        if !dup && (R_BRAIN..R_BONE).contains(&rho) && in_gap(p) {
                            c += 1;
                        }
                    }
                }
                c as f64 * h * h * h
            })
            .sum::<f64>();
        seen.push((lo, hi));
    }
    v.bone -= cut;
    v.soft += cut;
    v
}

#[derive(Clone, Debug)]
pub struct PhantomOptions {
    /// Voxel size (mm) in x, y (in-plane) and z (slice).
    pub spacing: [f64; 3],
    /// Sub-samples per axis for partial-volume averaging.
    pub supersample: usize,
    /// Standard deviation of the deterministic noise (HU).
    pub noise_hu: f64,
    /// Vertex spacing of the face scan (mm); 3 mm gives ~5 k vertices.
    pub scan_step_mm: f64,
}

impl Default for PhantomOptions {
    fn default() -> Self {
        PhantomOptions {
            spacing: [1.5, 1.5, 1.5],
            supersample: 3,
            noise_hu: 8.0,
            scan_step_mm: 3.0,
        }
    }
}

/// Deterministic pseudo-random normal deviate per voxel (splitmix64 + Box–Muller), so the
/// phantom is byte-identical on every machine and thread count.
pub(crate) fn noise(idx: u64) -> f64 {
    let mix = |mut z: u64| {
        z = z.wrapping_add(0x9E3779B97F4A7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    };
    let u1 = ((mix(idx * 2) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = ((mix(idx * 2 + 1) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
}

/// The phantom CT: identity LPS orientation, covering the head and nose with a margin.
pub fn ct(opts: &PhantomOptions) -> Volume {
    let lo = [-92.0, -112.0, -Z_HALF - R_SKIN - 8.0];
    let hi = [92.0, 92.0, Z_HALF + R_SKIN + 8.0];
    sample_ct(lo, hi, opts, hu_at)
}

/// A CT of the box [lo, hi] (voxel centres from `lo`, identity LPS orientation) of an analytic
/// HU field: each voxel is the mean of `supersample`³ sub-samples (partial volume) plus the
/// deterministic noise of its index. Shared by the capsule head and `phantom_jaws`.
pub(crate) fn sample_ct(
    lo: [f64; 3],
    hi: [f64; 3],
    opts: &PhantomOptions,
    hu: impl Fn([f64; 3]) -> f64 + Sync,
) -> Volume {
    let dims = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / opts.spacing[a]).ceil() as usize + 1);
    let s = opts.supersample.max(1);
    let [nx, ny, nz] = dims;
    let mut data = vec![0f32; nx * ny * nz];
    data.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slab)| {
            for j in 0..ny {
                for i in 0..nx {
                    let c = [
                        lo[0] + i as f64 * opts.spacing[0],
                        lo[1] + j as f64 * opts.spacing[1],
                        lo[2] + k as f64 * opts.spacing[2],
                    ];
                    let mut acc = 0.0;
                    for a in 0..s {
                        for b in 0..s {
                            for d in 0..s {
                                let off = |t: usize, ax: usize| {
                                    ((t as f64 + 0.5) / s as f64 - 0.5) * opts.spacing[ax]
                                };
                                acc += hu([c[0] + off(a, 0), c[1] + off(b, 1), c[2] + off(d, 2)]);
                            }
                        }
                    }
                    let idx = i + nx * (j + ny * k);
                    let v = acc / (s * s * s) as f64 + opts.noise_hu * noise(idx as u64);
                    slab[i + nx * j] = v.round() as f32;
                }
            }
        });
    Volume {
        dims,
        spacing: opts.spacing,
        origin: lo,
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data,
    }
}

/// A face scan of the analytic skin: a (φ, z) grid over the face, as a structured-light
/// scanner would see it (front ±100°, from below the chin to the forehead).
pub fn face_scan(step_mm: f64) -> Mesh {
    let phi_max = 100f64.to_radians();
    let nphi = ((2.0 * phi_max * R_SKIN) / step_mm).round() as usize + 1;
    let (z0, z1) = (-Z_HALF - 50.0, Z_HALF + 30.0);
    let nz = ((z1 - z0) / step_mm).round() as usize + 1;
    let mut verts = Vec::with_capacity(nphi * nz);
    for j in 0..nz {
        let z = z0 + (z1 - z0) * j as f64 / (nz - 1) as f64;
        for i in 0..nphi {
            let phi = -phi_max + 2.0 * phi_max * i as f64 / (nphi - 1) as f64;
            if z.abs() <= Z_HALF {
                verts.push(skin_point(phi, z));
            } else {
                // On the caps: the sphere of radius R_SKIN about the segment end.
                let zc = z.clamp(-Z_HALF, Z_HALF);
                let dzc = z - zc;
                let r = (R_SKIN * R_SKIN - dzc * dzc).max(0.0).sqrt();
                verts.push([r * phi.sin(), -r * phi.cos(), z]);
            }
        }
    }
    grid_mesh(verts, nphi, nz)
}

/// Triangulate a (φ, z) grid of vertices (row-major, `nphi` per row, φ growing towards +x, z
/// up) with outward normals and diagonals mirrored about the mid-sagittal plane, dropping the
/// triangles that collapse (at the poles of a cap).
pub(crate) fn grid_mesh(verts: Vec<[f64; 3]>, nphi: usize, nz: usize) -> Mesh {
    let mut tris = Vec::new();
    for j in 0..nz - 1 {
        for i in 0..nphi - 1 {
            let a = (j * nphi + i) as u32;
            let b = a + 1;
            let c = a + nphi as u32;
            let d = c + 1;
            // Outward normals: φ grows towards +x (patient left), z up. The diagonals mirror
            // about the mid-sagittal plane, so the mesh is as symmetric as the head.
            if 2 * i + 1 < nphi - 1 {
                tris.push([a, c, b]);
                tris.push([b, c, d]);
            } else {
                tris.push([a, c, d]);
                tris.push([a, d, b]);
            }
        }
    }
    let mut m = Mesh::new(verts, tris);
    // Drop the triangles that collapse at the very top/bottom of the caps.
    let diag = m.diagonal();
    m.triangles.retain(|t| {
        let [a, b, c] = t.map(|i| m.vertices[i as usize]);
        facesim::vec3::norm(facesim::vec3::cross(
            facesim::vec3::sub(b, a),
            facesim::vec3::sub(c, a),
        )) > 1e-9 * diag * diag
    });
    m.compact();
    m
}

/// The plan written with the phantom: a 6 mm mandibular advancement.
pub fn case_toml(ct_name: &str, with_scan: bool) -> String {
    let skin = if with_scan {
        "\n[skin]\npath = \"face.ply\"\n"
    } else {
        ""
    };
    format!(
        r#"# facesim phantom case: a synthetic head whose geometry is known exactly (docs/design/phantom.md).
name = "phantom-mandible-advance-6mm"

[ct]
path = "{ct_name}"
{skin}
[surface]
alpha = 0.01
beta = 0.02
movable = {{ sphere = {{ center = [0.0, -60.0, -45.0], radius = 70.0 }} }}

[[osteotomy]]
name = "mandible"
region = {{ box = {{ min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] }} }}
translate = [0.0, -6.0, 0.0]
"#
    )
}

/// Write a complete phantom case into `dir`.
pub fn write_case(dir: &std::path::Path, opts: &PhantomOptions) -> Result<()> {
    use facesim::error::Error;
    facesim::output::create_dir_guarded(dir)?;
    let vol = ct(opts);
    facesim::volume::nifti_io::write(&vol, &dir.join("ct.nii.gz"))?;
    facesim::volume::dicom_io::write_series(&vol, &dir.join("ct_dicom"), "1")?;
    let step = opts.scan_step_mm;
    if !(step >= 0.1) {
        return Err(Error::config(format!(
            "phantom face scan step {step} mm must be at least 0.1 mm"
        )));
    }
    facesim::mesh::ply::write(
        &face_scan(step),
        &dir.join("face.ply"),
        facesim::mesh::ply::Encoding::BinaryLittleEndian,
    )?;
    let text = case_toml("ct.nii.gz", true);
    facesim::output::write_bytes_atomic(&dir.join("case.toml"), |w| w.write_all(text.as_bytes()))?;
    let text = case_toml("ct_dicom", false);
    facesim::output::write_bytes_atomic(&dir.join("case_dicom_extracted.toml"), |w| {
        w.write_all(text.as_bytes())
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layers_are_where_the_table_says() {
        // On the −y axis at z = 30 (above the nose centre but within it), outside the bump.
        let at = |r: f64| tissue_at([r, 0.0, 30.0]); // +x side: no nose
        assert_eq!(at(30.0), Tissue::Soft);
        assert_eq!(at(63.0), Tissue::Bone);
        assert_eq!(at(70.0), Tissue::Soft);
        assert_eq!(at(75.0), Tissue::Fat);
        assert_eq!(at(79.0), Tissue::Skin);
        assert_eq!(at(81.0), Tissue::Air);
        // Nose tip at φ = 0, z = 0 protrudes NOSE_H mm.
        assert_eq!(
            tissue_at([0.0, -(R_SKIN + NOSE_H) + 0.5, 0.0]),
            Tissue::Skin
        );
        assert_eq!(tissue_at([0.0, -(R_SKIN + NOSE_H) - 0.5, 0.0]), Tissue::Air);
        // Mandible and maxilla are separated by soft tissue.
        assert_eq!(tissue_at([0.0, -63.0, OCCLUSAL_Z]), Tissue::Soft);
        assert_eq!(tissue_at([0.0, -63.0, OCCLUSAL_Z - 3.0]), Tissue::Bone);
    }

    #[test]
    fn closed_form_volumes_match_brute_quadrature_without_features() {
        // Skin shell of the capsule by shells: 4/3π(80³−78³) + 2π·40·2·(80²−78²)/… spot check.
        let v = analytic_volumes();
        let shell = capsule_volume(R_SKIN) - capsule_volume(R_FAT);
        assert!(
            v.skin > shell && v.skin < shell * 1.05,
            "{} vs {}",
            v.skin,
            shell
        );
        let bone = capsule_volume(R_BONE) - capsule_volume(R_BRAIN);
        assert!(v.bone < bone && v.bone > bone * 0.95);
    }
}
