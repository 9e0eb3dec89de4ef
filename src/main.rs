//! The `lidar-noise` command line: parses arguments with clap and calls the library.

mod cli;
mod commands;
mod options;

/// mimalloc: reuses freed pages across frames instead of returning them to the kernel.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's number of its `purge_delay` option (enum `mi_option_e` in its `mimalloc.h`:
/// 15, after `eager_commit_delay`; the Rust bindings leave it unnamed).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Keeps freed pages for a second before mimalloc returns them to the kernel, instead of
/// its 10 ms. Why: a dataset scan takes longer than 10 ms, so every scan's buffers (a
/// few MB) went back to the kernel between scans and faulted in again on the next one,
/// a tenth of a KITTI sequence's time in page faults (figures in the manual's benchmark
/// history). Memory still goes back once the process has not needed it for a second. A
/// user's own `MIMALLOC_PURGE_DELAY` is left to win.
fn slow_purge() {
    if std::env::var_os("MIMALLOC_PURGE_DELAY").is_none() {
        // SAFETY: sets one of mimalloc's option values; called before any thread starts
        // (the function is not thread-safe).
        unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, 1000) };
    }
}

fn main() {
    slow_purge();
    // First, before the heap grows (see the function for why).
    lidar_noise::memory::no_transparent_huge_pages();
    // mimalloc hands a worker's freed warm-up block back to that worker (see the function).
    lidar_noise::memory::warm_worker_heaps(12 << 20);
    std::process::exit(cli::main());
}
