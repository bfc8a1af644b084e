//! The library's error type: every user-facing failure names the file it came
//! from and, where there is one, the key or line inside it.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file a problem lies.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    /// The whole file (it is missing, unreadable, or of the wrong kind).
    File,
    /// A key path inside a TOML file, e.g. `light[1].intensity.spot.cutoff_deg`.
    Key(String),
    /// A 1-based line number inside a text file (OBJ, IES).
    Line(usize),
}

/// An error in the user's input or environment. Displayed as
/// `file: key: message` so that a user knows exactly what to edit.
#[derive(Debug, Clone)]
pub struct Error {
    pub file: PathBuf,
    pub location: Location,
    pub message: String,
}

impl Error {
    /// An error about a whole file.
    pub fn file(file: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error {
            file: file.as_ref().to_path_buf(),
            location: Location::File,
            message: message.into(),
        }
    }

    /// An error at a key path of a TOML file.
    pub fn key(file: impl AsRef<Path>, key: impl Into<String>, message: impl Into<String>) -> Self {
        Error {
            file: file.as_ref().to_path_buf(),
            location: Location::Key(key.into()),
            message: message.into(),
        }
    }

    /// An error at a line of a text file.
    pub fn line(file: impl AsRef<Path>, line: usize, message: impl Into<String>) -> Self {
        Error {
            file: file.as_ref().to_path_buf(),
            location: Location::Line(line),
            message: message.into(),
        }
    }

    /// An I/O failure on `file`, with the operating system's reason.
    pub fn io(file: impl AsRef<Path>, err: &std::io::Error) -> Self {
        let what = match err.kind() {
            std::io::ErrorKind::NotFound => "file not found".to_string(),
            std::io::ErrorKind::PermissionDenied => "permission denied".to_string(),
            _ => err.to_string(),
        };
        Error::file(file, what)
    }

    /// Re-attributes this error to the key of a referring file, keeping the
    /// original as the cause: `scene.toml: real[0].mesh: room.obj: line 3: ...`.
    pub fn within(self, file: impl AsRef<Path>, key: impl Into<String>) -> Self {
        Error::key(file, key, self.to_string())
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = self.file.display();
        match &self.location {
            Location::File => write!(f, "{file}: {}", self.message),
            Location::Key(key) => write!(f, "{file}: {key}: {}", self.message),
            Location::Line(line) => write!(f, "{file}: line {line}: {}", self.message),
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T, E = Error> = std::result::Result<T, E>;
