//! `equiarm experiment`: the paper's RL experiments as grids of in-process runs.

use std::process::ExitCode;
use std::sync::atomic::Ordering;

use equiarm_experiment::cli::ExperimentCommand;

/// Runs `equiarm experiment`; SIGINT/SIGTERM stop the runs with a checkpoint.
pub fn run(c: ExperimentCommand) -> anyhow::Result<ExitCode> {
    let stop = equiarm_nodes::signals::stop_flag(equiarm_nodes::signals::CHECKPOINT_AND_STOP);
    let code = equiarm_experiment::cli::run(c, &move || stop.load(Ordering::Relaxed))?;
    Ok(super::exit_code(code))
}
