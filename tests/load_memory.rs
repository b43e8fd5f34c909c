//! Loading peaks at no more than 2× the voxel payload of host memory.
//!
//! A counting global allocator tracks the live bytes; this binary holds a single test so
//! no other test allocates concurrently.

mod common;

use common::{data, shared_files};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use volao::volume::{self, LoadOptions};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY-free wrapper: delegates to the system allocator and only counts bytes.
#[allow(
    unsafe_code,
    reason = "a GlobalAlloc impl is unsafe by definition; it only forwards to System"
)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            let now = LIVE.fetch_add(new_size, Ordering::Relaxed) + new_size;
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

#[test]
fn loading_peaks_below_twice_the_payload() {
    let mut report = Vec::new();
    for (file, raw) in shared_files() {
        let path = data(file);
        let opts = LoadOptions {
            raw,
            ..Default::default()
        };
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let loaded = volume::load(&path, &opts).unwrap_or_else(|e| panic!("{e}"));
        let peak = PEAK.load(Ordering::Relaxed) - base;
        let payload = loaded.volume.data.byte_len();
        drop(loaded);
        report.push(format!(
            "{file}: peak {peak} B for {payload} B ({:.2}×)",
            peak as f64 / payload as f64
        ));
        // 2× the payload, plus 256 KiB for fixed-size buffers (gzip window, read buffers)
        // that dominate only for the tiny files.
        assert!(
            peak <= 2 * payload + (256 << 10),
            "{file}: loading peaked at {peak} bytes, over 2× the {payload}-byte payload\n{}",
            report.join("\n")
        );
    }
    eprintln!("{}", report.join("\n"));
}
