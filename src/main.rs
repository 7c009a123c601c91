//! `equiarm`: the one command-line program of the suite. One subcommand per node or tool, each a
//! module of [`cmd`] with its arguments and its `run`; `main` routes, and decides the exit code once
//! (the code a command's `run` returns, or 1 with the error printed).

mod cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "equiarm", version, about = "ROS 2 node suite for robot learning with equivariant models")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Message types: list them, or show one's definition (like `ros2 interface`).
    #[command(after_help = "Examples:\n  equiarm msg list\n  equiarm msg show equiarm_msgs/msg/Observation")]
    #[command(subcommand)]
    Msg(cmd::msg::MsgCommand),
    /// Topics: print a topic's messages.
    #[command(after_help = "Examples:\n  equiarm topic echo /episodes -t equiarm_msgs/msg/EpisodeResult --count 5")]
    #[command(subcommand)]
    Topic(cmd::topic::TopicCommand),
    /// Simulated environment node: one of the paper's five tasks on the lock-step protocol.
    ///
    /// Publishes Observation on `observation` (relative to --namespace), waits for the GripperCommand
    /// on `gripper_cmd` naming its seq, steps, publishes Transition on /transitions and, at episode end,
    /// EpisodeResult on /episodes (discounted_return with gamma 0.99); camera images and CameraInfo on
    /// `camera/...`. Commands for another seq are ignored; commands with NaN/inf are rejected (nothing
    /// moves). Out-of-range values are clipped, as the paper's environments do: dx, dy, dz to
    /// +-0.05 m, dtheta to +-pi/4 rad, open_ratio to [0, 1], and the target position to the workspace.
    #[command(
        after_help = "Examples:\n  equiarm sim --task block_pulling --seed 0 --namespace /env0\n  equiarm sim --task drawer_opening --namespace /eval --eval\n  equiarm sim snapshot --task block_in_bowl --out snapshots"
    )]
    Sim(cmd::sim::SimCommand),
    /// Records topics into a rosbag2-compatible MCAP bag until Ctrl-C (the recorder node).
    #[command(
        after_help = "Examples:\n  equiarm record -o runs/today --all\n  equiarm record -o runs/cmds /env0/gripper_cmd:equiarm_msgs/msg/GripperCommand --compression lz4\n  equiarm record -o runs/live --all --foxglove 8765"
    )]
    Record(cmd::record::RecordArgs),
    /// Bags: describe, evaluate, repair.
    #[command(
        after_help = "Examples:\n  equiarm bag info runs/today\n  equiarm bag eval runs/today --json\n  equiarm bag play runs/today --rate 2 --remap /env0/observation:/replay/observation\n  equiarm bag recover runs/killed runs/recovered\n  equiarm bag export runs/today --format lerobot runs/today-lerobot\n  equiarm bag video runs/today --out runs/today-videos --episodes env0:3,eval"
    )]
    #[command(subcommand)]
    Bag(cmd::bag::BagCommand),
    /// Trains SAC from demonstrations (docs/paper.md §2): in this process (`--in-process`), or as the
    /// trainer node over DDS (transitions from /transitions, weights out on /policy/weights).
    ///
    /// Writes metrics.csv/jsonl (CleanRL names), learning_curve.png, checkpoints/ and config.json into
    /// --run-dir; prints an evaluation table at the end. Ctrl-C stops with a checkpoint; --resume continues.
    #[command(
        after_help = "Examples:\n  equiarm train --in-process --task block_pulling --model equi --seed 0 --run-dir runs/pull_s0\n  equiarm train --resume runs/pull_s0\n  equiarm train --in-process --eval-every 500 --video-every 2 --run-dir runs/filmed\n  equiarm train --task block_pulling --num-envs 5 --run-dir runs/dds_s0\n  equiarm train --print-config --preset paper --task block_in_bowl"
    )]
    Train(Box<equiarm_nodes::train_cli::TrainArgs>),
    /// Policy node: answers each Observation on `observation` (relative to --namespace) with a
    /// GripperCommand on `gripper_cmd` naming its seq: the actor's sampled or greedy action, the
    /// expert's, or a random one. In sample/greedy mode it takes new actor weights from
    /// /policy/weights (transient-local) and logs `weights version N (updates U)` on each switch.
    #[command(
        after_help = "Examples:\n  equiarm policy --namespace /env0 --mode expert\n  equiarm policy --namespace /env0 --mode sample --expert-episodes 4 --max-lead 5\n  equiarm policy --namespace /eval --mode greedy --checkpoint runs/pull_s0"
    )]
    Policy(equiarm_nodes::policy_cli::PolicyArgs),
    /// Networks: diagnostics of saved (or freshly initialised) equivariant networks.
    #[command(after_help = "Examples:\n  equiarm nn check-equivariance --fresh --net equi-actor --config reduced")]
    #[command(subcommand)]
    Nn(cmd::nn::NnCommand),
    /// The supervised rotation-estimation experiment (docs/rotest.md): datasets, training, the
    /// invariant bound, the report.
    #[command(
        subcommand,
        after_help = "Examples:\n  equiarm rotest data --corrupt grid,side --pairs 2000 --seed 0 -o data/rotest/side+grid\n  equiarm rotest snapshots -o docs/rotest\n  equiarm rotest bound data/rotest/condition_reverse\n  equiarm rotest train --data data/rotest/none --model equi --train-pairs 400 --seed 0 -o runs/rotest/none/equi/400/s0\n  equiarm rotest grid --data data/rotest --runs runs/rotest --sizes 100,400\n  equiarm rotest status --data data/rotest --runs runs/rotest --sizes 100,400\n  equiarm rotest invariance --data data/rotest/none runs/rotest/none/equi/400/s0\n  equiarm rotest report runs/rotest --data data/rotest"
    )]
    Rotest(equiarm_rotest::cli::RotestCommand),
    /// The paper's RL experiments as named grids of in-process runs (experiments/NAME.toml,
    /// docs/experiment_runner.md): run them a few at a time, resume after an interruption, report;
    /// check the paper's claims on the reports (docs/results/claims.toml).
    #[command(
        subcommand,
        after_help = "Examples:\n  equiarm experiment run tasks --parallel 2\n  equiarm experiment status tasks\n  equiarm experiment report tasks\n  equiarm experiment claims\n  equiarm experiment heldout runs/block_pulling-2026-12-08"
    )]
    Experiment(equiarm_experiment::cli::ExperimentCommand),
    /// Times the learner on a device beside the CPU (median SAC update and batch-1 action per
    /// network family, peak device memory), then trains Equi SAC there for a few minutes
    /// (docs/backends.md, "GPU check"). Writes RUN_DIR/device_check.json.
    #[command(
        after_help = "Examples:\n  equiarm device-check --device vulkan --size paper --run-minutes 5\n  equiarm device-check --device vulkan:cpu --size reduced16 --reps 3 --run-minutes 1\n  equiarm device-check --device cpu --size reduced16 --no-cpu --run-minutes 0"
    )]
    DeviceCheck(equiarm_train::device_check::DeviceCheckArgs),
    /// DDS Security (SROS2): keystores and the nodes' enclaves, as `ros2 security` makes them; a node
    /// started with ROS_SECURITY_ENABLE=true joins only in its enclave (docs/security.md).
    #[command(
        subcommand,
        after_help = "Examples:\n  equiarm security create-keystore keys\n  equiarm security create-enclave keys /equiarm/env0/sim\n  equiarm security create-enclave keys /my_tool --all-topics --domain 7\n  equiarm security create-enclave keys /equiarm/trainer --key-password-file keys.password\n  equiarm security list-enclaves keys"
    )]
    Security(cmd::security::SecurityCommand),
}

