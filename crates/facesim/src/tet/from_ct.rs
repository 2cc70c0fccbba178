//! The soft tissue of a CT case as a tetrahedral mesh: isosurface stuffing (`stuffing`) of the
//! region inside the skin iso-surface and outside the bone iso-surface, restricted to a box.
//!
//! The iso-surfaces are the pipeline's own (`pipeline::surfaces`): the skin where
//! `seg.skin_field` crosses `windows.head_threshold`, the bone where `seg.bone_field` crosses
//! `windows.bone`, both sampled trilinearly as marching tetrahedra interpolate them. One
//! implicit (negative in soft tissue): f = max(head_threshold − skin, bone − bone_iso), in HU.
//!
//! Air cavities (sinuses, airway, mouth air) are not part of the head mask, so `skin_field`
//! clamps them below the head threshold: they are holes in the mesh, bounded by Skin nodes
//! (their walls are a skin-type iso-surface, as in the pipeline's skin surface).
//!
//! Thin tissue (skin 2–3 mm over bone, the nasal bridge) narrower than about one lattice
//! spacing may be missed by the lattice: the mesh stays valid (stuffing's angle bounds do not
//! depend on the surface) but the gap closes there. `voxel_volume_mm3` (the soft tissue of the
//! box counted from voxel centres) against `quality.volume_mm3 + dropped_volume_mm3` shows how
//! much was lost.
//!
//! Pieces of tissue that reach no skin node (the brain, tissue enclosed by bone) are left out:
//! they cannot move with the face (`dropped_volume_mm3`).
//!
//! Tissue per tetrahedron: the segmentation label of the voxel nearest its centroid; when that
//! voxel is air or bone (partial volume at the boundary), the most common soft label
//! (skin, fats, muscle) within 1, then 2, then 3 voxels; muscle when none is found (counted in
//! `tissue_fallbacks`).

use super::graded;
use super::quality::Quality;
use super::stuffing::{self, NodeKind as StuffKind};
use crate::error::{Error, Result};
use crate::segment::{BONE, MUSCLE, Segmentation};
use crate::volume::blocks::BlockRange;
use crate::volume::{Volume, VoxelMap, sample_field};
use rayon::prelude::*;

/// Lattice sizes (mm): `skin_size_mm` at the skin, doubling with depth up to `deep_size_mm`
/// (rounded down to skin size × 2^k, k ≤ 4); `margin_mm` widens the box on every side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshParams {
    pub skin_size_mm: f64,
    pub deep_size_mm: f64,
    pub margin_mm: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum NodeKind {
    Interior,
    /// On the skin iso-surface (including cavity walls).
    Skin,
    /// On the bone iso-surface.
    Bone,
    /// On the region's cut faces only.
    Cut,
}

pub struct SoftTissueMesh {
    /// LPS mm.
    pub nodes: Vec<[f64; 3]>,
    /// Positive volume (`tet::gradients` is Some for each).
    pub tets: Vec<[u32; 4]>,
    /// Per tetrahedron, a soft label of `crate::segment` (SKIN, FAT_DARK, FAT_BRIGHT, MUSCLE).
    pub tissue: Vec<u8>,
    /// The box the lattice filled (LPS mm): `roi` widened by `margin_mm`, its upper corner
    /// rounded up to whole lattice cells. Its faces are the `Cut` faces; beyond the CT the
    /// fields read air, so where the scan ends inside it the tissue ends in a surface.
    pub lattice_box: ([f64; 3], [f64; 3]),
    /// Per node.
    pub kind: Vec<NodeKind>,
    pub quality: Quality,
    /// Soft tissue inside the box counted from voxel centres (mm³), to compare with
    /// `quality.volume_mm3`: thin tissue the lattice could not resolve is the difference.
    pub voxel_volume_mm3: f64,
    /// Tetrahedra with no soft voxel within 3 voxels of their centroid (labelled muscle).
    pub tissue_fallbacks: usize,
    /// Surface slivers left out by the mesher (`stuffing::Stuffed::flattened`).
    pub flattened: usize,
    /// Volume (mm³) of tissue pieces that do not reach the skin (enclosed by bone), left out.
    pub dropped_volume_mm3: f64,
}

