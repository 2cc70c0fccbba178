//! Cost of a stage: wall time, CPU time (user + system, all threads, from getrusage) and peak
//! heap above the live heap at the start (the counting allocator in `memory`; None when the
//! binary does not install it). Stages are measured one after another, never nested.

use serde::{Deserialize, Serialize};
use std::time::Instant;

#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct StageCost {
    pub wall_s: f64,
    pub cpu_s: f64,
    pub peak_heap_mb: Option<f64>,
}

pub struct Meter {
    wall: Instant,
    cpu: f64,
    heap_base: usize,
}

/// User + system CPU seconds of the whole process so far.
pub fn cpu_seconds() -> f64 {
    // SAFETY: getrusage writes into the zeroed struct we pass and reads nothing else.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return 0.0;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

/// Peak resident set size of the process so far (MB).
pub fn max_rss_mb() -> f64 {
    // SAFETY: as above.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return 0.0;
    }
    u.ru_maxrss as f64 / 1024.0
}

impl Meter {
    pub fn start() -> Meter {
        Meter {
            heap_base: crate::memory::start(),
            cpu: cpu_seconds(),
            wall: Instant::now(),
        }
    }

    pub fn stop(&self) -> StageCost {
        StageCost {
            wall_s: self.wall.elapsed().as_secs_f64(),
            cpu_s: cpu_seconds() - self.cpu,
            peak_heap_mb: crate::memory::peak_since(self.heap_base).map(|b| b as f64 / 1e6),
        }
    }
}
