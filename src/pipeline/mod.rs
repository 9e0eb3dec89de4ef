//! The whole per-frame pipeline: noise chain and detection filters, ground removal,
//! clustering and the cluster report. One frame in, one [`FrameResult`] out; frames are
//! independent, so any number of threads gives the same results.

use crate::cluster::{self, ClusterInfo, ClusterOptions, ObjectRule};
use crate::config::Config;
use crate::error::Result;
use crate::frame::Frame;
use crate::frame::Return;
use crate::ground::{self, GroundOptions};
use crate::noise::{stage_rng, stage_tags, NoiseChain, NoiseSummary, NoisyFrame};
use serde::Serialize;

pub mod report;

/// The configured pipeline, shareable between threads.
#[derive(Clone, Debug)]
pub struct Pipeline {
    chain: NoiseChain,
    ground: GroundOptions,
    cluster: ClusterOptions,
    objects: ObjectRule,
    seed: u64,
    ground_tag: u32,
}

/// Counts of one frame (or, merged, of a capture) after every stage.
#[derive(Clone, Debug, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct StageCounts {
    /// Returns kept by the noise chain and the detection filters.
    pub kept: u64,
    /// Kept returns labelled ground.
    pub ground: u64,
    /// Kept returns not labelled ground (the clustering's input).
    pub non_ground: u64,
    /// Clusters with at least `min_points` returns.
    pub clusters: u64,
    /// Of those, objects (clusters passing the `[cluster]` object rule).
    pub objects: u64,
    /// Non-ground returns in clusters smaller than `min_points`.
    pub noise_points: u64,
    /// Non-ground returns in clusters (objects).
    pub cluster_points: u64,
}

impl StageCounts {
    /// Adds another frame's counts.
    pub fn merge(&mut self, o: &StageCounts) {
        self.kept += o.kept;
        self.ground += o.ground;
        self.non_ground += o.non_ground;
        self.clusters += o.clusters;
        self.objects += o.objects;
        self.noise_points += o.noise_points;
        self.cluster_points += o.cluster_points;
    }

    /// Share of kept returns labelled ground (0 when nothing was kept).
    pub fn ground_fraction(&self) -> f64 {
        if self.kept == 0 {
            0.0
        } else {
            self.ground as f64 / self.kept as f64
        }
    }
}

/// Everything the pipeline found in one frame.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// Every return of the frame with its fate, noisy range and power.
    pub noisy: NoisyFrame,
    /// The kept returns with noisy range and coordinates, in capture order.
    pub survivors: Vec<Return>,
    /// Index in `noisy.clean` of each survivor.
    pub kept: Vec<u32>,
    /// Ground label of each survivor.
    pub ground: Vec<bool>,
    /// Cluster id of each survivor: -1 for ground and for noise.
    pub labels: Vec<i32>,
    /// The clusters, sorted by id, each flagged object or not.
    pub clusters: Vec<ClusterInfo>,
    /// Counts after each stage.
    pub counts: StageCounts,
    /// What the noise chain and the filters did.
    pub noise: NoiseSummary,
}

impl Pipeline {
    /// Builds the pipeline of a validated configuration.
    pub fn new(config: &Config) -> Self {
        Pipeline {
            chain: NoiseChain::new(config),
            ground: config.ground.clone(),
            cluster: config.cluster,
            objects: config.objects,
            seed: config.seed,
            // Ground has its own stream, keyed like a stage named "ground".
            ground_tag: stage_tags(&["ground"])[0],
        }
    }

    /// The pipeline for frames of a sensor with `lasers` lasers (see
    /// [`NoiseChain::for_lasers`]).
    pub fn for_lasers(&self, lasers: usize) -> Result<Self, String> {
        Ok(Pipeline {
            chain: self.chain.clone().for_lasers(lasers)?,
            ..self.clone()
        })
    }

    /// The pipeline for frames of `sensor` (see [`NoiseChain::for_sensor`]).
    pub fn for_sensor(&self, sensor: &crate::sensor::SensorModel) -> Result<Self, String> {
        Ok(Pipeline {
            chain: self.chain.clone().for_sensor(sensor)?,
            ..self.clone()
        })
    }

    /// The noise chain.
    pub fn chain(&self) -> &NoiseChain {
        &self.chain
    }

    /// Runs every stage on one frame. On a thread of a rayon pool, the parts of the frame
    /// that do not depend on each other are forks an idle thread may take (see
    /// [`crate::par::join`]); the results are the same on any thread.
    pub fn process(&self, frame: Frame) -> Result<FrameResult> {
        self.process_with(frame, true)
    }

