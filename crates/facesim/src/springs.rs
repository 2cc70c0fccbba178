//! Tissue springs from skin to skull (Koch 1996 §2.5–2.6, docs/design/pipeline.md §4).
//!
//! Main spring of skin vertex i: march from x_s along the inward normal −n_i (step half the
//! smallest voxel spacing) until bone; the attachment x_b is refined by bisection on the bone
//! field. Stiffness in series (eq. 1–2): 1/c = (1/l) Σ_h l_h / c_h over the tissue runs crossed,
//! c_h the relative stiffness of the label at each step (Koch Table 1). No bone within
//! `max_length_mm` → no spring, counted and located. Strut springs run from x_s^i to the
//! attachments of i's mesh neighbours, integrated the same way. k_i = Σ areas of the triangles
//! around i (eq. 21).

use crate::case::{Springs as SpringParams, Stiffness};
use crate::mesh::{Column, Edges, Mesh};
use crate::segment::{self, Segmentation};
use crate::union_find::UnionFind;
use crate::vec3::{add, norm, scale, sub};
use crate::volume::{Volume, VoxelMap, sample_field};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Kind {
    Main,
    Strut,
}

#[derive(Clone, Debug)]
pub struct Spring {
    /// Skin vertex.
    pub skin: usize,
    /// Index of the attachment in `SpringSet::attachments`.
    pub bone: usize,
    /// Series-integrated relative stiffness c (eq. 2).
    pub c: f64,
    /// Pre-operative length (mm).
    pub rest: f64,
    pub kind: Kind,
}

