//! equiarm_sac: SAC from demonstrations as in Wang et al. (ICLR 2023), docs/paper.md §2, with no ROS in it.
//!
//! - [`agent`]: the SAC agent (critic → actor → α → target), Equi / CNN / SEN networks by name.
//! - [`replay`], [`frame`], [`augment`]: prioritised replay with expert retention over compact
//!   shared frames; RAD/DrQ random crops and the centre crop for acting.
//! - [`learner`]: agent + replay + crops + checkpoints, fed by any transport.
//! - [`train`]: the transport-free training loop (`equiarm train --in-process`).
//! - [`config`]: the typed run configuration, paper and reduced presets per task.
//! - [`optim`]: Adam and Polyak keyed by parameter path (checkpoints load across processes).
//! - [`rng`], [`schedule`]: seeded ChaCha streams saved in checkpoints; Linear/Every schedules.
//! - [`metrics`], [`plot`], [`progress`]: CleanRL-style scalar logs, the learning-curve PNG and
//!   the progress line.
//!
//! Limitations: FERM (CURL) is not implemented yet.

pub mod agent;
pub mod augment;
pub mod config;
pub mod frame;
pub mod learner;
pub mod metrics;
pub mod optim;
pub mod plot;
pub mod progress;
pub mod replay;
pub mod rng;
pub mod schedule;
pub mod tensorfile;
pub mod train;

/// Scratch directories for this crate's unit tests, removed when the test ends.
#[cfg(test)]
pub(crate) mod scratch {
    use std::path::{Path, PathBuf};

    /// An empty directory under the system temp dir (per process and name); removed on drop,
    /// so passing tests leave nothing behind (a failing one's panic still drops it).
    pub(crate) struct Scratch(PathBuf);

    impl Scratch {
        /// `equiarm_sac_<name>_<pid>`, emptied. Not created: some tests want it missing.
        pub(crate) fn new(name: &str) -> Self {
            let dir = std::env::temp_dir().join(format!("equiarm_sac_{name}_{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            Scratch(dir)
        }
    }

    impl std::ops::Deref for Scratch {
        type Target = Path;
        fn deref(&self) -> &Path {
            &self.0
        }
    }

    impl AsRef<Path> for Scratch {
        fn as_ref(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}
