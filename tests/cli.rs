//! The `equiarm` program as a user runs it: message tools, `topic echo` over DDS, and clean shutdown
//! of a node on SIGTERM and SIGINT.

mod support;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use equiarm_msgs::RosMessage;
use equiarm_msgs::msg::{GripperCommand, Observation};
use equiarm_nodes::ros::{RosNode, RosOptions, qos};
use support::golden_values::*;

fn equiarm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_equiarm"))
}

#[test]
fn msg_show_prints_the_full_definition_and_rejects_unknown_types() {
    let out = equiarm().args(["msg", "show", "equiarm_msgs/Observation"]).output().unwrap();
    assert!(out.status.success());
    assert_eq!(String::from_utf8(out.stdout).unwrap(), Observation::DEFINITION);
    let out = equiarm().args(["msg", "show", "--raw", "equiarm_msgs/msg/GripperCommand"]).output().unwrap();
    assert_eq!(String::from_utf8(out.stdout).unwrap(), GripperCommand::MSG_TEXT);
    let out = equiarm().args(["msg", "show", "nope/Nope"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("unknown message type 'nope/Nope'"), "{err}");
    let out = equiarm().args(["msg", "list"]).output().unwrap();
    assert_eq!(String::from_utf8(out.stdout).unwrap().lines().count(), equiarm_msgs::ALL_TYPES.len());
}

/// `equiarm msg list | head -1` and the like: a tool whose reader has gone ends quietly (killed by
/// SIGPIPE, as Unix tools are), not with a panic on the failed write.
#[test]
fn a_tool_whose_reader_is_gone_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    for args in [&["msg", "list"][..], &["msg", "show", "equiarm_msgs/Observation"]] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = equiarm().args(args).stdout(writer).stderr(Stdio::piped()).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{args:?}: {:?} {err}", out.status);
    }
}

fn echo_then_signal(domain: u16, signal: &str) {
    let mut child = equiarm()
        .args(["topic", "echo", "/cli/gripper_cmd", "--type", GripperCommand::TYPE_NAME])
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            if tx.send(line.unwrap()).is_err() {
                break;
            }
        }
    });

    let rt = tokio::runtime::Runtime::new().unwrap();
    let line = rt.block_on(async {
        let mut node = RosNode::new("/", "cli_pub", &RosOptions { domain_id: domain, ..Default::default() }).unwrap();
        let publ = node.publisher::<GripperCommand>("/cli/gripper_cmd", qos::command()).unwrap();
        let start = Instant::now();
        loop {
            assert!(start.elapsed() < Duration::from_secs(20), "equiarm topic echo printed nothing");
            publ.publish(command_typical()).await.unwrap();
            tokio::time::sleep(Duration::from_millis(100)).await;
            if let Ok(line) = rx.try_recv() {
                break line;
            }
        }
    });
    let v: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(v["obs_seq"], 42);
    assert_eq!(v["dx"], 0.03125);
    assert_eq!(v["source"], GripperCommand::SOURCE_EXPERT);
    assert_eq!(v["header"]["frame_id"], "world");

    let status = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let start = Instant::now();
    let exit = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "no exit within 10 s of SIG{signal}");
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(exit.success(), "exit {exit} after SIG{signal}:\n{err}");
    assert!(err.contains(&format!("SIG{signal} received, shutting down")), "{err}");
}

#[test]
fn topic_echo_prints_messages_and_exits_cleanly_on_sigterm() {
    echo_then_signal(75, "TERM");
}

#[test]
fn topic_echo_exits_cleanly_on_sigint() {
    echo_then_signal(76, "INT");
}

#[test]
fn a_bad_ros_domain_id_is_an_error_naming_the_variable() {
    let out = equiarm()
        .args(["topic", "echo", "/x", "--type", "std_msgs/Header", "--count", "1"])
        .env("ROS_DOMAIN_ID", "999")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("ROS_DOMAIN_ID='999'"), "{err}");
}

