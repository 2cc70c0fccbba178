//! The one measure of a stage's cost: wall time, CPU time (user + system, all threads, from
//! getrusage) and peak heap above the live heap at the start — the latter only when the caller
//! supplies a [`HeapProbe`] (a binary that installs [`CountingAllocator`] has one; the library
//! installs no global allocator). Stages are measured one after another, never nested.

use serde::{Deserialize, Serialize};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Instant;

#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct StageCost {
    pub wall_s: f64,
    pub cpu_s: f64,
    pub peak_heap_mb: Option<f64>,
}

/// Live and peak heap bytes, from whatever counts them (a global allocator in a binary).
pub trait HeapProbe: Sync {
    /// Reset the high-water mark to the live bytes and return them.
    fn mark(&self) -> usize;
    /// Peak bytes above `base` since the last `mark`.
    fn peak_since(&self, base: usize) -> usize;
}

pub struct Meter<'a> {
    wall: Instant,
    cpu: f64,
    heap: Option<(&'a dyn HeapProbe, usize)>,
}

/// User + system CPU seconds of the whole process so far.
pub(crate) fn cpu_seconds() -> f64 {
    // SAFETY: getrusage writes into the zeroed struct we pass and reads nothing else.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return 0.0;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

/// Peak resident set size of the process so far (MB): the whole run's peak, which stage meters
/// cannot give (each resets the heap high-water mark).
pub fn max_rss_mb() -> f64 {
    // SAFETY: as above.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return 0.0;
    }
    u.ru_maxrss as f64 / 1024.0
}

impl<'a> Meter<'a> {
    pub fn start(heap: Option<&'a dyn HeapProbe>) -> Meter<'a> {
        Meter {
            heap: heap.map(|h| (h, h.mark())),
            cpu: cpu_seconds(),
            wall: Instant::now(),
        }
    }

    pub fn stop(&self) -> StageCost {
        StageCost {
            wall_s: self.wall.elapsed().as_secs_f64(),
            cpu_s: cpu_seconds() - self.cpu,
            peak_heap_mb: self.heap.map(|(h, base)| h.peak_since(base) as f64 / 1e6),
        }
    }
}

/// A global allocator that counts live heap bytes and their high-water mark (two relaxed atomics
/// per allocation), for report.json's per-stage peak heap. A binary installs it with
/// `#[global_allocator] static A: CountingAllocator = CountingAllocator;`; the library installs
/// none, and without it [`counted_heap`] gives no figure.
pub struct CountingAllocator;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Relaxed) + by;
    // A plain load first: the read-modify-write only at a new peak (rare), so threads do not
    // fight over the cache line on every allocation.
    if now > PEAK.load(Relaxed) {
        PEAK.fetch_max(now, Relaxed);
    }
}

// SAFETY: every call forwards to the system allocator unchanged; only the counters are added.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                grew(new_size - layout.size());
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Relaxed);
            }
        }
        p
    }
}

/// The counting allocator's figures as a [`HeapProbe`].
struct Counted;

impl HeapProbe for Counted {
    fn mark(&self) -> usize {
        let live = LIVE.load(Relaxed);
        PEAK.store(live, Relaxed);
        live
    }
    fn peak_since(&self, base: usize) -> usize {
        PEAK.load(Relaxed).saturating_sub(base)
    }
}

/// The heap probe of [`CountingAllocator`] when the program installed it (it has counted an
/// allocation), else None: no figure beats a zero.
pub fn counted_heap() -> Option<&'static dyn HeapProbe> {
    static PROBE: Counted = Counted;
    (PEAK.load(Relaxed) > 0).then_some(&PROBE as &dyn HeapProbe)
}
