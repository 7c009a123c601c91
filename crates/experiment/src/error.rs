//! The experiment runner's errors: each names the file or run directory it is about.

use std::path::PathBuf;

/// What can go wrong.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// The grid file does not read, or a value in it is out of its domain.
    #[error("grid {path}: {message}")]
    Grid {
        /// The grid file.
        path: PathBuf,
        /// What is wrong, naming the key.
        message: String,
    },
    /// A run directory holds something the grid does not explain (another config, a bad result).
    #[error("run {dir}: {message}")]
    Run {
        /// The run directory.
        dir: PathBuf,
        /// What is wrong and the way out.
        message: String,
    },
    /// The claims file does not read, or a claim in it names no cell; or the page for the claims
    /// table has no place for it.
    #[error("claims {path}: {message}")]
    Claims {
        /// The claims file or the page.
        path: PathBuf,
        /// What is wrong, naming the claim.
        message: String,
    },
    /// Reading or writing a file failed (the file, and the cause).
    #[error(transparent)]
    Io(#[from] equiarm_types::files::FileError),
    /// A JSON file (a run's config or result, a report's archive) does not read or write.
    #[error(transparent)]
    Json(#[from] equiarm_sac::learner::JsonFileError),
    /// A figure could not be drawn or written.
    #[error(transparent)]
    Plot(#[from] equiarm_train::plot::PlotError),
    /// The grid runner could not lock or watch a run.
    #[error(transparent)]
    Runner(#[from] equiarm_train::grid::GridError),
    /// Training or evaluating a run failed.
    #[error(transparent)]
    Train(#[from] equiarm_train::TrainError),
}

/// The runner's results.
pub type Result<T, E = ExperimentError> = std::result::Result<T, E>;
