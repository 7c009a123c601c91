//! Error type of the simulator. Every failure caused by external input (a URDF file, a config value,
//! an action with NaN) is reported as a [`SimError`] naming what was wrong; nothing here panics on it.

use std::path::PathBuf;

/// Everything that can go wrong in `equiarm_sim`.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A URDF (or other asset) file could not be read.
    #[error("reading {file}: {cause}")]
    Read {
        /// Path of the file that could not be read.
        file: PathBuf,
        /// The I/O error (not found, permission denied, not UTF-8...).
        cause: std::io::Error,
    },
    /// The XML of a URDF file did not parse into the URDF data model (bad number, unknown joint type,
    /// missing attribute...). `message` is the parser's, which names the element.
    #[error("parsing URDF {file}: {message}")]
    UrdfParse {
        /// The file: its path, or `urdf/<name>.urdf` for a bundled copy.
        file: String,
        /// The parser's error message.
        message: String,
    },
    /// The URDF parsed, but one element is not usable by the simulator.
    #[error("URDF {file}: {element}: {message}")]
    UrdfInvalid {
        /// The file: its path, or `urdf/<name>.urdf` for a bundled copy.
        file: String,
        /// The offending element, e.g. ``link `palm` <collision> #0`` or, for an XML error located by the
        /// loader's own scan, ``line 5: joint `j` <joint type="telescopic">``.
        element: String,
        /// What is wrong with it.
        message: String,
    },
    /// A configuration value is out of its domain.
    #[error("invalid config value `{field}`: {message}")]
    Config {
        /// Name of the offending config field or argument (`dt`, `elevation_deg`, `max_steps`, `seeds`...).
        field: &'static str,
        /// What is wrong: usually the rejected value and the domain it must lie in.
        message: String,
    },
    /// An action had a non-finite component.
    #[error("invalid action: {0}")]
    Action(String),
    /// `step` was called before `reset`.
    #[error("the environment must be reset before it is stepped")]
    NotReset,
    /// `step` was called after the episode ended (success, an invalid state or the step limit).
    #[error("the episode ended after {steps} steps: reset the environment before stepping it again")]
    EpisodeOver {
        /// Steps the ended episode took.
        steps: u32,
    },
    /// Writing an image failed.
    #[error("writing image {file}: {message}")]
    Image {
        /// The PNG file, or the directory that could not be created.
        file: PathBuf,
        /// The error of the image encoder or the file system.
        message: String,
    },
}

/// `Result` with [`SimError`] as the default error type.
pub type Result<T, E = SimError> = std::result::Result<T, E>;
