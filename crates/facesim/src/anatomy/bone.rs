//! The CT's bone as the detectors see it, the landmark labels, and a frame's pitch turn.

use crate::labels;
use crate::volume::Volume;

/// The CT and its tissue labels, with the bone test the detectors share.
pub struct Bone<'a> {
    pub vol: &'a Volume,
    /// Tissue labels per voxel (`crate::labels`), the segmentation's.
    pub labels: &'a [u8],
}

impl Bone<'_> {
    /// Whether the voxel nearest to p (LPS mm) is bone; false outside the CT.
    pub fn is_bone(&self, p: [f64; 3]) -> bool {
        let c = self.vol.to_voxel(p).map(f64::round);
        if (0..3).any(|a| c[a] < 0.0 || c[a] >= self.vol.dims[a] as f64) {
            return false;
        }
        self.labels[self.vol.idx(c[0] as usize, c[1] as usize, c[2] as usize)] == labels::BONE
    }
}

/// The bony landmark labels found from the CT, in the order report.json lists them.
/// Paired ones end in `-R` / `-L` (the patient's right and left).
pub const LANDMARKS: [&str; 27] = [
    "Po-R", "Po-L", "Or-R", "Or-L", // Frankfort horizontal: porion, orbitale
    "ANS", "A", "PNS", "Pir-R", "Pir-L", // maxilla; Pir: lowest point of the piriform rim
    "PTM-R", "PTM-L", // pterygomaxillary junction, at the Le Fort I level
    "U1", "U1-apex", "L1", "L1-apex", // incisal edges and root apices (central incisors)
    "U6-R", "U6-L", // upper first molars' mesiobuccal cusps (the occlusal plane)
    "B", "Pog", "Gn", "Me", // symphysis
    "MF-R", "MF-L", // mental foramina
    "Go-R", "Go-L", // gonion
    "Co-R", "Co-L", // condylion: the top of each condylar head
];

/// `frame` turned face-down by `pitch_deg` about its lateral axis: forward tips down, up tips
/// forward (the origin and the midsagittal plane stay).
pub fn turned(frame: &crate::landmarks::HeadFrame, pitch_deg: f64) -> crate::landmarks::HeadFrame {
    use crate::vec3::{add, scale, sub};
    let (s, c) = pitch_deg.to_radians().sin_cos();
    let mut f = *frame;
    f.anterior = sub(scale(frame.anterior, c), scale(frame.vertical, s));
    f.vertical = add(scale(frame.vertical, c), scale(frame.anterior, s));
    f
}
