//! The files a processed frame writes on its own: its point cloud (PLY, LAS, LAZ, or a
//! scan in its input's format with a sidecar of fates) and its linkage tree; and its report
//! pieces, serialised by the worker that processed it.

use super::spool::SpoolEntry;
use super::Plan;
use crate::cloud::frames::CloudReader;
use crate::cloud::returns::TimeField;
use crate::pipeline::report::{FrameClusters, FrameReport, FATE_CODES};
use crate::pipeline::FrameResult;
use crate::writers::ply::{PlyColumns, PlyFrame};
use crate::writers::scan::ScanPoint;
use crate::writers::write_file;
use anyhow::Result;
use std::path::Path;

/// Writes a processed frame's own files (point cloud, linkage) into `dir` and returns its
/// report pieces and the frame's return buffer (for the reader to reuse).
pub(crate) fn frame_outputs(
    plan: &Plan,
    mut result: FrameResult,
    source: &str,
    dir: &Path,
    inputs: &[&Path],
    frame_file: bool,
) -> Result<(SpoolEntry, Vec<crate::frame::Return>)> {
    let clusters = FrameClusters {
        index: result.noisy.index,
        clusters: std::mem::take(&mut result.clusters),
    };
    let r = &result;
    // The frame file and the reports are a fork an idle worker may take (see
    // `crate::par::join`); the frame file's error comes first, as when they run in turn.
    let (ply, reports) = crate::par::join(
        || {
            if plan.ply && frame_file {
                write_ply(plan, r, source, dir, inputs)?;
            }
            Ok::<(), anyhow::Error>(())
        },
        || {
            if plan.linkage {
                write_linkage(plan, r, dir, inputs)?;
            }
            SpoolEntry::of(FrameReport::of(r), &clusters)
        },
    );
    ply?;
    let entry = reports?;
    // The frame's buffer goes back to the reader for the next frame.
    Ok((entry, result.noisy.clean))
}

