//! `equiarm policy`: the policy node.

use std::process::ExitCode;

use equiarm_nodes::policy_cli::PolicyArgs;
use equiarm_nodes::ros::RosOptions;

/// Runs the policy node until SIGINT/SIGTERM.
pub fn run(args: &PolicyArgs) -> anyhow::Result<ExitCode> {
    let opts = RosOptions::from_env()?;
    super::runtime()?.block_on(equiarm_nodes::policy::run(args, &opts))?;
    Ok(ExitCode::SUCCESS)
}
