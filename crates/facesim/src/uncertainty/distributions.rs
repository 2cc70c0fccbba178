//! `[uncertainty]`'s schema lives with the case schema (`case::uncertainty`); its items are
//! re-exported here for the sampling and the paths callers use.

pub use crate::case::uncertainty::*;