/// Samples per axis of the grading's range test: 4 samples span about three skin elements,
/// eight voxels of a head CT.
const SAMPLE_CHUNK: usize = 4;

/// HU given to samples outside the CT: air for the skin field, no bone for the bone field.
const OUTSIDE_HU: f32 = -1024.0;

/// What `decide` says of the voxels every trilinear sample inside the LPS box `corners` reads
/// (None when a sample there may fall outside the grid). The box's voxel-coordinate
/// extent is that of its eight corners (the map is affine), widened by 1e-6 voxels for points
/// inside it computed another way.
fn one_sided(
    map: &VoxelMap,
    grid: &BlockRange,
    corners: [[f64; 3]; 2],
    decide: impl Fn([usize; 3], [usize; 3]) -> Option<bool>,
) -> Option<bool> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for k in 0..8 {
        let c = map.to_voxel(std::array::from_fn(|a| corners[(k >> a) & 1][a]));
        for a in 0..3 {
            lo[a] = lo[a].min(c[a]);
            hi[a] = hi[a].max(c[a]);
        }
    }
    grid.voxels_read(lo, hi, 1e-6)
        .and_then(|(first, last)| decide(first, last))
}

/// Mesh the soft tissue of `vol` inside `roi` (an LPS box, mm; widened by `p.margin_mm`).
pub fn soft_tissue(
    vol: &Volume,
    seg: &Segmentation,
    roi: ([f64; 3], [f64; 3]),
    p: &MeshParams,
) -> Result<SoftTissueMesh> {
    check_params(p)?;
    let lo = roi.0.map(|x| x - p.margin_mm);
    let hi = roi.1.map(|x| x + p.margin_mm);
    let fields = Fields::new(vol, seg);
    let m = stuff_tissue(&fields, lo, hi, p)?;
    if m.tets.is_empty() {
        return Err(Error::config(format!(
            "tetrahedral mesh: no soft tissue inside the region {lo:?} .. {hi:?} (LPS mm)"
        )));
    }
    let kind = node_kinds(&fields, vol.bounds(), &m.nodes, &m.kind);
    let (nodes, tets, kind, dropped_volume_mm3) = keep_skin_components(m.nodes, m.tets, kind);
    let m = stuffing::Stuffed {
        nodes,
        tets,
        kind: Vec::new(),
        ..m
    };
    let (tissue, tissue_fallbacks) = tissue_labels(vol, seg, &fields.map, &m.nodes, &m.tets);
    let quality = Quality::of(&m.nodes, &m.tets);
    // The box as meshed: rounded up to whole cubes of the coarsest size.
    let (lo, hi) = m.bounds;
    let voxel_volume_mm3 = voxel_volume(vol, &fields, lo, hi);
    Ok(SoftTissueMesh {
        nodes: m.nodes,
        tets: m.tets,
        tissue,
        lattice_box: m.bounds,
        kind,
        quality,
        voxel_volume_mm3,
        tissue_fallbacks,
        flattened: m.flattened,
        dropped_volume_mm3,
    })
}

fn check_params(p: &MeshParams) -> Result<()> {
    if !(p.skin_size_mm.is_finite() && p.skin_size_mm > 0.0) {
        return Err(Error::config(format!(
            "tetrahedral mesh: skin size must be positive, got {} mm",
            p.skin_size_mm
        )));
    }
    if !(p.margin_mm.is_finite() && p.margin_mm >= 0.0) {
        return Err(Error::config(format!(
            "tetrahedral mesh: margin must be ≥ 0, got {} mm",
            p.margin_mm
        )));
    }
    Ok(())
}

/// The skin and bone fields of a CT with their iso-values, sampled trilinearly at LPS points.
struct Fields {
    skin: Vec<f32>,
    bone: Vec<f32>,
    skin_iso: f64,
    bone_iso: f64,
    map: VoxelMap,
    dims: [usize; 3],
}

impl Fields {
    fn new(vol: &Volume, seg: &Segmentation) -> Fields {
        Fields {
            skin: seg.skin_field(vol),
            bone: seg.bone_field(vol),
            skin_iso: seg.windows.head_threshold,
            bone_iso: seg.windows.bone,
            map: vol.voxel_map(),
            dims: vol.dims,
        }
    }

