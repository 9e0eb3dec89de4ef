//! `sweep`: the library's sweep into an output folder, called without the command line.

use crate::*;

/// Runs the library's sweep (what `lidar-noise sweep` runs, silently) of `captures` into
/// `output`, where its tidy table then is: `varies` are `KEY=V1,V2,...`, `sets`
/// `KEY=VALUE`, `seeds` and `frames` as the command's options. ValueError for bad options,
/// OSError for files. The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (captures, output, config=None, varies=Vec::new(), sets=Vec::new(), seeds=None, frames=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sweep(
    py: Python<'_>,
    captures: Vec<PathBuf>,
    output: PathBuf,
    config: Option<PathBuf>,
    varies: Vec<String>,
    sets: Vec<String>,
    seeds: Option<String>,
    frames: Option<String>,
) -> PyResult<()> {
    use lidar_noise::sweep::folder::SweepRequest;
    use lidar_noise::sweep::plan::{parse_seeds, Vary};
    let request = (|| -> Result<SweepRequest, Error> {
        Ok(SweepRequest {
            config,
            sets,
            varies: varies
                .iter()
                .map(|v| Vary::parse(v))
                .collect::<Result<_, _>>()?,
            seeds: seeds.as_deref().map(parse_seeds).transpose()?,
            frames: match &frames {
                Some(text) => lidar_noise::range::parse_range("--frames", text)?,
                None => lidar_noise::range::ALL_FRAMES,
            },
            ..SweepRequest::new(captures, output)
        })
    })()
    .map_err(py_err)?;
    py.detach(|| lidar_noise::sweep::folder::sweep(&request, &lidar_noise::observe::Silent))
        .map_err(|e| {
            let message = lidar_noise::error::message_of(&e);
            let io = e.chain().any(|c| {
                matches!(c.downcast_ref::<Error>(), Some(Error::Io { .. }))
                    || c.downcast_ref::<std::io::Error>().is_some()
            });
            if io {
                PyOSError::new_err(message)
            } else {
                PyValueError::new_err(message)
            }
        })
}
