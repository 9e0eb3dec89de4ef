//! A sweep's progress knows its totals before work starts: the cells of each capture and
//! the frames every cell runs (issue 33: the frames bar showed "31/0 frames" until the
//! first batch of cells was done).

mod common;

use lidar_noise::sensor::frames::DecoderOptions;
use lidar_noise::sweep::plan::{BaseConfig, Vary};
use lidar_noise::sweep::run::{run, CaptureInput, Observer, SweepSettings};
use std::sync::Mutex;

#[derive(Debug, PartialEq)]
enum Event {
    Capture(u64),
    FramesTotal(u64),
    FrameDone,
    CellDone,
}

#[derive(Default)]
struct Recorder(Mutex<Vec<Event>>);

impl Observer for Recorder {
    fn capture(&self, _name: &str, cells: u64) {
        self.0.lock().unwrap().push(Event::Capture(cells));
    }
    fn frames_total(&self, n: u64) {
        self.0.lock().unwrap().push(Event::FramesTotal(n));
    }
    fn frame_done(&self) {
        self.0.lock().unwrap().push(Event::FrameDone);
    }
    fn cell_done(&self) {
        self.0.lock().unwrap().push(Event::CellDone);
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
        bands: lidar_noise::sweep::metrics::DEFAULT_BANDS.to_vec(),
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
    assert_eq!(events[0], Event::Capture(6), "{events:?}");
    let Event::FramesTotal(n) = events[1] else {
        panic!("the frames' total comes second, before any work: {events:?}");
    };
    let total = |e: Event| events.iter().filter(|x| **x == e).count() as u64;
    assert_eq!(total(Event::FrameDone), n * 6, "frames run = total x cells");
    assert_eq!(total(Event::CellDone), 6);
    // Given once: the bar's length does not move under the user's eyes.
    assert_eq!(
        events
            .iter()
            .filter(|e| matches!(e, Event::FramesTotal(_)))
            .count(),
        1
    );
}