    /// The implicit's two terms at `q`: the skin's and the bone's.
    fn parts(&self, q: [f64; 3]) -> (f64, f64) {
        let c = self.map.to_voxel(q);
        (
            self.skin_iso - sample_field(&self.skin, self.dims, c, OUTSIDE_HU) as f64,
            sample_field(&self.bone, self.dims, c, OUTSIDE_HU) as f64 - self.bone_iso,
        )
    }

    /// The implicit: negative in soft tissue.
    fn f(&self, q: [f64; 3]) -> f64 {
        let (s, b) = self.parts(q);
        s.max(b)
    }

    /// f(q) < 0, the skin's term first: the bone's is not needed where the skin's is not
    /// below zero.
    fn tissue_at(&self, q: [f64; 3]) -> bool {
        let c = self.map.to_voxel(q);
        self.skin_iso - (sample_field(&self.skin, self.dims, c, OUTSIDE_HU) as f64) < 0.0
            && (sample_field(&self.bone, self.dims, c, OUTSIDE_HU) as f64) - self.bone_iso < 0.0
    }
}

/// Stuff the box `lo`..`hi`: a uniform lattice of the skin size, or a graded one when the deep
/// size allows coarser cubes.
fn stuff_tissue(
    fields: &Fields,
    lo: [f64; 3],
    hi: [f64; 3],
    p: &MeshParams,
) -> Result<stuffing::Stuffed> {
    let f = |q: [f64; 3]| fields.f(q);
    // Grading: a cube of size s = h·2^l stays whole unless the skin or the bone iso-surface
    // crosses the cube grown by s on every side (sampled every h), so the size doubles about
    // every cube-width of distance from both surfaces, up to the deep size. Both surfaces stay
    // in the finest uniform lattice (`graded`: size changes away from every surface keep
    // stuffing's angle bounds); only tissue away from them coarsens.
    let h = p.skin_size_mm;
    let levels = if p.deep_size_mm > h {
        ((p.deep_size_mm / h).log2().floor() as u32).min(4)
    } else {
        0
    };
    if levels == 0 {
        stuffing::stuff(&f, lo, hi, h)
    } else {
        let grading = Grading {
            fields,
            skin_range: BlockRange::new(&fields.skin, fields.dims),
            bone_range: BlockRange::new(&fields.bone, fields.dims),
            h,
        };
        let surface_near = |a: [f64; 3], b: [f64; 3]| grading.surface_near(a, b);
        let bg = graded::background(lo, hi, h, levels, &surface_near)?;
        graded::stuff_graded(&f, &bg)
    }
}

/// The grading's test: whether an iso-surface passes near a cube, from the fields' block
/// ranges where they decide it and from samples where they do not.
struct Grading<'a> {
    fields: &'a Fields,
    skin_range: BlockRange,
    bone_range: BlockRange,
    /// The skin size (mm).
    h: f64,
}

