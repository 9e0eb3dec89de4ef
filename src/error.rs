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
    /// A capture file is malformed or not an HDL-32E capture.
    #[error("{path}: {message}")]
    Capture {
        /// The capture file.
        path: PathBuf,
        /// What is wrong and where (packet number, byte offset).
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
