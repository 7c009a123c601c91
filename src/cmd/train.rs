//! `equiarm train`: SAC from demonstrations, in this process or as the trainer node.

use std::process::ExitCode;

use equiarm_nodes::ros::RosOptions;
use equiarm_nodes::train_cli::TrainArgs;

/// Runs `equiarm train` (or prints its config with `--print-config`).
pub fn run(args: &TrainArgs) -> anyhow::Result<ExitCode> {
    let cfg = args.build_config()?;
    if args.print_config {
        println!("{}", serde_json::to_string_pretty(&cfg)?);
        return Ok(ExitCode::SUCCESS);
    }
    let summary = if args.in_process {
        equiarm_nodes::train_cli::run_in_process(args, cfg)?
    } else {
        let opts = RosOptions::from_env()?;
        super::runtime()?.block_on(equiarm_nodes::trainer::run(args, cfg, &opts))?
    };
    println!("{summary}");
    Ok(ExitCode::SUCCESS)
}
