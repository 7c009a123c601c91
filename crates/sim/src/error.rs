//! Error type of the simulator. Every failure caused by external input (a URDF file, a config value,
//! an action with NaN) is reported as a [`SimError`] naming what was wrong; nothing here panics on it.

use std::path::PathBuf;

/// Everything that can go wrong in `equiarm_sim`.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A URDF (or other asset) file could not be read.
    #[error("reading {file}: {source}")]
    Read {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The XML of a URDF file did not parse into the URDF data model (bad number, unknown joint type,
    /// missing attribute...). `message` is the parser's, which names the element.
    #[error("parsing URDF {file}: {message}")]
    UrdfParse { file: String, message: String },
    /// The URDF parsed, but one element is not usable by the simulator.
    #[error("URDF {file}: {element}: {message}")]
    UrdfInvalid { file: String, element: String, message: String },
    /// A configuration value is out of its domain.
    #[error("invalid config value `{field}`: {message}")]
    Config { field: &'static str, message: String },
    /// An action had a non-finite component.
    #[error("invalid action: {0}")]
    Action(String),
    /// `step` was called before `reset`.
    #[error("the environment must be reset before it is stepped")]
    NotReset,
    /// Writing an image failed.
    #[error("writing image {file}: {message}")]
    Image { file: PathBuf, message: String },
}

pub type Result<T, E = SimError> = std::result::Result<T, E>;
