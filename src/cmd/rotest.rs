//! `equiarm rotest`: the supervised rotation-estimation experiment.

use std::process::ExitCode;
use std::sync::atomic::Ordering;

use equiarm_rotest::cli::RotestCommand;

/// Runs `equiarm rotest`; `train` and `grid` stop with a checkpoint on SIGINT/SIGTERM, the other
/// subcommands keep the default action (end at once).
pub fn run(c: RotestCommand) -> anyhow::Result<ExitCode> {
    // burn materialises a loaded optimiser record (a rotest checkpoint's Adam state) on its
    // default device before moving it to the training device, and in the GPU build that
    // default is Vulkan: a resumed CPU run would start a Vulkan instance (or fail without a
    // driver). rotest names its device itself (--device), so the default is the CPU unless
    // the user set BURN_DEVICE. Set here, before any thread of this process reads the
    // environment.
    if std::env::var_os("BURN_DEVICE").is_none() {
        // SAFETY: no other thread runs yet: logging is set up, the subcommand not started.
        unsafe { std::env::set_var("BURN_DEVICE", "flex") };
    }
    let stop = c.stops_with_checkpoint().then(|| equiarm_nodes::signals::stop_flag(equiarm_rotest::cli::TRAIN_STOP));
    let code = equiarm_rotest::cli::run(c, &|| stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)))?;
    Ok(super::exit_code(code))
}