/// Writes the frame's point cloud (PLY, LAS or LAZ) into `dir`.
fn write_ply(
    plan: &Plan,
    r: &FrameResult,
    source: &str,
    dir: &Path,
    inputs: &[&Path],
) -> Result<()> {
    let ground: Vec<u8> = r.ground.iter().map(|&g| u8::from(g)).collect();
    let path = dir.join(plan.output.file_name(r.noisy.index));
    let mut comments = vec![
        format!("config {}", plan.config.provenance()),
        format!("seed {}", plan.config.seed),
        format!(
            "fate codes: {}",
            FATE_CODES
                .iter()
                .enumerate()
                .map(|(i, c)| format!("{i} {c}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        "cause: index of the stage in the noise chain that decided the fate, 255 none or the \
         detection filters; range_clean 0 for added returns"
            .into(),
        "range is after noise, range_clean before; power is a fraction of emitted power".into(),
        "cluster -1 is ground or noise".into(),
    ];
    // The whole effective configuration, so that it can be rebuilt from the file alone.
    comments.extend(
        plan.config
            .effective_toml()
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| format!("effective-config {l}")),
    );
    let start = r.noisy.clean.first().map_or(0.0, |c| c.time);
    if plan.keep_dropped {
        // Every return: kept ones at their noisy position, dropped ones where they were.
        let mut returns = r.noisy.clean.clone();
        let mut ground_all = vec![0u8; returns.len()];
        let mut cluster_all = vec![-1i32; returns.len()];
        for (s, &k) in r.kept.iter().enumerate() {
            returns[k as usize] = r.survivors[s];
            ground_all[k as usize] = ground[s];
            cluster_all[k as usize] = r.labels[s];
        }
        let range_clean: Vec<f32> = (0..r.noisy.len()).map(|i| clean_range(r, i)).collect();
        let power: Vec<f32> = r.noisy.power.iter().map(|&p| p as f32).collect();
        let fate: Vec<u8> = r.noisy.fate.iter().map(|&f| f as u8).collect();
        let ply = PlyFrame {
            columns: PlyColumns {
                range_clean: Some(&range_clean),
                power: Some(&power),
                fate: Some(&fate),
                cause: Some(&r.noisy.cause),
                ground: Some(&ground_all),
                cluster: Some(&cluster_all),
            },
            comments: &comments,
            ..PlyFrame::new(&returns, source, r.noisy.index, start)
        };
        write_file(&*plan.output.document(ply), &path, inputs)?;
    } else {
        let range_clean: Vec<f32> = r.kept.iter().map(|&k| clean_range(r, k as usize)).collect();
        let power: Vec<f32> = r
            .kept
            .iter()
            .map(|&k| r.noisy.power[k as usize] as f32)
            .collect();
        // Chains that can report spurious echoes say which points are echoes; the
        // columns depend on the configuration only, never on the data.
        let echoes = plan.pipeline.chain().proposes_echoes();
        let (fate, cause): (Vec<u8>, Vec<u8>) = if echoes {
            r.kept
                .iter()
                .map(|&k| (r.noisy.fate[k as usize] as u8, r.noisy.cause[k as usize]))
                .unzip()
        } else {
            (Vec::new(), Vec::new())
        };
        let ply = PlyFrame {
            columns: PlyColumns {
                range_clean: Some(&range_clean),
                power: Some(&power),
                fate: echoes.then_some(&fate[..]),
                cause: echoes.then_some(&cause[..]),
                ground: Some(&ground),
                cluster: Some(&r.labels),
            },
            comments: &comments,
            ..PlyFrame::new(&r.survivors, source, r.noisy.index, start)
        };
        write_file(&*plan.output.document(ply), &path, inputs)?;
    }
    Ok(())
}

/// The kept returns of a processed scan as points to write back (`point` is the return's
/// index in the frame until [`write_scan`] maps it to the input's).
pub(crate) fn scan_points(r: &FrameResult) -> Vec<ScanPoint> {
    scan_points_of(r, |k| k.map(|k| k as u32))
}

/// The kept returns of a processed scan as points to write back, `point` the index in
/// the input (`order`: the input index of each return of the frame), and the order of
/// the rows in the input's point order (echoes the noise added after the recorded
/// points), as [`write_scan_files_in_order`] takes them: mapped and placed as the rows
/// are built (a pass over the rows each was a twentieth of a dataset run).
pub(crate) fn scan_points_in_input_order(
    r: &FrameResult,
    order: &[u32],
) -> (Vec<ScanPoint>, Vec<u32>) {
    let mut placing = Placing::new(order.len());
    let mut j = 0;
    let rows = scan_points_of(r, |k| {
        let point = k.and_then(|k| order.get(k).copied());
        placing.add(j, point);
        j += 1;
        point
    });
    let at = placing.order(&rows);
    (rows, at)
}

/// Writes a scan's noisy points as `format` to `scan` and their fates to `fates`, the
/// rows taken in `order`: both files in one pass over the rows where the format's
/// records are of fixed size, else the rows put in order first. The sidecar is committed
/// first, so that a scan file is there only once both are complete.
pub(crate) fn write_scan_files_in_order(
    format: crate::cloud::Format,
    rows: &[ScanPoint],
    order: &[u32],
    scan: &Path,
    fates: &Path,
    inputs: &[&Path],
) -> Result<()> {
    use crate::writers::atomic::AtomicFile;
    // No buffer of their own: the chunks come whole (64 KB), and a buffer would copy them.
    let mut fate_file = AtomicFile::with_buffer(fates, inputs, 0)?;
    let mut scan_file = AtomicFile::with_buffer(scan, inputs, 0)?;
    let written = crate::writers::scan::write_scan_and_fates(
        format,
        rows,
        order,
        &mut |b| scan_file.write_all(b),
        &mut |b| fate_file.write_all(b),
    );
    match written {
        Some(done) => {
            done?;
            fate_file.commit()?;
            scan_file.commit()?;
            Ok(())
        }
        None => {
            // Dropped uncommitted: their temporary files go.
            drop((fate_file, scan_file));
            let rows: Vec<ScanPoint> = order.iter().map(|&j| rows[j as usize]).collect();
            write_ordered_scan_files(format, &rows, None, scan, fates, inputs)
        }
    }
}

/// The kept returns of a processed scan as points to write back, `point` given by `index`
/// from the return's index in the frame (`None` for an added return), called a row at a
/// time in order.
fn scan_points_of(
    r: &FrameResult,
    mut index: impl FnMut(Option<usize>) -> Option<u32>,
) -> Vec<ScanPoint> {
    r.kept
        .iter()
        .zip(&r.survivors)
        .zip(r.ground.iter().zip(&r.labels))
        .map(|((&k, s), (&g, &cluster))| {
            let k = k as usize;
            ScanPoint {
                x: s.x,
                y: s.y,
                z: s.z,
                intensity: s.intensity,
                ring: u16::from(s.ring),
                point: index((k < r.noisy.clean_len).then_some(k)),
                fate: r.noisy.fate[k] as u8,
                cause: r.noisy.cause[k],
                range_clean: clean_range(r, k),
                ground: u8::from(g),
                cluster,
            }
        })
        .collect()
}

/// The times the sensor reports for the kept returns of a processed scan, in the order
/// of [`scan_points`]' rows (seconds, the returns' time base).
pub(crate) fn reported_times(r: &FrameResult) -> Vec<f64> {
    r.survivors.iter().map(|s| s.time).collect()
}

/// Writes frame `index` of a scan back in the scan's own format, in the input's point
/// order (echoes the noise added after the recorded points), with its sidecar of fates.
pub(crate) fn write_scan(
    reader: &CloudReader,
    rows: Vec<ScanPoint>,
    reported: &[f64],
    index: u32,
    dir: &Path,
    inputs: &[&Path],
) -> Result<()> {
    let format = reader.format();
    let stem = format!("frame_{index:05}");
    let scan = dir.join(format!(
        "{stem}.{}",
        crate::writers::scan::extension(format)
    ));
    let fates = dir.join(format!("{stem}.fate.csv"));
    let times = reader.times().map(|(field, stored)| ScanTimes {
        field,
        stored,
        reported,
    });
    let order = reader.order();
    let mut rows = rows;
    for p in &mut rows {
        p.point = p.point.and_then(|k| order.get(k as usize).copied());
    }
    write_scan_files(format, order.len(), rows, times, &scan, &fates, inputs)
}

/// The times of a scan placed by its time field, for writing them back in that field.
pub(crate) struct ScanTimes<'a> {
    /// The field.
    pub field: &'a TimeField,
    /// The points' times as stored, input order.
    pub stored: &'a [f64],
    /// The reported time of each row of [`scan_points`], in its order.
    pub reported: &'a [f64],
}

/// Writes a scan's noisy points as `format` to `scan` and their fates to `fates`, in the
/// input's point order (`rows`' `point`: the index in the input of `points`, `None` for
/// an added echo), echoes the noise added after the recorded points. The sidecar is
/// written first, so that a scan file is there only once both are complete. `times`:
/// where a time field placed the points, their times, written back in that field.
pub(crate) fn write_scan_files(
    format: crate::cloud::Format,
    points: usize,
    rows: Vec<ScanPoint>,
    times: Option<ScanTimes<'_>>,
    scan: &Path,
    fates: &Path,
    inputs: &[&Path],
) -> Result<()> {
    // A point whose time no stage changed gets its time as stored, exactly; the others
    // (a clock's error, an added echo) their return's time in the field's unit. In row
    // order, before the rows are put in input order (then these with them).
    // One reported time a row (`reported_times` of the same result); anything else
    // writes no time rather than misplacing one.
    let times = times.filter(|t| t.reported.len() == rows.len());
    let stored: Option<Vec<f64>> = times.map(|t| {
        rows.iter()
            .zip(t.reported)
            .map(
                |(p, &time)| match p.point.and_then(|i| t.stored.get(i as usize)) {
                    Some(&s) if t.field.to_return(s) == time => s,
                    _ => t.field.to_file(time),
                },
            )
            .collect()
    });
    let (rows, stored) = in_input_order(rows, stored, points);
    write_ordered_scan_files(format, &rows, stored.as_deref(), scan, fates, inputs)
}

/// Writes a scan's noisy points as `format` to `scan` and their fates to `fates`, in
/// the order of `rows` (and `times`, one a row, the field's values where given). The
/// sidecar is written first, so that a scan file is there only once both are complete.
pub(crate) fn write_ordered_scan_files(
    format: crate::cloud::Format,
    rows: &[ScanPoint],
    times: Option<&[f64]>,
    scan: &Path,
    fates: &Path,
    inputs: &[&Path],
) -> Result<()> {
    use crate::writers::scan::{Fates, Scan};
    write_file(&Fates { points: rows }, fates, inputs)?;
    write_file(
        &Scan {
            format,
            points: rows,
            times,
        },
        scan,
        inputs,
    )?;
    Ok(())
}

/// `rows` (and `times`, one a row) with the recorded points in input order (`point`,
/// below `points`), then the added echoes in their order: placed by index rather than
/// sorted (a stable sort was a tenth of a dataset run), which gives the same order as
/// long as no input point is there twice; a stable sort where one is.
fn in_input_order(
    rows: Vec<ScanPoint>,
    times: Option<Vec<f64>>,
    points: usize,
) -> (Vec<ScanPoint>, Option<Vec<f64>>) {
    let mut placing = Placing::new(points);
    for (j, p) in rows.iter().enumerate() {
        placing.add(j, p.point);
    }
    let order = placing.order(&rows);
    let gather = |j: &u32| rows[*j as usize];
    let times = times.map(|t| order.iter().map(|&j| t[j as usize]).collect());
    (order.iter().map(gather).collect(), times)
}

/// The rows of a scan placed at their points' input indices as they come, for
/// [`in_input_order`].
struct Placing {
    /// Per input point, the row that holds it ([`Placing::NONE`]: none).
    at: Vec<u32>,
    /// The rows of added echoes, in their order.
    echoes: Vec<u32>,
    /// Whether every row so far had an input point of its own, or none.
    placed: bool,
}

impl Placing {
    const NONE: u32 = u32::MAX;

    fn new(points: usize) -> Self {
        Placing {
            at: vec![Self::NONE; points],
            echoes: Vec::new(),
            placed: true,
        }
    }

    /// Places row `j`, of input point `point` (`None`: an added echo).
    #[inline]
    fn add(&mut self, j: usize, point: Option<u32>) {
        match point.and_then(|i| self.at.get_mut(i as usize)) {
            Some(slot) if *slot == Self::NONE => *slot = j as u32,
            None if point.is_none() => self.echoes.push(j as u32),
            _ => self.placed = false,
        }
    }

    /// The rows in output order: the recorded points by input index, then the echoes;
    /// a stable sort of `rows` by point where some input point was there twice.
    fn order(self, rows: &[ScanPoint]) -> Vec<u32> {
        if self.placed {
            // Sized up front: a filtered iterator collects by doubling, and the moves of
            // the growing vector were a sixth of this function.
            let mut order = Vec::with_capacity(rows.len());
            order.extend(self.at.iter().copied().filter(|&j| j != Self::NONE));
            order.extend_from_slice(&self.echoes);
            order
        } else {
            let mut order: Vec<u32> = (0..rows.len() as u32).collect();
            order.sort_by_key(|&j| rows[j as usize].point.map_or((1, 0), |i| (0, i)));
            order
        }
    }
}

/// Range of return `i` before noise: 0 for a return a stage added (it has no clean origin).
fn clean_range(r: &FrameResult, i: usize) -> f32 {
    if i < r.noisy.clean_len {
        r.noisy.clean[i].range
    } else {
        0.0
    }
}

/// Writes the frame's single-linkage merge tree into `dir`.
fn write_linkage(plan: &Plan, r: &FrameResult, dir: &Path, inputs: &[&Path]) -> Result<()> {
    let points: Vec<[f32; 3]> = r
        .survivors
        .iter()
        .zip(&r.ground)
        .filter(|(_, &g)| !g)
        .map(|(s, _)| [s.x, s.y, s.z])
        .collect();
    let z = crate::cluster::linkage(&points, plan.config.cluster.max_edge_m)?;
    let path = dir.join(format!("linkage_{:05}.csv", r.noisy.index));
    crate::writers::atomic::write_atomically(&path, inputs, |out| {
        crate::cluster::write_linkage_csv(out, &z)
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn row(point: Option<u32>, cluster: i32) -> ScanPoint {
        ScanPoint {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            intensity: 0,
            ring: 0,
            point,
            fate: 0,
            cause: 255,
            range_clean: 0.0,
            ground: 0,
            cluster,
        }
    }

    #[test]
    fn rows_are_placed_as_the_stable_sort_orders_them() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for case in 0..200 {
            let points = rng.random_range(0..300usize);
            // A subset of the input points, shuffled, with echoes among them; in some
            // cases a point twice or one beyond the input (the sort's order then).
            let mut rows: Vec<ScanPoint> = (0..points as u32)
                .filter(|_| rng.random_bool(0.7))
                .map(|i| row(Some(i), 0))
                .collect();
            for k in 0..rng.random_range(0..20) {
                rows.push(row(None, k));
            }
            if case % 5 == 0 && !rows.is_empty() {
                let i = rng.random_range(0..rows.len());
                rows.push(row(rows[i].point, -7));
            }
            if case % 7 == 0 {
                rows.push(row(Some(points as u32 + 3), -9));
            }
            for i in (1..rows.len()).rev() {
                rows.swap(i, rng.random_range(0..=i));
            }
            let mut want = rows.clone();
            want.sort_by_key(|p| p.point.map_or((1, 0), |i| (0, i)));
            // Each row's time (here its index) goes with it.
            let times: Vec<f64> = (0..rows.len()).map(|j| j as f64).collect();
            let (got, got_times) = in_input_order(rows.clone(), Some(times), points);
            assert_eq!(got, want, "case {case}");
            for (p, &t) in got.iter().zip(&got_times.unwrap()) {
                assert_eq!(*p, rows[t as usize], "case {case}");
            }
        }
    }
}
