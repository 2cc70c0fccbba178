//! Heap accounting for the peak-memory columns of the study and the benchmarks, and for the
//! `facesim` binary's per-stage figure: a global allocator wrapper that counts live bytes and
//! their high-water mark. A binary installs [`Counting`]; [`PROBE`] reads it through the
//! library's `meter::HeapProbe` (without the allocator installed it reports nothing).

use facesim::meter::HeapProbe;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

pub struct Counting;

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Relaxed) + layout.size();
            // A plain load first: the read-modify-write only when this is a new peak (rare), so
            // threads do not fight over the cache line on every allocation.
            if now > PEAK.load(Relaxed) {
                PEAK.fetch_max(now, Relaxed);
            }
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
                let now =
                    LIVE.fetch_add(new_size - layout.size(), Relaxed) + new_size - layout.size();
                if now > PEAK.load(Relaxed) {
                    PEAK.fetch_max(now, Relaxed);
                }
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Relaxed);
            }
        }
        p
    }
}

/// Whether the counting allocator is in use (any allocation has been counted).
pub fn installed() -> bool {
    PEAK.load(Relaxed) > 0
}

/// The counting allocator as the library's heap probe.
pub struct Probe;

pub static PROBE: Probe = Probe;

impl HeapProbe for Probe {
    fn mark(&self) -> usize {
        let live = LIVE.load(Relaxed);
        PEAK.store(live, Relaxed);
        live
    }
    fn peak_since(&self, base: usize) -> usize {
        PEAK.load(Relaxed).saturating_sub(base)
    }
}

impl Probe {
    /// The probe when the counting allocator is installed, else None (no figure beats a zero).
    pub fn if_installed() -> Option<&'static dyn HeapProbe> {
        installed().then_some(&PROBE as &dyn HeapProbe)
    }
}
