//! `equiarm device-check`: the learner's speed on a device beside the CPU's.

use std::process::ExitCode;

use equiarm_train::device_check::DeviceCheckArgs;

/// Runs `equiarm device-check`.
pub fn run(args: &DeviceCheckArgs) -> anyhow::Result<ExitCode> {
    equiarm_train::device_check::device_check(args)?;
    Ok(ExitCode::SUCCESS)
}
