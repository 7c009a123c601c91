//! End-to-end test of the README's main job (issue: one command runs the suite): `launch_scripts/
//! train.sh` over DDS on loopback with a tiny budget and a tiny network: recorder, trainer, two
//! sim + policy pairs (expert demos first, then the learned policy) and the eval pair. Asserts that
//! transitions flowed (the trainer's count), weights were broadcast and picked up (the policies'
//! `weights version` lines), a checkpoint and the learning curve exist, and the recorded bag opens
//! in `equiarm bag info` and `equiarm bag eval`. A second test interrupts the script with SIGINT
//! mid-run and asserts that no process of the suite is left and the bag is readable, also when the
//! test itself runs with SIGINT ignored (a background job of a script): the launch scripts then run
//! themselves again with SIGINT at its default (`eqa_default_signals` in launch_scripts/lib.sh).
//!
//! A failing test SIGKILLs what is left of its suite ([`KillOnPanic`]), so that a 100,000-update
//! run does not go on after it.
//!
//! A third runs the secured suite (`train.sh --secure`).
//!
//! Domains 105, 106 and 107. The test command runs this inside a private network namespace.

mod support;

use std::os::unix::process::CommandExt as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_equiarm")
}

fn train_sh(domain: u32, run_dir: &Path, updates: u32, extra: &[&str]) -> Command {
    train_sh_with(domain, run_dir, updates, &[], extra)
}

/// `train.sh SCRIPT_ARGS … -- TRAINER_ARGS … EXTRA`.
fn train_sh_with(domain: u32, run_dir: &Path, updates: u32, script_args: &[&str], extra: &[&str]) -> Command {
    let mut c = Command::new("bash");
    c.arg(support::repo().join("launch_scripts/train.sh"))
        .args(script_args)
        .args(["--num-envs", "2", "--total-updates", &updates.to_string(), "--run-dir"])
        .arg(run_dir)
        .args(["--", "--image", "19:16", "--hidden", "8", "--batch-size", "16", "--demo-episodes", "2"])
        .args(["--eval-every", "10", "--eval-episodes", "2", "--weights-every", "5", "--training-starts", "20"])
        .args(extra)
        .env("EQUIARM_BIN", bin())
        .env("ROS_DOMAIN_ID", domain.to_string())
        // the nodes' default log filter, as a user gets it
        .env_remove("RUST_LOG");
    c
}

fn log(run_dir: &Path, name: &str) -> String {
    std::fs::read_to_string(run_dir.join("logs").join(format!("{name}.log"))).unwrap_or_default()
}

/// `(pid, command line)` of the processes started with `ROS_DOMAIN_ID=domain` in their environment
/// (each test has its own domain).
fn survivors(domain: u32) -> Vec<(String, String)> {
    let needle = format!("ROS_DOMAIN_ID={domain}");
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let env = std::fs::read(e.path().join("environ")).unwrap_or_default();
        if env.split(|&b| b == 0).any(|v| v == needle.as_bytes()) {
            let cmd = std::fs::read(e.path().join("cmdline")).unwrap_or_default();
            out.push((e.file_name().to_string_lossy().into_owned(), String::from_utf8_lossy(&cmd).replace('\0', " ")));
        }
    }
    out
}

/// On a panic (a failed assertion), SIGKILLs every process of ROS domain `.0`: the suite's nodes
/// run in their own process groups and would otherwise outlive the test.
struct KillOnPanic(u32);

impl Drop for KillOnPanic {
    fn drop(&mut self) {
        if std::thread::panicking() {
            for (pid, _) in survivors(self.0) {
                let _ = Command::new("kill").args(["-KILL", &pid]).status();
            }
        }
    }
}

/// The run learned over DDS: at least 20 transitions reached the trainer, and each of `policies`
/// switched to weights the trainer broadcast (version 2 or later).
fn learned(run_dir: &Path, policies: &[&str]) {
    let trainer = log(run_dir, "trainer");
    let received: u64 = trainer
        .lines()
        .find_map(|l| l.split("received ").nth(1)?.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("trainer log has no 'received N transitions':\n{trainer}"));
    assert!(received >= 20, "only {received} transitions reached the trainer");
    for p in policies {
        let l = log(run_dir, p);
        let newest =
            l.lines().filter_map(|x| x.split("weights version ").nth(1)?.split(' ').next()?.parse::<u64>().ok()).max();
        assert!(newest.unwrap_or(0) >= 2, "{p} never switched to broadcast weights:\n{l}");
    }
}

fn bag_opens(bag: &Path) {
    let info = Command::new(bin()).args(["bag", "info"]).arg(bag).output().unwrap();
    assert!(info.status.success(), "bag info failed: {}", String::from_utf8_lossy(&info.stderr));
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("/transitions"), "no /transitions in the bag:\n{text}");
    let eval = Command::new(bin()).args(["bag", "eval", "--json"]).arg(bag).output().unwrap();
    assert!(eval.status.success(), "bag eval failed: {}", String::from_utf8_lossy(&eval.stderr));
    let v: serde_json::Value = serde_json::from_slice(&eval.stdout).expect("bag eval --json prints JSON");
    assert!(v.to_string().contains("episodes"), "{v}");
}

