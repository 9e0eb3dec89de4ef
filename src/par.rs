//! Fork points inside one frame's work: `run` processes frames on the threads of one
//! rayon pool, so that a worker with no frame left takes the second half of a fork in
//! another worker's frame instead of idling at the end of a capture (see
//! `engine::stream_frames`).

/// Runs `a` and `b` and returns both results. On a thread of a rayon pool it is a
/// `rayon::join`: `a` runs here and `b` waits to be taken by an idle thread of the pool,
/// or runs here after `a` when none is idle (a join costs next to nothing then). On any
/// other thread both run here in turn, since a join there would start rayon's global pool
/// and wait for it. `a` and `b` must be independent; the results are the same either way.
pub fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    if rayon::current_thread_index().is_some() {
        rayon::join(a, b)
    } else {
        (a(), b())
    }
}

/// Worker threads set by [`set_worker_threads`], if any.
static THREADS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();

/// Sets the number of worker threads [`worker_threads`] gives (`--threads N`); the first
/// call wins.
pub fn set_worker_threads(n: usize) {
    let _ = THREADS.set(n.max(1));
}

/// Worker threads to use: as set by [`set_worker_threads`], else `RAYON_NUM_THREADS`
/// (when a positive number), else one per core, as rayon decides. Unlike
/// `rayon::current_num_threads` it does not start rayon's global pool, whose idle threads
/// would spin beside the streaming workers of `run` and `convert` (a pool of their own,
/// of this size).
pub fn worker_threads() -> usize {
    if let Some(&n) = THREADS.get() {
        return n;
    }
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}
