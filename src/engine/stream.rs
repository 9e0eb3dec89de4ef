//! The bounded frame pipeline every frame-by-frame command shares: one thread reads frames
//! from a [`FrameSource`] (a capture or a point-cloud file), a pool of workers processes
//! them, and the results come back in frame order (`run`, `run --chunk-frames`, `convert`).

use crate::frame::{Frame, FrameSource};
use anyhow::{Context, Result};
use std::ops::RangeInclusive;

/// Runs `work` on every frame in `frames` as a bounded pipeline: the calling thread
/// decodes frames and hands them to `par::worker_threads()` workers, and hands
/// each result to `done` (with the reader, to recycle buffers) in frame order as soon as
/// every earlier frame's is in. Decoding, processing (with each frame's own files) and the
/// ordered report append overlap, with no barrier between groups of frames: a slow frame
/// holds back only the report append, never the workers. At most `workers + 2` frames
/// are in flight (decoded, queued, processed or waiting for an earlier one), so memory
/// stays bounded whatever the capture's length. Errors come in frame order: a frame's
/// processing error before a decoding error further on; after the first error no new
/// frame is started.
///
/// The workers are the threads of one rayon pool, one frame loop each, so that `work`'s
/// forks ([`crate::par::join`]) can be taken by a worker that has no frame left: at the
/// end of a capture the last frames then use every core, not one frame per core.
pub fn stream_frames<T: Send, R: FrameSource + ?Sized>(
    reader: &mut R,
    frames: &RangeInclusive<u32>,
    warmup: usize,
    work: impl Fn(Frame) -> Result<T> + Sync,
    mut done: impl FnMut(T, &mut R) -> Result<()>,
) -> Result<()> {
    use std::collections::BTreeMap;
    use std::panic::AssertUnwindSafe;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{mpsc, Mutex};
    let workers = crate::par::worker_threads();
    // A worker that finishes needs one decoded frame ready, and one more lets a frame
    // finish before an earlier one without idling a worker; frames decoded further ahead
    // only hold memory (3.3 MB each), whose first-touched pages cost CPU time: on the
    // shared capture `2 x workers + 1` (5 at 2 workers) peaked at 68-71 MB and took 1-4 %
    // more CPU than this (66 MB) in four interleaved comparisons.
    let window = workers + 2;
    // A pool of its own, of exactly `workers` threads: the global pool may have another
    // size (set before `--threads` was read) and would also take other rayon work.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers)
        .build()
        .with_context(|| format!("cannot start {workers} worker threads"))?;
    let (frame_tx, frame_rx) = mpsc::sync_channel::<(usize, Frame)>(workers);
    let frame_rx = Mutex::new(frame_rx);
    // A worker's panic travels to the calling thread and resumes there.
    type Outcome<T> = std::thread::Result<Result<T>>;
    let (result_tx, result_rx) = mpsc::channel::<(usize, Outcome<T>)>();
    // Set on the first error: queued frames are then skipped, not processed.
    let stop = AtomicBool::new(false);
    // The calling thread is no thread of the pool: it decodes and keeps frame order while
    // the pool's threads run the frames (and, when idle, the forks of other frames).
    pool.in_place_scope(|scope| -> Result<()> {
        let (frame_rx, result_tx, work, stop) = (&frame_rx, &result_tx, &work, &stop);
        // One frame loop on each thread of the pool (a broadcast, so that no thread can
        // run a second loop inside a fork it waits for).
        scope.spawn_broadcast(move |_, ctx| {
            let result_tx = result_tx.clone();
            // Until its first frame, the worker faults in `warmup` bytes of its heap (see
            // `HeapWarmer`); only the first `WARMED_WORKERS` do.
            let bytes = if ctx.index() < WARMED_WORKERS {
                warmup
            } else {
                0
            };
            let mut warmer = crate::memory::HeapWarmer::new(bytes);
            loop {
                let next = next_frame(frame_rx, &mut warmer);
                let Ok((seq, frame)) = next else {
                    return;
                };
                if stop.load(Ordering::Relaxed) {
                    continue;
                }
                let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| work(frame)));
                if result_tx.send((seq, outcome)).is_err() {
                    return;
                }
            }
        });
        let mut frame_tx = Some(frame_tx);
        // Results that arrived before an earlier frame's, by sequence number.
        let mut pending: BTreeMap<usize, Outcome<T>> = BTreeMap::new();
        let (mut sent, mut finished) = (0usize, 0usize);
        let mut decode_error: Option<anyhow::Error> = None;
        // Hands over every result whose predecessors are all in.
        let mut drain =
            |pending: &mut BTreeMap<usize, Outcome<T>>, finished: &mut usize, reader: &mut R| {
                while let Some(outcome) = pending.remove(finished) {
                    *finished += 1;
                    let result = outcome.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                    if let Err(e) = result.and_then(|r| done(r, reader)) {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
                Ok::<(), anyhow::Error>(())
            };
        loop {
            // Decode ahead while the window has room.
            while frame_tx.is_some() && sent - finished < window {
                match reader.next_batch(1, frames) {
                    Ok(mut batch) => match batch.pop() {
                        Some(frame) => {
                            let tx = frame_tx.as_ref().expect("checked above");
                            // The workers only leave once the queue is closed.
                            tx.send((sent, frame)).expect("workers are running");
                            sent += 1;
                        }
                        None => {
                            frame_tx = None;
                        }
                    },
                    Err(e) => {
                        decode_error = Some(e.into());
                        frame_tx = None;
                    }
                }
                // Reports go out between decodes, not only when the window is full.
                while let Ok((seq, result)) = result_rx.try_recv() {
                    pending.insert(seq, result);
                }
                if let Err(e) = drain(&mut pending, &mut finished, reader) {
                    drop(frame_tx.take());
                    return Err(e);
                }
            }
            if finished == sent {
                break;
            }
            let (seq, result) = result_rx
                .recv()
                .expect("a worker holds every unfinished frame");
            pending.insert(seq, result);
            if let Err(e) = drain(&mut pending, &mut finished, reader) {
                drop(frame_tx.take());
                return Err(e);
            }
        }
        decode_error.map_or(Ok(()), Err)
    })
}

