//! How long library calls ([`crate::engine::run`], [`crate::sweep::folder::sweep`])
//! report while they work: warnings, status lines and progress go to one [`Observer`]
//! that the caller implements (the command line prints to stderr and draws progress
//! bars; Python stays silent). The library itself never prints.

/// A count of work done whose progress an [`Observer`] may show.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Counter {
    /// Frames of a capture (of every cell of a capture, in a sweep).
    Frames,
    /// Files of a dataset folder.
    Scans,
    /// Cells of a sweep.
    Cells,
}

impl Counter {
    /// The unit a progress display names.
    pub fn unit(self) -> &'static str {
        match self {
            Counter::Frames => "frames",
            Counter::Scans => "scans",
            Counter::Cells => "cells",
        }
    }
}

/// Receives what a call reports, from several threads; every method does nothing unless
/// implemented.
pub trait Observer: Sync {
    /// Something the user should know that does not stop the work.
    fn warn(&self, _message: &str) {}
    /// A line saying what the call did (the units a shard owns, where results are).
    fn note(&self, _message: &str) {}
    /// Whether progress is shown: totals that cost work to know are counted only then.
    fn shows_progress(&self) -> bool {
        false
    }
    /// `counter` starts (again) from 0, with its total when known.
    fn start(&self, _counter: Counter, _total: Option<u64>) {}
    /// The total of `counter` is now `total`.
    fn set_total(&self, _counter: Counter, _total: u64) {}
    /// What `counter` is counting now (a capture's name).
    fn label(&self, _counter: Counter, _label: &str) {}
    /// `n` more units of `counter` are done.
    fn advance(&self, _counter: Counter, _n: u64) {}
    /// `counter` is done: its display can go.
    fn finish(&self, _counter: Counter) {}
}

/// An observer that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Observer for Silent {}