impl Grading<'_> {
    /// Whether f < 0 (soft tissue) at every sample of an LPS box, at none, or either.
    fn side_of_box(&self, corners: [[f64; 3]; 2]) -> Option<bool> {
        let (skin_iso, bone_iso) = (self.fields.skin_iso, self.fields.bone_iso);
        one_sided(&self.fields.map, &self.skin_range, corners, |lo, hi| {
            let (skin_lo, skin_hi) = self.skin_range.range(lo, hi);
            let (bone_lo, bone_hi) = self.bone_range.range(lo, hi);
            if f64::from(skin_lo) > skin_iso && f64::from(bone_hi) < bone_iso {
                Some(true)
            } else if f64::from(skin_hi) <= skin_iso || f64::from(bone_lo) >= bone_iso {
                Some(false)
            } else {
                None
            }
        })
    }

    /// The wanted size of the cube `a`..`b`: the skin size when f changes sign in the cube
    /// grown by its size on every side (sampled every skin size), else no limit.
    fn surface_near(&self, a: [f64; 3], b: [f64; 3]) -> f64 {
        let h = self.h;
        let s = b[0] - a[0];
        let n = (3.0 * s / h).ceil() as usize;
        let sample =
            |ijk: [usize; 3]| [0, 1, 2].map(|ax| a[ax] - s + 3.0 * s * ijk[ax] as f64 / n as f64);
        // The samples' lattice in chunks of SAMPLE_CHUNK per axis: a chunk whose fields'
        // ranges keep f on one side of zero is that side at every sample without sampling
        // it (the samples are convex combinations of the voxels the range covers), so the
        // answer, a crossing or none, is the same as sampling every point.
        let (mut inside, mut outside) = (false, false);
        let chunks = n / SAMPLE_CHUNK + 1;
        for ck in 0..chunks {
            for cj in 0..chunks {
                for ci in 0..chunks {
                    let first = [ci, cj, ck].map(|c| c * SAMPLE_CHUNK);
                    let last = first.map(|f| (f + SAMPLE_CHUNK - 1).min(n));
                    match self.side_of_box([sample(first), sample(last)]) {
                        Some(true) => inside = true,
                        Some(false) => outside = true,
                        None => {
                            for k in first[2]..=last[2] {
                                for j in first[1]..=last[1] {
                                    for i in first[0]..=last[0] {
                                        if self.fields.tissue_at(sample([i, j, k])) {
                                            inside = true;
                                        } else {
                                            outside = true;
                                        }
                                        if inside && outside {
                                            return h;
                                        }
                                    }
                                }
                            }
                        }
                    }
                    if inside && outside {
                        return h;
                    }
                }
            }
        }
        f64::INFINITY
    }
}

/// Per stuffed node its kind: surface nodes on the bone or the skin. `scan` is the CT's
/// outermost voxel centres: past them the fields jump to air, and the tissue ends where the
/// scan does.
fn node_kinds(
    fields: &Fields,
    scan: ([f64; 3], [f64; 3]),
    nodes: &[[f64; 3]],
    kind: &[StuffKind],
) -> Vec<NodeKind> {
    nodes
        .par_iter()
        .zip(kind)
        .map(|(q, k)| match k {
            StuffKind::Interior => NodeKind::Interior,
            StuffKind::Cut => NodeKind::Cut,
            StuffKind::Surface => surface_kind(fields, scan, *q),
        })
        .collect()
}

/// A surface node's kind: Bone where the bone's term decides f, else Skin.
fn surface_kind(fields: &Fields, (first, last): ([f64; 3], [f64; 3]), q: [f64; 3]) -> NodeKind {
    let on_bone = if crate::volume::past_scan_end((first, last), q) {
        // The scan's end: neither iso-surface, both terms below zero, so their
        // order says nothing. Bone only where bone reaches the last slice; the rest
        // is the tissue's free surface where the scan ends.
        let on_last = std::array::from_fn(|a| q[a].clamp(first[a], last[a]));
        fields.parts(on_last).1 >= 0.0
    } else {
        // On f = 0 one of the two terms is zero and the other is not above it.
        let (s, b) = fields.parts(q);
        b >= s
    };
    if on_bone {
        NodeKind::Bone
    } else {
        NodeKind::Skin
    }
}

/// Per tetrahedron the soft label near its centroid (muscle where none is found), and how
/// many fell back to muscle.
fn tissue_labels(
    vol: &Volume,
    seg: &Segmentation,
    map: &VoxelMap,
    nodes: &[[f64; 3]],
    tets: &[[u32; 4]],
) -> (Vec<u8>, usize) {
    let labels: Vec<Option<u8>> = tets
        .par_iter()
        .map(|t| {
            let c = [0, 1, 2].map(|a| t.iter().map(|n| nodes[*n as usize][a]).sum::<f64>() / 4.0);
            tissue_near(vol, seg, map.to_voxel(c))
        })
        .collect();
    let tissue_fallbacks = labels.iter().filter(|l| l.is_none()).count();
    let tissue = labels.into_iter().map(|l| l.unwrap_or(MUSCLE)).collect();
    (tissue, tissue_fallbacks)
}

/// Nodes, tetrahedra, node kinds and the volume left out (mm³).
type Kept = (Vec<[f64; 3]>, Vec<[u32; 4]>, Vec<NodeKind>, f64);