#[derive(Clone, Debug)]
pub struct SpringSet {
    /// Skull attachment point per skin vertex (None: no bone within reach).
    pub attachment_of: Vec<Option<usize>>,
    pub attachments: Vec<[f64; 3]>,
    pub springs: Vec<Spring>,
    /// k_i per skin vertex (eq. 21), mm².
    pub k: Vec<f64>,
    pub misses: Vec<usize>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MissRegion {
    pub vertices: usize,
    pub centroid: [f64; 3],
    pub bounds: ([f64; 3], [f64; 3]),
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SpringReport {
    pub main: usize,
    pub struts: usize,
    pub misses: usize,
    /// Centroid and bounding box (LPS mm) of the skin vertices whose ray found no bone.
    pub miss_centroid: Option<[f64; 3]>,
    pub miss_bounds: Option<([f64; 3], [f64; 3])>,
    /// The misses as connected patches of the skin mesh (at most 8): where the rays found no
    /// bone (a bone defect, the nose tip, ears, the field of view's edge). Ordered by size
    /// (largest first), then by centroid z (lowest first), then by smallest vertex index, so
    /// that tied patches (a symmetric head's two ears) keep one order from run to run.
    pub miss_regions: Vec<MissRegion>,
    pub length_mm: [f64; 3],
    pub stiffness: [f64; 3],
}

/// Relative stiffness of a label (bone is the end of a spring; air inside the head, e.g. a
/// sinus on the way, gets the softest tissue's value).
pub fn tissue_c(label: u8, s: &Stiffness) -> f64 {
    match label {
        segment::SKIN => s.skin,
        segment::MUSCLE => s.muscle,
        segment::FAT_DARK => s.fat_dark,
        segment::FAT_BRIGHT => s.fat_bright,
        _ => s.fat_dark.min(s.fat_bright),
    }
}

fn label_at(map: &VoxelMap, vol: &Volume, labels: &[u8], p: [f64; 3]) -> u8 {
    let c = map.to_voxel(p);
    let mut i = [0usize; 3];
    for a in 0..3 {
        let r = c[a].round();
        if !(r >= 0.0 && r < vol.dims[a] as f64) {
            return segment::AIR;
        }
        i[a] = r as usize;
    }
    labels[vol.idx(i[0], i[1], i[2])]
}

/// Σ l_h / c_h along the segment a → b, sampled every `step`.
fn compliance(
    vol: &Volume,
    labels: &[u8],
    a: [f64; 3],
    b: [f64; 3],
    step: f64,
    st: &Stiffness,
) -> f64 {
    let map = vol.voxel_map();
    let l = norm(sub(b, a));
    let n = (l / step).ceil().max(1.0) as usize;
    let h = l / n as f64;
    (0..n)
        .map(|k| {
            let p = add(a, scale(sub(b, a), (k as f64 + 0.5) / n as f64));
            let lab = label_at(&map, vol, labels, p);
            if lab == segment::BONE {
                0.0
            } else {
                h / tissue_c(lab, st)
            }
        })
        .sum()
}

/// +1 when the mesh's (counter-clockwise) vertex normals point out of the head, −1 when they
/// point into tissue (probed in the label volume two voxels either side).
pub(crate) fn outward_sign(mesh: &Mesh, vol: &Volume, labels: &[u8]) -> f64 {
    sign_of_normals(mesh, &mesh.vertex_normals(), vol, labels)
}

/// `outward_sign` for normals `n` already computed.
fn sign_of_normals(mesh: &Mesh, n: &[[f64; 3]], vol: &Volume, labels: &[u8]) -> f64 {
    let probe = 2.0 * vol.spacing.iter().cloned().fold(0.0, f64::max);
    let map = vol.voxel_map();
    let air = |d: f64| {
        mesh.vertices
            .iter()
            .zip(n)
            .filter(|(p, v)| {
                label_at(&map, vol, labels, add(**p, scale(**v, d * probe))) == segment::AIR
            })
            .count()
    };
    if air(-1.0) > air(1.0) { -1.0 } else { 1.0 }
}

/// Outward normals: flip the mesh's normals if most of them point into tissue.
fn outward_normals(mesh: &Mesh, vol: &Volume, labels: &[u8]) -> Vec<[f64; 3]> {
    let n = mesh.vertex_normals();
    let s = sign_of_normals(mesh, &n, vol, labels);
    n.iter().map(|v| scale(*v, s)).collect()
}

pub fn trace(
    mesh: &Mesh,
    vol: &Volume,
    seg: &Segmentation,
    bone_field: &[f32],
    params: &SpringParams,
    stiffness: &Stiffness,
    want: Option<&[bool]>,
) -> SpringSet {
    let labels = &seg.labels;
    let nb = mesh.neighbours();
    let traced = traced_vertices(&nb, want, mesh.vertices.len());
    let iso = seg.windows.bone as f32;
    let step = 0.5 * vol.spacing.iter().cloned().fold(f64::INFINITY, f64::min);
    let normals = outward_normals(mesh, vol, labels);
    let map = vol.voxel_map();
    let bone_at =
        |p: [f64; 3]| sample_field(bone_field, vol.dims, map.to_voxel(p), f32::MIN) >= iso;
    let hits = bone_hits(mesh, &normals, &traced, bone_at, params.max_length_mm, step);
    let mut attachment_of = vec![None; mesh.vertices.len()];
    let mut attachments = Vec::new();
    let mut misses = Vec::new();
    for (i, h) in hits.iter().enumerate() {
        match h {
            Some(p) => {
                attachment_of[i] = Some(attachments.len());
                attachments.push(*p);
            }
            None if traced[i] => misses.push(i),
            None => {}
        }
    }
    let pairs = spring_pairs(&nb, &attachment_of, want, params.struts);
    let springs: Vec<Spring> = pairs
        .par_iter()
        .map(|&(i, b, kind)| {
            let (xs, xb) = (mesh.vertices[i], attachments[b]);
            let l = norm(sub(xb, xs)).max(1e-9);
            let comp = compliance(vol, labels, xs, xb, step, stiffness);
            // eq. 2: 1/c = (1/l) Σ l_h / c_h.
            let c = if comp > 0.0 { l / comp } else { stiffness.skin };
            Spring {
                skin: i,
                bone: b,
                c,
                rest: l,
                kind,
            }
        })
        .collect();
    SpringSet {
        attachment_of,
        attachments,
        springs,
        k: vertex_areas(mesh),
        misses,
    }
}

/// `want`: the vertices whose springs the solve will use (only the skin the bone
/// moves can reach). Their struts end at their neighbours' attachments, so those are traced
/// too; every other vertex gets no spring and is not counted as a miss.
fn traced_vertices(nb: &[Vec<u32>], want: Option<&[bool]>, n: usize) -> Vec<bool> {
    match want {
        None => vec![true; n],
        Some(w) => {
            let mut t = w.to_vec();
            for (i, &wi) in w.iter().enumerate() {
                if wi {
                    for &j in &nb[i] {
                        t[j as usize] = true;
                    }
                }
            }
            t
        }
    }
}

/// Main springs: march from each traced vertex along its inward normal to the first bone
/// (steps of `step` up to `max_length`), refined by bisection; None when no bone is reached.
fn bone_hits(
    mesh: &Mesh,
    normals: &[[f64; 3]],
    traced: &[bool],
    bone_at: impl Fn([f64; 3]) -> bool + Sync,
    max_length: f64,
    step: f64,
) -> Vec<Option<[f64; 3]>> {
    mesh.vertices
        .par_iter()
        .zip(normals)
        .zip(traced)
        .map(|((&xs, &n), &traced)| {
            if !traced {
                return None;
            }
            let d = scale(n, -1.0);
            let mut t = 0.0;
            while t < max_length {
                let t1 = (t + step).min(max_length);
                if bone_at(add(xs, scale(d, t1))) {
                    let (mut lo, mut hi) = (t, t1);
                    for _ in 0..30 {
                        let m = 0.5 * (lo + hi);
                        if bone_at(add(xs, scale(d, m))) {
                            hi = m
                        } else {
                            lo = m
                        }
                    }
                    return Some(add(xs, scale(d, 0.5 * (lo + hi))));
                }
                t = t1;
            }
            None
        })
        .collect()
}

/// (skin vertex, attachment, kind) of every spring of the wanted vertices: the main spring to
/// its own attachment, struts (with `struts`) to its neighbours'.
fn spring_pairs(
    nb: &[Vec<u32>],
    attachment_of: &[Option<usize>],
    want: Option<&[bool]>,
    struts: bool,
) -> Vec<(usize, usize, Kind)> {
    let wanted = |i: usize| want.is_none_or(|w| w[i]);
    let mut pairs = Vec::new();
    for i in (0..attachment_of.len()).filter(|&i| wanted(i)) {
        if let Some(b) = attachment_of[i] {
            pairs.push((i, b, Kind::Main));
        }
        if struts {
            for &j in &nb[i] {
                if let Some(b) = attachment_of[j as usize] {
                    pairs.push((i, b, Kind::Strut));
                }
            }
        }
    }
    pairs
}

/// k_i per vertex (eq. 21): the areas of the triangles around it, mm².
fn vertex_areas(mesh: &Mesh) -> Vec<f64> {
    let mut k = vec![0.0; mesh.vertices.len()];
    for t in 0..mesh.triangles.len() {
        let a = 0.5 * norm(mesh.face_normal(t));
        for &v in &mesh.triangles[t] {
            k[v as usize] += a;
        }
    }
    k
}

/// The vertices whose springs a solve uses: with `[solve] restrict` on and part of the skin
/// rigid, the movable ones (a rigid vertex's DOFs are fixed, so its springs act on nothing);
/// otherwise all (None).
pub fn wanted(rigid: &[bool], restrict: bool) -> Option<Vec<bool>> {
    (restrict && rigid.iter().any(|r| *r)).then(|| rigid.iter().map(|r| !r).collect())
}

impl SpringSet {
    /// No springs on a skin of `n` vertices (models that do not use them).
    pub fn none(n: usize) -> SpringSet {
        SpringSet {
            attachment_of: vec![None; n],
            attachments: Vec::new(),
            springs: Vec::new(),
            k: vec![0.0; n],
            misses: Vec::new(),
        }
    }

    pub fn report(&self, mesh: &Mesh) -> SpringReport {
        let stat = |v: Vec<f64>| {
            if v.is_empty() {
                return [0.0; 3];
            }
            let mn = v.iter().cloned().fold(f64::INFINITY, f64::min);
            let mx = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            [mn, v.iter().sum::<f64>() / v.len() as f64, mx]
        };
        let main: Vec<&Spring> = self
            .springs
            .iter()
            .filter(|s| s.kind == Kind::Main)
            .collect();
        let (miss_centroid, miss_bounds) = match extent(mesh, &self.misses) {
            Some((c, b)) => (Some(c), Some(b)),
            None => (None, None),
        };
        let miss_regions = self.miss_regions(mesh);
        SpringReport {
            miss_regions,
            main: main.len(),
            struts: self.springs.len() - main.len(),
            misses: self.misses.len(),
            miss_centroid,
            miss_bounds,
            length_mm: stat(main.iter().map(|s| s.rest).collect()),
            stiffness: stat(main.iter().map(|s| s.c).collect()),
        }
    }

    /// The misses as connected patches (mesh edges between two misses): the 8 largest, in the
    /// order documented on [`SpringReport::miss_regions`]. Every key is computed from the
    /// vertices, never from a hash order, so the list is the same from run to run.
    fn miss_regions(&self, mesh: &Mesh) -> Vec<MissRegion> {
        let mut missing = vec![false; mesh.vertices.len()];
        for &i in &self.misses {
            missing[i] = true;
        }
        let mut sets = UnionFind::new(mesh.vertices.len());
        for t in &mesh.triangles {
            for e in 0..3 {
                let (a, b) = (t[e] as usize, t[(e + 1) % 3] as usize);
                if missing[a] && missing[b] {
                    sets.union(a, b);
                }
            }
        }
        // Patches in the order of their first miss, each listing its misses in `misses` order.
        let mut patch_of = vec![usize::MAX; mesh.vertices.len()];
        let mut patches: Vec<Vec<usize>> = Vec::new();
        for &i in &self.misses {
            let r = sets.find(i);
            if patch_of[r] == usize::MAX {
                patch_of[r] = patches.len();
                patches.push(Vec::new());
            }
            patches[patch_of[r]].push(i);
        }
        let mut regions: Vec<(MissRegion, usize)> = patches
            .iter()
            .filter_map(|g| {
                let (centroid, bounds) = extent(mesh, g)?;
                let first = *g.iter().min()?;
                let region = MissRegion {
                    vertices: g.len(),
                    centroid,
                    bounds,
                };
                Some((region, first))
            })
            .collect();
        regions.sort_by(|(a, fa), (b, fb)| {
            b.vertices
                .cmp(&a.vertices)
                .then(a.centroid[2].total_cmp(&b.centroid[2]))
                .then(fa.cmp(fb))
        });
        regions.truncate(8);
        regions.into_iter().map(|(r, _)| r).collect()
    }

    /// springs.ply (docs/reference/case.md): skin vertices then attachments; edges (skin, skull) with
    /// `stiffness` and `kind` (0 main, 1 strut).
    pub(crate) fn to_mesh(&self, skin: &Mesh) -> Mesh {
        let nv = skin.vertices.len();
        let vertices = skin
            .vertices
            .iter()
            .chain(&self.attachments)
            .copied()
            .collect();
        let edges = Some(Edges {
            pairs: self
                .springs
                .iter()
                .map(|s| [s.skin as u32, (nv + s.bone) as u32])
                .collect(),
            columns: vec![
                Column {
                    name: "stiffness".into(),
                    values: self.springs.iter().map(|s| s.c).collect(),
                },
                Column {
                    name: "kind".into(),
                    values: self
                        .springs
                        .iter()
                        .map(|s| if s.kind == Kind::Main { 0.0 } else { 1.0 })
                        .collect(),
                },
            ],
        });
        Mesh {
            vertices,
            edges,
            ..Default::default()
        }
    }
}

/// A bounding box (lo, hi).
type Bounds = ([f64; 3], [f64; 3]);

/// Centroid and bounding box (LPS mm) of the vertices `idx` of `mesh`; None when empty.
fn extent(mesh: &Mesh, idx: &[usize]) -> Option<([f64; 3], Bounds)> {
    if idx.is_empty() {
        return None;
    }
    let n = idx.len() as f64;
    let c = idx
        .iter()
        .fold([0.0; 3], |a, &i| add(a, mesh.vertices[i]))
        .map(|x| x / n);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for &i in idx {
        for a in 0..3 {
            lo[a] = lo[a].min(mesh.vertices[i][a]);
            hi[a] = hi[a].max(mesh.vertices[i][a]);
        }
    }
    Some((c, (lo, hi)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ten tied patches (three misses each, centroid z = 0), one larger patch and one lower
    /// one, listed in `misses` back to front: the report must order them by size, then z, then
    /// smallest vertex, and keep the same eight every time (a hash-ordered grouping did not).
    #[test]
    fn miss_regions_order_ties_by_smallest_vertex() {
        let mut mesh = Mesh::default();
        let patch = |mesh: &mut Mesh, x: f64, z: f64, n: usize| {
            let v0 = mesh.vertices.len() as u32;
            for k in 0..n {
                mesh.vertices.push([x + k as f64, (k % 2) as f64, z]);
            }
            for k in 2..n as u32 {
                mesh.triangles.push([v0, v0 + k - 1, v0 + k]);
            }
        };
        // Tied patches at decreasing x, so neither x nor list order gives the expected order.
        for p in 0..10 {
            patch(&mut mesh, 100.0 - 10.0 * p as f64, 0.0, 3);
        }
        patch(&mut mesh, 200.0, 0.0, 4);
        patch(&mut mesh, 300.0, -5.0, 3);
        let n = mesh.vertices.len();
        let set = SpringSet {
            attachment_of: vec![None; n],
            attachments: Vec::new(),
            springs: Vec::new(),
            k: vec![0.0; n],
            misses: (0..n).rev().collect(),
        };
        for _ in 0..20 {
            let r = set.report(&mesh);
            assert_eq!(r.misses, n);
            let got: Vec<(usize, [f64; 3])> = r
                .miss_regions
                .iter()
                .map(|m| (m.vertices, m.bounds.0))
                .collect();
            let mut want = vec![(4, [200.0, 0.0, 0.0]), (3, [300.0, 0.0, -5.0])];
            want.extend((0..6).map(|p| (3, [100.0 - 10.0 * p as f64, 0.0, 0.0])));
            assert_eq!(got, want);
        }
    }
}