/// Numbers that become durations, rates, step budgets or allocations are refused at the flag (exit
/// 2, clap's usage error, or 1 for a config field) with the value and the accepted range, never a
/// panic or a run that waits forever or runs out of memory.
#[test]
fn out_of_range_numbers_are_refused_at_the_flag_naming_the_range() {
    let dir = support::scratch("cli_ranges");
    let bag = dir.join("bag");
    let bag = bag.to_str().unwrap();
    let run = dir.join("run");
    let run = run.to_str().unwrap();
    let cases: [(&[&str], &str); 27] = [
        (&["record", "-o", bag, "--all", "--duration-s", "inf"], "outside (0, 2592000]"),
        (&["record", "-o", bag, "--all", "--duration-s", "NaN"], "outside (0, 2592000]"),
        (&["record", "-o", bag, "--all", "--flush-ms", "18446744073709551615"], "outside 1..=3600000"),
        (&["record", "-o", bag, "--all", "--polling-interval-ms", "0"], "outside 1..=3600000"),
        (&["record", "-o", bag, "--all", "--split-size-mb", "0"], "split-size-mb"),
        (&["bag", "play", bag, "--rate=-1"], "outside [0.001, 1000] (or 0"),
        // regression (issue 61): a Duration of 1e300 s panicked
        (&["bag", "play", bag, "--rate", "1e-300"], "outside [0.001, 1000] (or 0"),
        (&["bag", "play", bag, "--lockstep", "0"], "outside 1..=3600000"),
        (&["sim", "--timeout-ms", "18446744073709551615"], "outside 1..=3600000"),
        (&["policy", "--steps-per-update", "18446744073709551615"], "outside 1..=1000000"),
        (&["policy", "--eval-every", "0"], "0 updates is outside 1..=1000000"),
        (&["policy", "--eval-every", "10", "--max-lead", "5"], "cannot be used with '--max-lead"),
        (&["policy", "--eval-every", "10", "--mode", "expert"], "--eval-every needs --mode sample or greedy"),
        (&["train", "--idle-timeout-s", "inf"], "outside (0, 2592000]"),
        (&["train", "--in-process", "--run-dir", run, "--num-envs", "1000000"], "num_envs"),
        (&["train", "--in-process", "--run-dir", run, "--hidden", "100000000"], "agent.hidden"),
        (&["train", "--in-process", "--run-dir", run, "--batch-size", "1000000000"], "batch_size"),
        // regression (issue 61): 0 was taken as 1
        (&["experiment", "run", "tasks", "--parallel", "0"], "0 is not in 1..=64"),
        // regression (issue 61): hundreds of GB allocated, then an abort; a batch of 0 printed a
        // table of zeros, read as perfect equivariance
        (&["nn", "check-equivariance", "--fresh", "--size", "100000"], "outside 8..=256"),
        (&["nn", "check-equivariance", "--fresh", "--batch", "100000000"], "outside 1..=64"),
        (&["nn", "check-equivariance", "--fresh", "--batch", "0"], "outside 1..=64"),
        (&["nn", "check-equivariance", "--fresh", "--hidden", "100000000"], "outside 8..=512"),
        // regression (issue 61): one topic recorded under two types
        (&["record", "-o", run, "/a:std_msgs/msg/String", "/a:equiarm_msgs/msg/Observation"], "a topic has one type"),
        // regression (issue 61): the trainer took an eval namespace the sim refuses, then waited for it
        (&["train", "--eval-namespace", "/a/b"], "not an env namespace"),
        (&["sim", "--namespace", "/0env"], "not an env namespace"),
        (&["policy", "--namespace", "/env 0"], "not an env namespace"),
        // regression (issue 61): --steps past the episode stopped silently at its end
        (
            &["sim", "snapshot", "--task", "block_pulling", "--out", run, "--steps", "4294967295"],
            "more than the 50 steps",
        ),
    ];
    for (args, expected) in cases {
        let start = Instant::now();
        let out = equiarm().args(args).env("ROS_DOMAIN_ID", "98").output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(matches!(out.status.code(), Some(1 | 2)), "{args:?}: {:?}\n{err}", out.status);
        assert!(err.contains(expected), "{args:?}: no '{expected}' in:\n{err}");
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
        assert!(start.elapsed() < Duration::from_secs(20), "{args:?} took {:?}", start.elapsed());
    }
    assert!(!dir.join("run").join("metrics.csv").exists(), "a refused config wrote a run");
}
