//! The tissue labels of the segmentation (labels.nii.gz, docs/design/pipeline.md §1): here, below both
//! `segment` (which assigns them) and `case` (whose `[tet]` materials are per label), so that
//! neither imports the other for them.

pub const AIR: u8 = 0;
pub const SKIN: u8 = 1;
pub const FAT_DARK: u8 = 2;
pub const FAT_BRIGHT: u8 = 3;
pub const MUSCLE: u8 = 4;
pub const BONE: u8 = 5;
pub const LABEL_NAMES: [&str; 6] = ["air", "skin", "fat_dark", "fat_bright", "muscle", "bone"];