/// Workers of [`stream_frames`] that warm their heaps. Why a bound: a worker with no
/// frame to come (a capture of fewer frames than workers) warms its whole block, so on a
/// machine of many cores the warm-up would add that much memory per core; four bound it
/// at four blocks (48 MB at 12 MB a worker) and cover the machines it was measured on.
const WARMED_WORKERS: usize = 4;

/// The next item off the workers' queue. While `warmer` has pages left and no item is
/// ready, it warms one slice between polls; it is dropped (its pages handed back to the
/// heap) before an item is returned. The lock is held only while taking one item.
fn next_frame<T>(
    rx: &std::sync::Mutex<std::sync::mpsc::Receiver<T>>,
    warmer: &mut Option<crate::memory::HeapWarmer>,
) -> Result<T, std::sync::mpsc::RecvError> {
    use std::sync::mpsc::{RecvError, TryRecvError};
    use std::sync::TryLockError;
    while let Some(w) = warmer.as_mut() {
        let polled = match rx.try_lock() {
            Ok(rx) => rx.try_recv(),
            Err(TryLockError::Poisoned(e)) => e.into_inner().try_recv(),
            // The other worker waits on the queue: nothing for this one yet.
            Err(TryLockError::WouldBlock) => Err(TryRecvError::Empty),
        };
        if let Err(TryRecvError::Empty) = polled {
            if !w.step() {
                *warmer = None;
            }
        } else {
            // An item, or the queue closed: either way the warm-up is over.
            *warmer = None;
            return polled.map_err(|_| RecvError);
        }
    }
    rx.lock().unwrap_or_else(|e| e.into_inner()).recv()
}