#[test]
fn train_sh_runs_the_suite_to_the_end() {
    let run_dir = support::scratch("suite-e2e");
    let _cleanup = KillOnPanic(105);
    // a camera and a corruption other than the defaults: the sims must render what the trainer's config says
    let scene = ["--view", "angle60", "--corrupt", "random_reflection"];
    let out = train_sh(105, &run_dir, 20, &scene).stdout(Stdio::piped()).stderr(Stdio::piped()).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "train.sh failed:\n{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("success rate"), "no evaluation table:\n{stdout}");
    for sim in ["sim0", "sim1", "sim_eval"] {
        let l = log(&run_dir, sim);
        assert!(l.contains("camera elevation 60°") && l.contains("corruption random_reflection"), "{sim}:\n{l}");
    }
    learned(&run_dir, &["policy0", "policy1"]);
    // the training policies say how old the weights they acted on were; in a run of 20 updates
    // (weights every 5) no weights can be more than 20 updates behind. (A policy whose learned
    // actions all came before the trainer's first status, once a second, has no such line: this
    // run trains for about two seconds, so a policy may lack it.)
    let stale: Vec<u64> = ["policy0", "policy1"]
        .iter()
        .filter_map(|p| {
            log(&run_dir, p).lines().find_map(|l| {
                l.split("updates behind the trainer").nth(1)?.split("max ").nth(1)?.trim_end_matches(')').parse().ok()
            })
        })
        .collect();
    assert!(stale.iter().all(|&m| m <= 20), "staleness maxima {stale:?}");
    assert!(run_dir.join("checkpoints/latest").is_file());
    assert!(run_dir.join("learning_curve.png").is_file());
    bag_opens(&run_dir.join("bag"));
    // /env0's sim publishes its simulated time on /clock, and `record --all` records it as ROS 2's type.
    let info = Command::new(bin()).args(["bag", "info"]).arg(run_dir.join("bag")).output().unwrap();
    let info = String::from_utf8_lossy(&info.stdout);
    let clock = info.lines().find(|l| l.trim_start().starts_with("/clock ")).unwrap_or_else(|| panic!("{info}"));
    assert!(clock.contains("rosgraph_msgs/msg/Clock") && !clock.contains(" 0 msgs"), "{clock}");
    // The trained actor over the recorded transitions, its architecture from the run's manifest.
    let ev = Command::new(bin())
        .args(["bag", "eval", "--json", "--policy"])
        .arg(&run_dir)
        .arg(run_dir.join("bag"))
        .output()
        .unwrap();
    assert!(ev.status.success(), "bag eval --policy RUN_DIR failed: {}", String::from_utf8_lossy(&ev.stderr));
    let v: serde_json::Value = serde_json::from_slice(&ev.stdout).expect("JSON");
    assert!(v["transitions"].as_u64().unwrap_or(0) > 0 && v["dims"].as_array().map_or(0, |d| d.len()) == 5, "{v}");
    std::thread::sleep(Duration::from_millis(500));
    assert!(survivors(105).is_empty(), "left running: {:?}", survivors(105));
}

/// `train.sh --secure`: every node joins in its own enclave of the run's keystore (docs/security.md);
/// the suite learns and records as the plain one (transitions, weights, evaluations, the bag).
#[test]
fn the_secured_suite_learns_and_records() {
    let run_dir = support::scratch("suite-e2e-secure");
    let _cleanup = KillOnPanic(107);
    let out = train_sh_with(107, &run_dir, 20, &["--secure"], &[])
        .env_remove("ROS_SECURITY_KEYSTORE")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "train.sh --secure failed:\n{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("success rate"), "no evaluation table:\n{stdout}");
    for (name, enclave) in [
        ("trainer", "/equiarm/trainer"),
        ("record", "/equiarm/equiarm_recorder"),
        ("sim0", "/equiarm/env0/sim"),
        ("policy1", "/equiarm/env1/policy"),
        ("sim_eval", "/equiarm/eval/sim"),
        ("policy_eval", "/equiarm/eval/policy"),
    ] {
        let l = log(&run_dir, name);
        assert!(l.contains(&format!("security: enclave {enclave})")), "{name} did not join in {enclave}:\n{l}");
    }
    learned(&run_dir, &["policy0", "policy1"]);
    bag_opens(&run_dir.join("bag"));
    let info = Command::new(bin()).args(["bag", "info"]).arg(run_dir.join("bag")).output().unwrap();
    let info = String::from_utf8_lossy(&info.stdout);
    let tr = info.lines().find(|l| l.trim_start().starts_with("/transitions ")).unwrap_or_else(|| panic!("{info}"));
    assert!(!tr.contains(" 0 msgs"), "{tr}");
    assert!(run_dir.join("keystore/enclaves/equiarm/env1/sim/cert.pem").is_file());
    std::thread::sleep(Duration::from_millis(500));
    assert!(survivors(107).is_empty(), "left running: {:?}", survivors(107));
}

#[test]
fn ctrl_c_stops_every_process_and_leaves_a_readable_bag() {
    let run_dir = support::scratch("suite-sigint");
    let _cleanup = KillOnPanic(106);
    let mut child = train_sh(106, &run_dir, 100_000, &[])
        .process_group(0)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait until the trainer has made updates (its checkpoints dir appears only later, so look at the log).
    let t0 = Instant::now();
    while !log(&run_dir, "policy0").contains("weights version 2") {
        assert!(t0.elapsed() < Duration::from_secs(120), "the suite did not start training in 120 s");
        assert!(child.try_wait().unwrap().is_none(), "train.sh exited early");
        std::thread::sleep(Duration::from_millis(500));
    }
    // Ctrl-C in a terminal signals the whole foreground process group.
    let pgid = child.id() as i32;
    assert!(Command::new("kill").args(["-INT", "--", &format!("-{pgid}")]).status().unwrap().success());
    let t1 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        assert!(t1.elapsed() < Duration::from_secs(40), "train.sh did not stop within 40 s of SIGINT");
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(Duration::from_millis(500));
    let left = survivors(106);
    assert!(left.is_empty(), "processes left running after Ctrl-C: {left:?}");
    bag_opens(&run_dir.join("bag"));
}
