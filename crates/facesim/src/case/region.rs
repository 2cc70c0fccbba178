//! Region shapes (docs/reference/case.md) and whether a point is inside one. Mask and surface regions
//! hold their file's content once the input stage has read it
//! (`pipeline::inputs::read_region_files`); no file is read here.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Region shapes (docs/reference/case.md), used by `movable` and `osteotomy.region`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Region {
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    HalfSpace {
        point: [f64; 3],
        normal: [f64; 3],
    },
    Mask(Mask),
    /// Inside a closed surface (`surface = "maxilla.stl"`: STL, PLY, OBJ, VTK; docs/guide/slicer.md).
    Surface(SurfaceFile),
}

/// A `surface = "file.stl"` region: its path as written in case.toml and, once read
/// (`pipeline::inputs::read_masks`, at the input edge), the closed surface. Serialised as the path alone.
#[derive(Clone, Deserialize, Serialize)]
#[serde(from = "PathBuf", into = "PathBuf")]
pub struct SurfaceFile {
    pub path: PathBuf,
    pub surface: Option<std::sync::Arc<crate::mesh::inside::ClosedSurface>>,
}

impl From<PathBuf> for SurfaceFile {
    fn from(path: PathBuf) -> SurfaceFile {
        SurfaceFile {
            path,
            surface: None,
        }
    }
}

impl From<SurfaceFile> for PathBuf {
    fn from(s: SurfaceFile) -> PathBuf {
        s.path
    }
}

impl std::fmt::Debug for SurfaceFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Surface({:?})", self.path)
    }
}

impl SurfaceFile {
    fn contains(&self, p: [f64; 3]) -> bool {
        let Some(s) = &self.surface else {
            // Read before any stage runs, like masks (pipeline::inputs::read_masks).
            debug_assert!(
                false,
                "region surface {} used before it was read",
                self.path.display()
            );
            return false;
        };
        s.contains(p)
    }
}

/// A `mask = "file.nii.gz"` region: its path as written in case.toml and, once the pipeline has
/// read it (`pipeline::inputs::read_masks`, at the input edge), its voxels. Serialised as the path alone.
#[derive(Clone, Deserialize, Serialize)]
#[serde(from = "PathBuf", into = "PathBuf")]
pub struct Mask {
    pub path: PathBuf,
    pub voxels: Option<std::sync::Arc<crate::volume::Volume>>,
    /// A segment a `[[surgery]]` cut (`crate::anatomy::cuts`): it selects the bone it cut
    /// before any move, so that segments cut from one bone and moved together (a chin on a
    /// moved mandible) each keep their own bone.
    pub found: bool,
}

impl From<PathBuf> for Mask {
    fn from(path: PathBuf) -> Mask {
        Mask {
            path,
            voxels: None,
            found: false,
        }
    }
}

impl From<Mask> for PathBuf {
    fn from(m: Mask) -> PathBuf {
        m.path
    }
}

impl std::fmt::Debug for Mask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Mask({:?})", self.path)
    }
}

impl Mask {
    /// Non-zero voxel nearest to p; false outside the mask's grid.
    fn contains(&self, p: [f64; 3]) -> bool {
        let Some(m) = &self.voxels else {
            // Masks are read before any stage runs (pipeline::inputs::read_masks); an unread mask selecting
            // nothing would silently make every vertex rigid, as it once did.
            debug_assert!(
                false,
                "mask {} used before it was read",
                self.path.display()
            );
            return false;
        };
        let c = m.to_voxel(p).map(|x| x.round());
        if (0..3).any(|a| c[a] < 0.0 || c[a] >= m.dims[a] as f64) {
            return false;
        }
        m.data[m.idx(c[0] as usize, c[1] as usize, c[2] as usize)] != 0.0
    }
}

impl Region {
    /// Whether the region selects points at their pre-operative position (a segment cut by a
    /// `[[surgery]]`), not at their position after the plan's earlier steps.
    pub(crate) fn selects_pre_operative(&self) -> bool {
        matches!(self, Region::Mask(m) if m.found)
    }

    /// Whether p (LPS mm) is inside; a mask must have been read (`pipeline::inputs::read_masks`).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        match self {
            Region::Box { min, max } => (0..3).all(|a| p[a] >= min[a] && p[a] <= max[a]),
            Region::Sphere { center, radius } => {
                let d: f64 = (0..3).map(|a| (p[a] - center[a]).powi(2)).sum();
                d <= radius * radius
            }
            Region::HalfSpace { point, normal } => {
                (0..3).map(|a| (p[a] - point[a]) * normal[a]).sum::<f64>() >= 0.0
            }
            Region::Mask(m) => m.contains(p),
            Region::Surface(s) => s.contains(p),
        }
    }
}
