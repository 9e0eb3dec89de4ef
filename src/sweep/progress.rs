//! A sweep's progress as an [`Observer`] sees it: cells, and the frames of the cells of
//! the current capture, with totals known as early as the sweep can know them.

use crate::observe::{Counter, Observer};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Turns the sweep's events into counts for an observer (called from several threads).
pub(crate) struct Progress<'a> {
    observer: &'a dyn Observer,
    /// With `--chunk-frames` the units are known capture by capture (frames are counted).
    chunked: bool,
    /// Cells to go through in all (grows capture by capture with chunks).
    cells_total: AtomicU64,
    cells_done: AtomicU64,
    /// Frames done in the current capture.
    frames_done: AtomicU64,
    /// Cells still to compute in the current capture.
    pending_here: AtomicU64,
}

impl<'a> Progress<'a> {
    /// Starts the counts: `own` cells fall to this call (ignored with chunks).
    pub(crate) fn start(observer: &'a dyn Observer, chunked: bool, own: u64) -> Self {
        let cells = if chunked { 0 } else { own };
        observer.start(Counter::Cells, Some(cells));
        observer.start(Counter::Frames, Some(0));
        Progress {
            observer,
            chunked,
            cells_total: AtomicU64::new(cells),
            cells_done: AtomicU64::new(0),
            frames_done: AtomicU64::new(0),
            pending_here: AtomicU64::new(0),
        }
    }

    /// A capture starts with `cells` cells to compute.
    pub(crate) fn capture(&self, name: &str, cells: u64) {
        if self.chunked {
            let total = self.cells_total.fetch_add(cells, Relaxed) + cells;
            self.observer.set_total(Counter::Cells, total);
        }
        self.observer.label(Counter::Cells, name);
        self.frames_done.store(0, Relaxed);
        self.observer.start(Counter::Frames, Some(0));
        self.pending_here.store(cells, Relaxed);
    }

    /// Each pending cell of this capture runs `n` frames: known before any of them
    /// starts, except with chunks, where after the first.
    pub(crate) fn frames_total(&self, n: u64) {
        let cells = if self.chunked {
            // Units still to run, each of n frames.
            let total = self.cells_total.load(Relaxed);
            total.saturating_sub(self.cells_done.load(Relaxed))
        } else {
            self.pending_here.load(Relaxed)
        };
        let done = self.frames_done.load(Relaxed);
        self.observer.set_total(Counter::Frames, done + n * cells);
    }

    /// One frame of one cell is done.
    pub(crate) fn frame_done(&self) {
        self.frames_done.fetch_add(1, Relaxed);
        self.observer.advance(Counter::Frames, 1);
    }

    /// One cell is done (computed or loaded).
    pub(crate) fn cell_done(&self) {
        self.cells_done.fetch_add(1, Relaxed);
        self.observer.advance(Counter::Cells, 1);
    }

    /// Something the user should know (a cell file that did not verify).
    pub(crate) fn warn(&self, message: &str) {
        self.observer.warn(message);
    }

    /// The sweep's computing is over.
    pub(crate) fn finish(&self) {
        self.observer.finish(Counter::Frames);
        self.observer.finish(Counter::Cells);
    }
}