/// Keep the pieces of tissue (node-connected) that reach the skin: tissue enclosed by bone
/// (the brain, an orbit's contents behind closed bone) cannot move with the face. Returns the
/// renumbered nodes, tetrahedra, kinds and the volume dropped (mm³).
fn keep_skin_components(nodes: Vec<[f64; 3]>, tets: Vec<[u32; 4]>, kind: Vec<NodeKind>) -> Kept {
    let mut uf = crate::union_find::UnionFind::new(nodes.len());
    for t in &tets {
        for k in 1..4 {
            uf.union(t[0] as usize, t[k] as usize);
        }
    }
    let mut skin_root = vec![false; nodes.len()];
    for (i, k) in kind.iter().enumerate() {
        if *k == NodeKind::Skin {
            let r = uf.find(i);
            skin_root[r] = true;
        }
    }
    let keep: Vec<bool> = (0..nodes.len()).map(|i| skin_root[uf.find(i)]).collect();
    let mut new_id = vec![u32::MAX; nodes.len()];
    let (mut out_nodes, mut out_kind) = (Vec::new(), Vec::new());
    for i in 0..nodes.len() {
        if keep[i] {
            new_id[i] = out_nodes.len() as u32;
            out_nodes.push(nodes[i]);
            out_kind.push(kind[i]);
        }
    }
    let dropped_volume: f64 = tets
        .iter()
        .filter(|t| !keep[t[0] as usize])
        .filter_map(|t| super::gradients(t.map(|v| nodes[v as usize])).map(|(v, _)| v))
        .fold(0.0, |a, v| a + v); // (an empty f64 sum is −0)
    let out_tets: Vec<[u32; 4]> = tets
        .into_iter()
        .filter(|t| keep[t[0] as usize])
        .map(|t| t.map(|v| new_id[v as usize]))
        .collect();
    (out_nodes, out_tets, out_kind, dropped_volume)
}

fn is_soft(l: u8) -> bool {
    l != crate::segment::AIR && l != BONE
}

/// The soft label at continuous voxel coordinates `c`: the nearest voxel's, else the most
/// common soft label within 1, 2, 3 voxels (ties to the lower label).
fn tissue_near(vol: &Volume, seg: &Segmentation, c: [f64; 3]) -> Option<u8> {
    let centre = [0, 1, 2].map(|a| c[a].round().clamp(0.0, (vol.dims[a] - 1) as f64) as i64);
    let label = |q: [i64; 3]| -> Option<u8> {
        if (0..3).any(|a| q[a] < 0 || q[a] >= vol.dims[a] as i64) {
            return None;
        }
        seg.labels
            .get(vol.idx(q[0] as usize, q[1] as usize, q[2] as usize))
            .copied()
    };
    if let Some(l) = label(centre).filter(|l| is_soft(*l)) {
        return Some(l);
    }
    for r in 1..=3i64 {
        let mut count = [0usize; 6];
        for dz in -r..=r {
            for dy in -r..=r {
                for dx in -r..=r {
                    let l = label([centre[0] + dx, centre[1] + dy, centre[2] + dz]);
                    if let Some(l) = l.filter(|l| is_soft(*l)) {
                        count[l as usize] += 1;
                    }
                }
            }
        }
        let best = (1..5u8).max_by_key(|l| (count[*l as usize], std::cmp::Reverse(*l)))?;
        if count[best as usize] > 0 {
            return Some(best);
        }
    }
    None
}

/// Soft-tissue volume (mm³) of the voxels whose centres lie in the box: inside the skin
/// iso-surface and outside the bone's.
fn voxel_volume(vol: &Volume, fields: &Fields, lo: [f64; 3], hi: [f64; 3]) -> f64 {
    let count = (0..vol.len())
        .into_par_iter()
        .filter(|&i| {
            let p = vol.to_world(vol.ijk(i).map(|x| x as f64));
            (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a])
                && fields.skin[i] as f64 >= fields.skin_iso
                && (fields.bone[i] as f64) < fields.bone_iso
        })
        .count();
    count as f64 * vol.voxel_volume()
}
