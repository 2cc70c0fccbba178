//! The bony anatomy a plan in clinical terms needs, found from the CT (docs/guide/planning.md):
//!
//! - `head`: the clinical head frame — Frankfort horizontal (porion and orbitale, both sides)
//!   and the midsagittal plane, or where the CT does not hold them the soft-tissue facial plane
//!   N'–Pog' as the vertical of natural head position;
//! - `jaws`: the bony landmarks of the maxilla and the mandible the cuts are placed from;
//! - `cuts`: the osteotomies of `[[surgery]]` entries as segments of bone.
//!
//! Every landmark is detected or missing with the reason; positions are LPS mm.

mod bone;
pub mod cuts;
mod find;
pub mod head;
pub mod jaws;
pub mod moves;
pub(crate) mod readback;
#[cfg(test)]
mod sample;
pub mod surgery;

pub use bone::{Bone, LANDMARKS, turned};
pub use find::{Anatomy, find};
