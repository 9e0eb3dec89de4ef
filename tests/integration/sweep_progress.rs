//! A sweep's progress knows its totals before work starts: the cells of each capture and
//! the frames every cell runs (issue 33: the frames bar showed "31/0 frames" until the
//! first batch of cells was done).

use crate::common;

use lidar_noise::observe::{Counter, Observer};
use lidar_noise::sensor::frames::DecoderOptions;
use lidar_noise::sweep::plan::{BaseConfig, Vary};
use lidar_noise::sweep::run::{run, CaptureInput, SweepSettings};
use std::sync::Mutex;

#[derive(Debug, PartialEq)]
enum Event {
    Start(Counter, Option<u64>),
    Total(Counter, u64),
    Advance(Counter),
}

#[derive(Default)]
struct Recorder(Mutex<Vec<Event>>);

impl Observer for Recorder {
    fn start(&self, counter: Counter, total: Option<u64>) {
        self.0.lock().unwrap().push(Event::Start(counter, total));
    }
    fn set_total(&self, counter: Counter, total: u64) {
        self.0.lock().unwrap().push(Event::Total(counter, total));
    }
    fn advance(&self, counter: Counter, n: u64) {
        for _ in 0..n {
            self.0.lock().unwrap().push(Event::Advance(counter));
        }
    }
}

#[test]
fn frames_total_is_known_before_the_first_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (base, _) = BaseConfig::load(None, &[]).unwrap();
    let settings = SweepSettings {
        base,
        varies: vec![Vary::parse("rain.rate_mm_h=0,3,7").unwrap()],
        seeds: vec![1, 2],
        decoder: DecoderOptions::default(),
        frames: 0..=2,
        output: dir.path().to_path_buf(),
        bands: lidar_noise::score::metrics::DEFAULT_BANDS.to_vec(),
        chunk_frames: None,
    };
    let captures = vec![CaptureInput {
        name: "crossroad".into(),
        path: common::crossroad(),
        labels: None,
    }];
    let rec = Recorder::default();
    run(&settings, &captures, &rec).unwrap();
    let events = rec.0.into_inner().unwrap();
    assert_eq!(
        events[0],
        Event::Start(Counter::Cells, Some(6)),
        "{events:?}"
    );
    let first_frame = events
        .iter()
        .position(|e| *e == Event::Advance(Counter::Frames))
        .expect("frames run");
    let totals: Vec<u64> = events
        .iter()
        .filter_map(|e| match e {
            Event::Total(Counter::Frames, n) => Some(*n),
            _ => None,
        })
        .collect();
    // Given once, before any work: the bar's length does not move under the user's eyes.
    assert_eq!(totals.len(), 1, "{events:?}");
    let given = events
        .iter()
        .position(|e| matches!(e, Event::Total(Counter::Frames, _)))
        .unwrap();
    assert!(
        given < first_frame,
        "the frames' total comes before any work: {events:?}"
    );
    let count = |e: Event| events.iter().filter(|x| **x == e).count() as u64;
    // The total covers every pending cell: frames run = total.
    assert_eq!(count(Event::Advance(Counter::Frames)), totals[0]);
    assert_eq!(totals[0] % 6, 0, "frames per cell x cells");
    assert_eq!(count(Event::Advance(Counter::Cells)), 6);
}
