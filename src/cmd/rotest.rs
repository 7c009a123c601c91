//! `equiarm rotest`: the supervised rotation-estimation experiment.

use std::process::ExitCode;
use std::sync::atomic::Ordering;

use equiarm_rotest::cli::RotestCommand;

/// Runs `equiarm rotest`; `train` and `grid` stop with a checkpoint on SIGINT/SIGTERM, the other
/// subcommands keep the default action (end at once).
pub fn run(c: RotestCommand) -> anyhow::Result<ExitCode> {
    let stop = c.stops_with_checkpoint().then(|| equiarm_nodes::signals::stop_flag(equiarm_rotest::cli::TRAIN_STOP));
    let code = equiarm_rotest::cli::run(c, &|| stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)))?;
    Ok(super::exit_code(code))
}
