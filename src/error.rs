//! Error types shared by the library.

use std::path::PathBuf;

/// Errors the library reports to the user.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An input or output file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file involved.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A capture file is malformed or not the capture its reader decodes.
    #[error("{path}: {message}")]
    Capture {
        /// The capture file.
        path: PathBuf,
        /// What is wrong and where (packet number, byte offset).
        message: String,
    },
    /// A capture of another sensor than the reader decodes (the message names it).
    #[error("{path}: {message}")]
    OtherSensor {
        /// The capture file.
        path: PathBuf,
        /// What the capture is.
        message: String,
    },
    /// A configuration or calibration file is invalid.
    #[error("{path}: {message}")]
    Config {
        /// The configuration file.
        path: PathBuf,
        /// What is wrong and where (key and line).
        message: String,
    },
    /// Any other invalid input, described for the user.
    #[error("{0}")]
    Invalid(String),
}

/// Result with the library's error type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// Largest configuration, calibration, scene or labels file read (bytes): far above any
/// real one (a configuration is a few kB, a labels file of a long synthesized capture a
/// few MB), and small enough that `-c /dev/zero` is refused at once instead of filling
/// memory.
pub const MAX_TEXT_INPUT_BYTES: u64 = 64 << 20;

/// Reads the whole of `path`, refusing more than [`MAX_TEXT_INPUT_BYTES`] (a device such
/// as `/dev/zero` is refused after that many bytes, not read until memory runs out).
pub fn read_bounded(path: &std::path::Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut bytes = Vec::new();
    file.take(MAX_TEXT_INPUT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > MAX_TEXT_INPUT_BYTES {
        return Err(Error::Invalid(format!(
            "{}: larger than {} MiB, far more than such a file holds: is it the right file?",
            path.display(),
            MAX_TEXT_INPUT_BYTES >> 20
        )));
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text (the error names the byte offset of the first invalid
/// byte).
pub fn read_text_bounded(path: &std::path::Path) -> Result<String> {
    String::from_utf8(read_bounded(path)?).map_err(|e| Error::Config {
        path: path.to_path_buf(),
        message: format!(
            "not a text file (invalid UTF-8 at byte {})",
            e.utf8_error().valid_up_to()
        ),
    })
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message
/// already ends with (our errors print their source themselves, so `{:#}` said it twice):
/// how the command line and Python show an error.
pub fn message_of(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.ends_with(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

/// The first ten of `items` joined by commas, then ", and N more" for the rest: how an
/// error names a long list of missing parts.
pub(crate) fn first_ten(items: &[String]) -> String {
    let shown: Vec<&str> = items.iter().take(10).map(String::as_str).collect();
    let mut text = shown.join(", ");
    if items.len() > 10 {
        text.push_str(&format!(", and {} more", items.len() - 10));
    }
    text
}
