//! How the pipeline reports on itself: one [`Observer`] hears each stage start (for progress) and
//! finish (with its cost), and may lend a heap probe for the peak-memory figure. The library
//! draws nothing on a terminal; the command line's observer does (crates/facesim-cli).

use crate::meter::{HeapProbe, StageCost};

pub trait Observer: Sync {
    /// A stage starts; `what` is a short phrase for a progress line ("segmenting tissues").
    fn started(&self, _what: &str) {}
    /// A stage finished; `stage` is its key in report.json's `timings`.
    fn finished(&self, _stage: &str, _cost: &StageCost) {}
    /// The whole run is over (a progress display clears itself).
    fn done(&self) {}
    /// A warning of a run that ends in an error (a successful run's are in its report).
    fn warn(&self, _msg: &str) {}
    /// The counter of heap bytes, when the program has one.
    fn heap(&self) -> Option<&dyn HeapProbe> {
        None
    }
}

/// Hears nothing: for tests, the study and library callers that want no progress.
pub struct Quiet;

impl Observer for Quiet {}