/// Whether the command's output is meant to be read, and maybe cut short, by another program
/// (`equiarm bag info … | head`): such a command ends quietly when its reader goes, as Unix tools
/// do, instead of panicking on the failed write. Not the nodes and training runs: their sockets
/// must not end the process.
fn writes_for_a_pipe(command: &Command) -> bool {
    matches!(
        command,
        Command::Msg(_)
            | Command::Topic(_)
            | Command::Bag(_)
            | Command::Nn(_)
            | Command::Rotest(_)
            | Command::Experiment(_)
            | Command::Security(_)
    )
}

fn main() -> ExitCode {
    equiarm_nodes::ros::init_logging();
    let command = Cli::parse().command;
    if writes_for_a_pipe(&command) {
        // SAFETY: called before any other thread exists; SIG_DFL is a valid disposition for SIGPIPE.
        unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    }
    match dispatch(command) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Routes a command to its module.
fn dispatch(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::Msg(c) => cmd::msg::run(c),
        Command::Topic(c) => cmd::topic::run(c),
        Command::Sim(c) => cmd::sim::run(c),
        Command::Record(a) => cmd::record::run(a),
        Command::Bag(c) => cmd::bag::run(c),
        Command::Train(a) => cmd::train::run(&a),
        Command::Policy(a) => cmd::policy::run(&a),
        Command::Nn(c) => cmd::nn::run(c),
        Command::Rotest(c) => cmd::rotest::run(c),
        Command::Experiment(c) => cmd::experiment::run(c),
        Command::DeviceCheck(a) => cmd::device_check::run(&a),
        Command::Security(c) => cmd::security::run(c),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The example lines of a command's `--help` (its `after_help`, lines starting with `equiarm `).
    fn examples(cmd: &clap::Command) -> Vec<String> {
        let text = cmd.get_after_help().map(|h| h.to_string()).unwrap_or_default();
        text.lines().map(str::trim).filter(|l| l.starts_with("equiarm ")).map(str::to_string).collect()
    }

    #[test]
    fn every_subcommand_help_has_examples_that_parse() {
        let root = Cli::command();
        for sub in root.get_subcommands() {
            let lines = examples(sub);
            assert!(!lines.is_empty(), "`equiarm {} --help` has no example", sub.get_name());
            for line in &lines {
                let argv: Vec<&str> = line.split_whitespace().collect();
                assert_eq!(argv[1], sub.get_name(), "example '{line}' is not for `equiarm {}`", sub.get_name());
                if let Err(e) = Cli::try_parse_from(&argv) {
                    panic!("example '{line}' does not parse: {e}");
                }
            }
            // Every leaf command under it is shown by at least one example (hidden, internal ones
            // such as `experiment run-one` excepted).
            for leaf in sub.get_subcommands().filter(|c| c.get_name() != "help" && !c.is_hide_set()) {
                let shown = lines.iter().any(|l| l.split_whitespace().nth(2) == Some(leaf.get_name()));
                assert!(shown, "no example of `equiarm {} {}`", sub.get_name(), leaf.get_name());
            }
        }
    }

    #[test]
    fn the_example_check_sees_a_bad_example() {
        assert!(Cli::try_parse_from(["equiarm", "train", "--no-such-flag"]).is_err());
        assert!(Cli::try_parse_from(["equiarm", "bag", "info", "x"]).is_ok());
    }
}
