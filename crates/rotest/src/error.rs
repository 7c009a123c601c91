//! The error type of the experiment. Bad input (a flag out of its domain, a damaged or foreign
//! dataset file, a run directory without runs) is reported naming the flag or the file.

use std::path::PathBuf;

/// Everything that can go wrong in `equiarm_rotest`.
#[derive(Debug, thiserror::Error)]
pub enum RotestError {
    /// Reading or writing a file or directory failed (the file, and the cause).
    #[error(transparent)]
    Io(#[from] equiarm_types::files::FileError),
    /// A file is not what it should be (not a dataset, a damaged chunk, a bad run file...).
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where in the file.
        message: String,
    },
    /// An option is out of its domain.
    #[error("invalid value for `{field}`: {message}")]
    Config {
        /// The option (as on the command line, e.g. `--train-pairs`).
        field: &'static str,
        /// The rejected value and the domain it must lie in.
        message: String,
    },
    /// Another process is training in this run directory (it holds `RUN/.lock`).
    #[error(
        "{path}: another process is training in this run directory; wait for it to end or choose another directory"
    )]
    Busy {
        /// The run directory.
        path: PathBuf,
    },
    /// A run directory could not be claimed.
    #[error(transparent)]
    Train(#[from] equiarm_train::TrainError),
    /// The grid runner could not lock or watch a run.
    #[error(transparent)]
    Runner(#[from] equiarm_train::grid::GridError),
    /// The simulator failed (a camera or scene setting).
    #[error(transparent)]
    Sim(#[from] equiarm_sim::SimError),
    /// A network could not be built.
    #[error(transparent)]
    Net(#[from] equiarm_nn::nets::NetError),
    /// The device cannot be used.
    #[error(transparent)]
    Device(#[from] equiarm_nn::device::DeviceError),
    /// Saving or loading network weights failed.
    #[error(transparent)]
    Checkpoint(#[from] equiarm_nn::checkpoint::CheckpointError),
    /// Saving or loading the optimiser's state failed.
    #[error(transparent)]
    Optim(#[from] equiarm_sac::optim::OptimError),
    /// Drawing or writing a figure failed.
    #[error(transparent)]
    Plot(#[from] equiarm_train::plot::PlotError),
    /// Writing an image (a snapshot of pairs) failed.
    #[error("{path}: {message}")]
    Image {
        /// The output file.
        path: PathBuf,
        /// The encoder's or plotter's error.
        message: String,
    },
}

/// `Result` with [`RotestError`].
pub type Result<T, E = RotestError> = std::result::Result<T, E>;