    /// [`Pipeline::process`] without what only the reports read: the clusters'
    /// descriptions (`clusters` empty, `counts.objects` 0) and the noise summary (`noise`
    /// empty). For a dataset run, which writes each scan's points, fates, ground and
    /// cluster labels (and scores them against ground truth), and where the two were a
    /// tenth of a KITTI scan's time.
    pub fn process_points(&self, frame: Frame) -> Result<FrameResult> {
        self.process_with(frame, false)
    }

    /// The pipeline on one frame; `report` adds the clusters' descriptions and the noise
    /// summary.
    fn process_with(&self, frame: Frame, report: bool) -> Result<FrameResult> {
        let noisy = self.chain.process_owned(frame);
        // The noise summary and the survivors' indices read the noisy frame only: they are
        // the fork beside ground removal and clustering.
        let (rest, (noise, kept)) = crate::par::join(
            || self.segment(&noisy, report),
            || {
                let noise = if report {
                    noisy.summary()
                } else {
                    NoiseSummary::default()
                };
                (noise, noisy.kept_indices())
            },
        );
        let rest = rest?;
        debug_assert_eq!(kept.len(), rest.survivors.len());
        Ok(FrameResult {
            noisy,
            survivors: rest.survivors,
            kept,
            ground: rest.ground,
            labels: rest.labels,
            clusters: rest.clusters,
            counts: rest.counts,
            noise,
        })
    }

    /// Survivors, ground, clusters and counts of a noisy frame; the clusters described
    /// only when `describe`.
    fn segment(&self, noisy: &NoisyFrame, describe: bool) -> Result<Segmented> {
        let survivors = noisy.survivors();
        let mut rng = stage_rng(self.seed, noisy.index, self.ground_tag);
        let ground = ground::segment(&survivors, &self.ground, &mut rng);
        // The non-ground survivors by index, and their points for the clustering, in one
        // branch-free pass (as `kept_indices`); the clusters are described from
        // `survivors` through the same indices instead of a copy of the returns.
        // Both buffers are this worker's scratch from its earlier frames: they only grow,
        // so a frame neither zero-fills them nor touches fresh pages.
        let (mut non_ground_buf, mut points_buf) = SCRATCH.take();
        let n = survivors.len();
        if non_ground_buf.len() < n {
            non_ground_buf.resize(n, 0);
            points_buf.resize(n, [0.0; 3]);
        }
        let (non_ground, points) = (&mut non_ground_buf[..n], &mut points_buf[..n]);
        let mut k = 0;
        for (i, (s, &g)) in survivors.iter().zip(&ground).enumerate() {
            non_ground[k] = i as u32;
            points[k] = [s.x, s.y, s.z];
            k += usize::from(!g);
        }
        let (non_ground, points) = (&non_ground[..k], &points[..k]);
        let clustering = cluster::cluster(points, &self.cluster)?;
        let mut labels = vec![-1i32; survivors.len()];
        for (&i, &label) in non_ground.iter().zip(&clustering.labels) {
            labels[i as usize] = label;
        }
        let mut clusters = if describe {
            cluster::describe_subset(&survivors, non_ground, &clustering.labels)?
        } else {
            Vec::new()
        };
        for c in &mut clusters {
            c.object = self.objects.is_object(c, self.cluster.min_points);
        }
        let counts = StageCounts {
            kept: survivors.len() as u64,
            ground: (survivors.len() - non_ground.len()) as u64,
            non_ground: non_ground.len() as u64,
            clusters: clustering.n_clusters as u64,
            objects: clusters.iter().filter(|c| c.object).count() as u64,
            noise_points: clustering.n_noise_points as u64,
            cluster_points: (non_ground.len() - clustering.n_noise_points) as u64,
        };
        SCRATCH.set((non_ground_buf, points_buf));
        Ok(Segmented {
            survivors,
            ground,
            labels,
            clusters,
            counts,
        })
    }
}

thread_local! {
    /// A worker's buffers for the non-ground indices and points of [`Pipeline::segment`],
    /// kept from frame to frame (a nested call on the same thread finds them taken and
    /// starts empty ones).
    static SCRATCH: std::cell::Cell<(Vec<u32>, Vec<[f32; 3]>)> =
        const { std::cell::Cell::new((Vec::new(), Vec::new())) };
}

/// A [`FrameResult`] but for the noise summary and the survivors' indices.
struct Segmented {
    survivors: Vec<Return>,
    ground: Vec<bool>,
    labels: Vec<i32>,
    clusters: Vec<ClusterInfo>,
    counts: StageCounts,
}
