//! Learning over DDS: two `equiarm sim` + `equiarm policy --mode sample` pairs and one `equiarm train`
//! trainer node with a tiny network (docs/architecture.md#the-loop-over-dds). Guards that the policies switch to the
//! trainer's weights, that no transition is lost between the sims and the trainer, that SIGINT stops
//! every node cleanly with a checkpoint; and, without DDS, how the trainer stores transitions (each
//! frame once, expert demos only from successful episodes, never the eval env) and how the policy
//! refuses weights that are not its own. Domains 100–104 are this file's.

mod support;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, PolicyWeights, Transition};
use equiarm_sac::agent::{Agent, AgentConfig, ModelKind};
use equiarm_sac::config::TrainConfig;
use equiarm_sac::replay::Stored;
use equiarm_train::ingest::{BadTransition, Ingest};
use equiarm_train::policy::{Policy, PolicyMode, WeightsOutcome};
use equiarm_train::trainer::{Trainer, TrainerOptions};

/// A spawned `equiarm` process whose stderr is collected line by line; killed if a test panics.
struct Node {
    name: String,
    child: Option<Child>,
    log: Arc<Mutex<String>>,
}

impl Node {
    fn spawn(domain: u16, name: &str, args: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_equiarm"))
            .args(args)
            .env("ROS_DOMAIN_ID", domain.to_string())
            .env("RUST_LOG", "info,rustdds=off,ros2_client=off")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("spawning equiarm {args:?}: {e}"));
        let log = Arc::new(Mutex::new(String::new()));
        let (sink, err) = (log.clone(), child.stderr.take().unwrap());
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                let mut l = sink.lock().unwrap();
                l.push_str(&line);
                l.push('\n');
            }
        });
        let (sink, out) = (log.clone(), child.stdout.take().unwrap());
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let mut l = sink.lock().unwrap();
                l.push_str(&line);
                l.push('\n');
            }
        });
        Node { name: name.into(), child: Some(child), log }
    }

    fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }

    /// Waits (bounded) until the log satisfies `pred`.
    fn wait_log(&self, what: &str, limit: Duration, pred: impl Fn(&str) -> bool) {
        let start = Instant::now();
        while !pred(&self.log()) {
            assert!(start.elapsed() < limit, "{}: no {what} within {limit:?}:\n{}", self.name, self.log());
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn sigint(&self) {
        let pid = self.child.as_ref().unwrap().id().to_string();
        assert!(Command::new("kill").args(["-INT", &pid]).status().unwrap().success());
    }

    /// Waits (bounded) for the exit; asserts status 0 and returns the log.
    fn wait_ok(&mut self, limit: Duration) -> String {
        let child = self.child.as_mut().unwrap();
        let start = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            assert!(start.elapsed() < limit, "{} did not exit within {limit:?}:\n{}", self.name, self.log());
            std::thread::sleep(Duration::from_millis(50));
        };
        self.child = None;
        std::thread::sleep(Duration::from_millis(100)); // let the reader thread take the last lines
        let log = self.log();
        assert!(status.success(), "{} exited with {status}:\n{log}", self.name);
        log
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        if let Some(c) = self.child.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The numbers after `prefix` on the log's lines, e.g. every N of `weights version N`.
fn numbers_after(log: &str, prefix: &str) -> Vec<u64> {
    log.match_indices(prefix)
        .filter_map(|(i, _)| {
            log[i + prefix.len()..].chars().take_while(|c| c.is_ascii_digit()).collect::<String>().parse().ok()
        })
        .collect()
}

#[test]
fn two_sim_policy_pairs_train_one_trainer_over_dds_without_losing_a_transition() {
    const DOMAIN: u16 = 100;
    let run_dir = support::scratch("learn_dds_run");
    let run = run_dir.to_str().unwrap();
    let net = ["--image", "19:16", "--hidden", "8"];
    let mut trainer_args =
        vec!["train", "--run-dir", run, "--batch-size", "16", "--num-envs", "2", "--demo-episodes", "0"];
    trainer_args.extend([
        "--eval-every",
        "0",
        "--weights-every",
        "5",
        "--total-updates",
        "100000",
        "--training-starts",
        "20",
    ]);
    trainer_args.extend(["--idle-timeout-s", "120", "--quiet"]);
    trainer_args.extend(net);
    let mut trainer = Node::spawn(DOMAIN, "trainer", &trainer_args);
    trainer.wait_log("start", Duration::from_secs(60), |l| l.contains("waiting for transitions"));

    let mut policies: Vec<Node> = (0..2)
        .map(|i| {
            let (ns, seed) = (format!("/env{i}"), (i + 1).to_string());
            let mut a = vec!["policy", "--namespace", &ns, "--mode", "sample", "--seed", &seed];
            a.extend(net);
            Node::spawn(DOMAIN, &format!("policy {ns}"), &a)
        })
        .collect();
    let mut sims: Vec<Node> = (0..2)
        .map(|i| {
            let (ns, seed) = (format!("/env{i}"), (i + 1).to_string());
            let a = ["sim", "--namespace", &ns, "--task", "block_pulling", "--seed", &seed, "--resolution", "19"];
            // 5 episodes of at most 50 steps: 200 steps and more even when a few end early
            Node::spawn(
                DOMAIN,
                &format!("sim {ns}"),
                &[&a[..], &["--episodes", "5", "--timeout-ms", "300"][..]].concat(),
            )
        })
        .collect();

    // The sims run their episodes and exit by themselves; each logs the steps it published.
    let published: u64 = sims
        .iter_mut()
        .map(|s| {
            let log = s.wait_ok(Duration::from_secs(120));
            let steps = numbers_after(&log, "steps: ");
            assert_eq!(steps.len(), 1, "{log}");
            assert!(log.contains("rejected: 0"), "{log}");
            steps[0]
        })
        .sum();
    assert!(published >= 200, "only {published} env steps");
    // Both policies acted with the trainer's weights after its first update (version 2 and later).
    for p in &policies {
        p.wait_log("weights version >= 2", Duration::from_secs(60), |l| {
            numbers_after(l, "weights version ").iter().any(|&v| v >= 2)
        });
    }

    trainer.sigint();
    let log = trainer.wait_ok(Duration::from_secs(60));
    let received = numbers_after(&log, "received ");
    assert_eq!(received, vec![published], "transitions published by the sims vs received by the trainer:\n{log}");
    assert!(
        log.contains(&format!("received {published} transitions (stored {published}, expert held 0, eval 0)")),
        "{log}"
    );
    assert!(log.contains("stopping (signal)"), "{log}");
    let latest = std::fs::read_to_string(run_dir.join("checkpoints/latest")).expect("no checkpoints/latest");
    let ck = run_dir.join("checkpoints").join(latest.trim());
    for f in ["manifest.json", "actor.safetensors", "replay.bin.zst", "trainer.json"] {
        assert!(ck.join(f).is_file(), "{} lacks {f}", ck.display());
    }
    let manifest = equiarm_sac::learner::read_manifest(&ck).unwrap();
    assert_eq!(
        (manifest.replay_len as u64, manifest.config.agent.hidden, manifest.config.image_size),
        (published, 8, 19)
    );
    assert!(manifest.updates >= 1 && run_dir.join("metrics.csv").is_file());

    for p in &mut policies {
        p.sigint();
        let log = p.wait_ok(Duration::from_secs(30));
        assert!(log.contains("SIGINT received") && log.contains("skipped 0 observations"), "{log}");
        if numbers_after(&log, "sent ")[0] >= 100 {
            assert!(log.contains("actor latency (batch 1, last 100): median"), "{log}");
        }
    }
}

#[test]
fn an_expert_pair_feeds_successful_demos_and_the_trainer_stops_at_total_updates_and_resumes() {
    const DOMAIN: u16 = 101;
    let run_dir = support::scratch("learn_dds_expert");
    let run = run_dir.to_str().unwrap();
    let trainer_args = |total: &'static str| {
        let mut a = vec![
            "train",
            "--run-dir",
            run,
            "--batch-size",
            "8",
            "--num-envs",
            "1",
            "--demo-episodes",
            "0",
            "--eval-every",
            "0",
        ];
        a.extend([
            "--weights-every",
            "2",
            "--training-starts",
            "8",
            "--checkpoint-every",
            "0",
            "--quiet",
            "--image",
            "19:16",
            "--hidden",
            "8",
        ]);
        a.extend(["--total-updates", total]);
        a
    };
    let mut trainer = Node::spawn(DOMAIN, "trainer", &trainer_args("3"));
    trainer.wait_log("start", Duration::from_secs(60), |l| l.contains("waiting for transitions"));
    let mut policy = Node::spawn(DOMAIN, "expert policy", &["policy", "--namespace", "/env0", "--mode", "expert"]);
    let sim_args = [
        "sim",
        "--namespace",
        "/env0",
        "--task",
        "block_pulling",
        "--seed",
        "3",
        "--resolution",
        "19",
        "--timeout-ms",
        "300",
    ];
    let mut sim = Node::spawn(DOMAIN, "sim", &sim_args);

    // Only successful expert episodes reach the replay; the trainer exits by itself after 3 updates.
    let log = trainer.wait_ok(Duration::from_secs(120));
    assert!(log.contains("stopping (total_updates reached) at 3 updates"), "{log}");
    assert!(log.contains("updates 3, env steps"), "the summary table: {log}");
    let ck = run_dir.join("checkpoints/step_0000003");
    let m = equiarm_sac::learner::read_manifest(&ck).unwrap();
    assert!(m.replay_len >= 8 && m.expert_len == m.replay_len, "{m:?}");
    assert_eq!(numbers_after(&log, "(stored "), vec![m.replay_len as u64], "{log}");

    // --resume continues from the latest checkpoint up to the new total.
    let mut args = trainer_args("6");
    args.extend(["--resume", run]);
    let mut resumed = Node::spawn(DOMAIN, "resumed trainer", &args);
    let log = resumed.wait_ok(Duration::from_secs(120));
    assert!(log.contains("at 3 updates") && log.contains("stopping (total_updates reached) at 6 updates"), "{log}");
    assert_eq!(std::fs::read_to_string(run_dir.join("checkpoints/latest")).unwrap().trim(), "step_0000006");

    for node in [&mut sim, &mut policy] {
        node.sigint();
        let log = node.wait_ok(Duration::from_secs(30));
        assert!(log.contains("SIGINT received"), "{log}");
    }
    let sim_log = sim.log();
    assert!(sim_log.contains("success true"), "the expert never succeeded: {sim_log}");
}

const SIZE: u32 = 19;

fn observation(env: &str, episode: u32, seq: u64, shade: u8) -> Observation {
    let n = (SIZE * SIZE) as usize;
    let expert_action = GripperCommand {
        obs_seq: seq,
        open_ratio: 1.0,
        dx: 0.01,
        source: GripperCommand::SOURCE_EXPERT,
        ..Default::default()
    };
    let mut o = Observation { seq, env: env.into(), episode, step: seq as u32, expert_action, ..Default::default() };
    o.set_frame(SIZE, SIZE, &vec![shade; n * 3], &vec![0.5 + shade as f32 / 1000.0; n]).unwrap();
    o
}

fn transition(env: &str, episode: u32, seq: u64, expert: bool, last: bool) -> Transition {
    let action = GripperCommand {
        obs_seq: seq,
        open_ratio: 1.0,
        dx: 0.05,
        dtheta: -std::f32::consts::FRAC_PI_4,
        ..Default::default()
    };
    Transition {
        env: env.into(),
        episode,
        step: seq as u32,
        obs_seq: seq,
        next_obs_seq: seq + 1,
        action,
        reward: last as u8 as f32,
        done: last,
        expert,
        ..Default::default()
    }
}

/// Feeds `ing` a step as a sim publishes it (its two Observations, a seen one again, then the
/// Transition); the rows it makes now.
fn step(ing: &mut Ingest, t: Transition) -> Result<Vec<Stored>, BadTransition> {
    for s in [t.obs_seq, t.next_obs_seq] {
        ing.observation(&observation(&t.env, t.episode, s, s as u8)).unwrap();
    }
    Ok(ing.transition(t)?.map(|j| ing.rows(j)).unwrap_or_default())
}

fn result(env: &str, episode: u32, success: bool, expert: bool) -> EpisodeResult {
    EpisodeResult { env: env.into(), episode, success, expert, ..Default::default() }
}

/// A trainer's ingest of `SIZE`-pixel frames, with `/eval` as its eval env.
fn ingest() -> Ingest {
    Ingest::new(
        &TrainConfig { image_size: SIZE as usize, ..TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling) },
        "/eval",
    )
}

#[test]
fn the_trainer_stores_each_frame_once_keeps_only_successful_demos_and_never_the_eval_env() {
    let mut ing = ingest();
    // Consecutive transitions share the frame between them.
    let a = step(&mut ing, transition("env0", 0, 0, false, false)).unwrap();
    let b = step(&mut ing, transition("env0", 0, 1, false, false)).unwrap();
    assert_eq!((a.len(), b.len()), (1, 1));
    assert!(Arc::ptr_eq(&a[0].next_obs, &b[0].obs), "the shared frame was stored twice");
    assert!(!Arc::ptr_eq(&a[0].obs, &a[0].next_obs));
    assert_eq!(a[0].action, [1.0, 1.0, 0.0, 0.0, -1.0], "physical command → normalised action");
    // Another env's transition with the same seq does not reuse env0's frame.
    let c = step(&mut ing, transition("env1", 0, 2, false, false)).unwrap();
    assert!(!Arc::ptr_eq(&c[0].obs, &b[0].next_obs));
    // The eval env is never stored.
    assert!(step(&mut ing, transition("eval", 0, 0, false, false)).unwrap().is_empty());
    // A Transition that overtakes its Observations waits for them, then is joined.
    assert!(ing.transition(transition("env7", 0, 0, false, false)).unwrap().is_none());
    assert!(ing.observation(&observation("env7", 0, 0, 0)).unwrap().is_empty());
    let joined = ing.observation(&observation("env7", 0, 1, 1)).unwrap();
    assert_eq!(joined.iter().map(|j| j.t.obs_seq).collect::<Vec<_>>(), [0]);
    assert_eq!(ing.rows(joined.into_iter().next().unwrap()).len(), 1);

    // Expert demos: held until the result; a failed episode's are dropped.
    assert!(step(&mut ing, transition("env2", 0, 0, true, false)).unwrap().is_empty());
    assert!(step(&mut ing, transition("env2", 0, 1, true, true)).unwrap().is_empty());
    assert_eq!(ing.episode(&result("env2", 0, true, true)).len(), 2);
    assert!(step(&mut ing, transition("env2", 1, 3, true, true)).unwrap().is_empty());
    assert!(ing.episode(&result("env2", 1, false, true)).is_empty());
    // A result that overtakes its episode's last transitions decides them on arrival.
    assert!(step(&mut ing, transition("env3", 0, 0, true, false)).unwrap().is_empty());
    assert_eq!(ing.episode(&result("env3", 0, true, true)).len(), 1);
    assert_eq!(step(&mut ing, transition("env3", 0, 1, true, true)).unwrap().len(), 1);
    assert!(ing.episode(&result("env4", 0, false, true)).is_empty());
    assert!(step(&mut ing, transition("env4", 0, 0, true, true)).unwrap().is_empty());

    // A malformed frame is refused with the reason.
    let mut bad = observation("env5", 0, 0, 0);
    bad.depth.truncate(5);
    let e = ing.observation(&bad).unwrap_err().to_string();
    assert!(e.contains("depth: not a zstd frame of 722 bytes (19 x 19 pixels)"), "{e}");
    // Regression (issue 28): a NaN or huge reward or a NaN action made the DDS trainer exit without a
    // checkpoint; now the transition is refused, naming the value, and counted.
    for (reward, dx, what) in
        [(f32::NAN, 0.0, "reward NaN"), (1e30, 0.0, "within ±1000"), (0.0, f32::NAN, "action dx is NaN")]
    {
        let mut t = transition("env6", 0, 0, false, false);
        (t.reward, t.action.dx) = (reward, dx);
        let e = step(&mut ing, t).unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
    let n = &ing.counts;
    assert_eq!((n.transitions, n.stored, n.expert_held, n.expert_dropped, n.eval, n.bad), (14, 8, 0, 2, 1, 3));
    assert_eq!((n.bad_frames, n.unmatched), (1, 0));
}

/// Regression: a reliable RustDDS reader hands a repaired sample over after the ones that followed
/// it. The trainer let a frame go once a Transition naming it was joined, so a late Observation's
/// Transition waited for ever (CI: received 410 transitions, stored 409, none counted as dropped).
#[test]
fn observations_and_transitions_that_dds_delivers_out_of_order_are_all_joined() {
    let mut ing = ingest();
    let obs = |seq: u64| observation("env0", 0, seq, seq as u8);
    // Observation 0 is lost and repaired after 1 and 2 and both Transitions.
    for s in [1, 2] {
        assert!(ing.observation(&obs(s)).unwrap().is_empty());
    }
    assert!(ing.transition(transition("env0", 0, 0, false, false)).unwrap().is_none());
    let t1 = ing.transition(transition("env0", 0, 1, false, false)).unwrap().expect("frames 1 and 2 are here");
    let late = ing.observation(&obs(0)).unwrap();
    assert_eq!(late.iter().map(|j| j.t.obs_seq).collect::<Vec<_>>(), [0], "the late frame joins Transition 0");
    assert!(Arc::ptr_eq(&late[0].next_obs, &t1.obs), "frame 1 is shared by rows 0 and 1");
    // Transition 2 is lost and repaired after Transition 3.
    for s in [3, 4] {
        assert!(ing.observation(&obs(s)).unwrap().is_empty());
    }
    let t3 = ing.transition(transition("env0", 0, 3, false, false)).unwrap().expect("frames 3 and 4 are here");
    let t2 = ing.transition(transition("env0", 0, 2, false, false)).unwrap().expect("frames 2 and 3 are kept");
    assert!(Arc::ptr_eq(&t2.next_obs, &t3.obs));
    let rows: usize = [t1, t2, t3].into_iter().chain(late).map(|j| ing.rows(j).len()).sum();
    assert_eq!(rows, 4);
    let n = &ing.counts;
    assert_eq!((n.transitions, n.stored, n.unmatched, ing.waiting()), (4, 4, 0, 0));
    // A Transition whose frame never comes is counted as waiting, not lost silently.
    assert!(ing.transition(transition("env0", 0, 9, false, false)).unwrap().is_none());
    assert_eq!(ing.waiting(), 1);
}

#[test]
fn the_policy_refuses_foreign_weights_and_answers_a_repeated_seq_identically() {
    let arch = AgentConfig { model: ModelKind::Equi, hidden: 8, input_size: 16, ..AgentConfig::default() };
    let mut policy = Policy::new(PolicyMode::Sample, arch.clone(), SIZE as usize, None, 7).unwrap();
    let data = Agent::new(arch, 99).unwrap().actor_bytes().unwrap();
    let weights = |version, model: &str, format: &str, data: Vec<u8>| PolicyWeights {
        version,
        updates: 3,
        model: model.into(),
        format: format.into(),
        data,
        ..Default::default()
    };

    let o = policy.on_weights(weights(5, "cnn", "safetensors", data.clone()));
    assert!(matches!(&o, WeightsOutcome::Refused(why) if why.contains("'cnn'")), "{o:?}");
    let o = policy.on_weights(weights(5, "equi", "npz", data.clone()));
    assert!(matches!(&o, WeightsOutcome::Refused(why) if why.contains("npz")), "{o:?}");
    assert_eq!(policy.version(), 0);
    let before = policy.answer(&observation("env0", 0, 0, 40)).unwrap();
    assert_eq!(policy.on_weights(weights(2, "equi", "safetensors", data.clone())), WeightsOutcome::Loaded);
    assert_eq!(policy.on_weights(weights(2, "equi", "safetensors", data.clone())), WeightsOutcome::Stale);
    let o = policy.on_weights(weights(3, "equi", "safetensors", b"not safetensors".to_vec()));
    assert!(matches!(o, WeightsOutcome::Failed(_)), "{o:?}");
    assert_eq!(policy.version(), 2, "a bad payload keeps the old weights");

    // A re-published Observation (same seq) gets the same command even in sample mode.
    let again = policy.answer(&observation("env0", 0, 0, 40)).unwrap();
    assert_eq!(again, before);
    let next = policy.answer(&observation("env0", 0, 1, 41)).unwrap();
    assert_eq!((next.obs_seq, next.source), (1, GripperCommand::SOURCE_POLICY));
    assert_ne!(next, before);
    // A malformed image is an error with the reason, not a panic.
    let mut bad = observation("env0", 0, 2, 42);
    bad.color.truncate(10);
    let e = policy.answer(&bad).unwrap_err().to_string();
    assert!(e.contains("color: not a zstd frame"), "{e}");
    // Expert mode sends back the expert's action for that seq.
    let mut expert = Policy::new(PolicyMode::Expert, AgentConfig::default(), 152, None, 0).unwrap();
    let e = expert.answer(&observation("env0", 0, 4, 1)).unwrap();
    assert_eq!((e.obs_seq, e.source, e.dx), (4, GripperCommand::SOURCE_EXPERT, 0.01));
}

/// Regression (issue 28): one weights message with version 2^64−1 made a policy ignore every later
/// version without a word. Versions now only order weights within one run; another run's weights are
/// followed and reported, older ones of the same run reported and ignored.
#[test]
fn weights_versions_only_grow_within_a_run_and_a_stray_version_cannot_silence_the_trainer() {
    let arch = AgentConfig { model: ModelKind::Cnn, hidden: 8, input_size: 16, ..AgentConfig::default() };
    let mut policy = Policy::new(PolicyMode::Greedy, arch.clone(), SIZE as usize, None, 1).unwrap();
    let data = Agent::new(arch, 5).unwrap().actor_bytes().unwrap();
    let w = |run: &str, version| PolicyWeights {
        run_id: run.into(),
        version,
        model: "cnn".into(),
        format: "safetensors".into(),
        data: data.clone(),
        ..Default::default()
    };
    assert_eq!(policy.on_weights(w("run-a", 1)), WeightsOutcome::Loaded);
    assert_eq!(policy.on_weights(w("run-a", 3)), WeightsOutcome::Loaded);
    assert_eq!(policy.on_weights(w("run-a", 3)), WeightsOutcome::Stale, "a re-delivery");
    assert_eq!(policy.on_weights(w("run-a", 2)), WeightsOutcome::Older { current: 3 });
    // A stray message of another run with the largest version: followed, and said so …
    assert_eq!(policy.on_weights(w("stray", u64::MAX)), WeightsOutcome::NewRun { was: "run-a".into() });
    assert_eq!(policy.version(), u64::MAX);
    // … and the trainer's next version is taken again (its run differs), not ignored.
    assert_eq!(policy.on_weights(w("run-a", 4)), WeightsOutcome::NewRun { was: "stray".into() });
    assert_eq!(policy.version(), 4);
    // Weights full of NaN are refused; the weights in use stay.
    let mut nan = w("run-a", 5);
    // safetensors: an 8-byte header length, the JSON header, then the f32 data: NaN in the first value.
    let start = 8 + u64::from_le_bytes(nan.data[..8].try_into().unwrap()) as usize;
    nan.data[start..start + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(matches!(policy.on_weights(nan), WeightsOutcome::Failed(_)));
    assert_eq!(policy.version(), 4);
}

/// In-process trainer options on the CPU for `run_dir` (resuming it with `resume`), eval env `/eval`.
fn trainer_options(run_dir: &std::path::Path, resume: bool) -> TrainerOptions {
    TrainerOptions {
        run_dir: run_dir.to_path_buf(),
        resume: resume.then(|| run_dir.to_path_buf()),
        force: false,
        eval_namespace: "/eval".into(),
        envs: Vec::new(),
        deterministic: false,
        device: equiarm_nn::device::open("cpu").unwrap(),
        weights_every: 0,
        progress: false,
    }
}

/// Regression (CI, 2026-12-03): an expert policy that never hands over (`policy --mode expert`
/// beside an unthrottled sim) filled the 100,000-slot replay with expert transitions, which are
/// never overwritten, and the trainer stopped with "replay buffer is full of expert transitions"
/// before its last updates. Now the rows it has no room for are counted and dropped, and training
/// goes on to `total_updates`. Here with 6 slots and four successful expert episodes of 3 steps.
#[test]
fn a_replay_full_of_expert_transitions_drops_further_rows_and_training_goes_on() {
    let run_dir = support::scratch("learn_dds_no_room");
    let mut cfg = TrainConfig {
        image_size: SIZE as usize,
        batch_size: 4,
        training_starts: 4,
        total_updates: 3,
        num_envs: 1,
        demo_episodes: 0,
        eval_every: 0,
        checkpoint_every: 0,
        ..TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling)
    };
    cfg.replay.capacity = 6;
    (cfg.agent.input_size, cfg.agent.hidden) = (16, 8);
    let (mut trainer, mut learner) = Trainer::open(cfg, trainer_options(&run_dir, false)).unwrap();
    let mut seq = 0;
    for episode in 0..4 {
        for k in 0..3 {
            trainer.observation(&observation("env0", episode, seq, seq as u8));
            trainer.observation(&observation("env0", episode, seq + 1, seq as u8 + 1));
            trainer.transition(transition("env0", episode, seq, true, k == 2));
            seq += 1;
        }
        seq += 1; // the next episode starts at a new Observation
        trainer.episode(result("env0", episode, true, true)).unwrap();
        trainer.with_learner(&mut learner, false).unwrap_or_else(|e| panic!("episode {episode}: {e}"));
    }
    assert_eq!((learner.replay().len(), learner.replay().expert_len()), (6, 6));
    assert_eq!(trainer.dropped_no_room(), 6, "the last two episodes' rows had no room");
    // A new row (an agent's, this time) finds no room either, and nothing stops.
    trainer.observation(&observation("env0", 4, seq, 9));
    trainer.observation(&observation("env0", 4, seq + 1, 10));
    trainer.transition(transition("env0", 4, seq, false, false));
    let mut updates = 0;
    loop {
        let next = trainer.with_learner(&mut learner, false).unwrap();
        if trainer.stop_reason(false, Duration::from_secs(60)).is_some() {
            break;
        }
        assert!(next.update, "an update is owed after {updates} updates");
        let m = learner.update().unwrap();
        trainer.updated(&learner, m).unwrap();
        updates += 1;
        assert!(updates <= 3, "the trainer did not stop at total_updates");
    }
    assert_eq!(trainer.dropped_no_room(), 7);
    assert_eq!(trainer.stop_reason(false, Duration::from_secs(60)), Some("total_updates reached"));
    let summary = trainer.finish(&mut learner, "total_updates reached").unwrap();
    assert_eq!(summary.updates, 3);
    let m = equiarm_sac::learner::read_manifest(&run_dir.join("checkpoints/step_0000003")).unwrap();
    assert_eq!((m.replay_len, m.expert_len), (6, 6));
}

/// A resumed trainer goes on evaluating: the eval env's episodes that end once the update count
/// reaches the next multiple of `eval_every` after the checkpoint's last evaluation are counted (an
/// evaluation in evals.json beside the first process's), the ones before it are not. (Session
/// twenty-nine saw a DDS run record no evaluation after `--resume`; it did not happen again with the
/// suite, stopped by SIGINT and resumed twice, so this pins the trainer's part of it.)
#[test]
fn a_resumed_trainer_records_the_evaluations_due_after_its_checkpoint() {
    let run_dir = support::scratch("learn_dds_resume_evals");
    let cfg = |total| {
        let mut c = TrainConfig {
            image_size: SIZE as usize,
            batch_size: 4,
            training_starts: 4,
            total_updates: total,
            num_envs: 1,
            demo_episodes: 0,
            eval_every: 2,
            eval_episodes: 2,
            checkpoint_every: 0,
            ..TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling)
        };
        (c.agent.input_size, c.agent.hidden) = (16, 8);
        c
    };
    let opts = |resume: bool| trainer_options(&run_dir, resume);
    let eval = |episode| EpisodeResult {
        env: "/eval".into(),
        episode,
        eval: true,
        success: true,
        steps: 5,
        ..Default::default()
    };
    // Trains to the config's total, feeding an agent episode of 4 steps (episode `e`, from `seq`)
    // before each update it owes, and two eval episodes once the update count is one of `evals_at`.
    let train = |trainer: &mut Trainer, learner: &mut equiarm_sac::learner::Learner, first: u32, evals_at: &[u64]| {
        let mut e = first;
        let (mut seq, mut fed) = (1000 * first as u64, None);
        loop {
            let next = trainer.with_learner(learner, false).unwrap();
            // (the trainer learns the update count here, as in the node's loop)
            let u = learner.updates();
            if evals_at.contains(&u) && fed != Some(u) {
                for k in 0..2 {
                    trainer.episode(eval(100 * u as u32 + k)).unwrap();
                }
                fed = Some(u);
            }
            if trainer.stop_reason(false, Duration::from_secs(60)).is_some() {
                return;
            }
            if !next.update {
                for k in 0..4 {
                    trainer.observation(&observation("env0", e, seq, seq as u8));
                    trainer.observation(&observation("env0", e, seq + 1, seq as u8 + 1));
                    trainer.transition(transition("env0", e, seq, false, k == 3));
                    seq += 1;
                }
                trainer.episode(result("env0", e, false, false)).unwrap();
                (e, seq) = (e + 1, seq + 1);
                continue;
            }
            let m = learner.update().unwrap();
            trainer.updated(learner, m).unwrap();
        }
    };
    let updates_of = |evals: &str| -> Vec<u64> {
        let v: serde_json::Value = serde_json::from_str(evals).unwrap();
        v.as_array().unwrap().iter().map(|e| e["updates"].as_u64().unwrap()).collect()
    };

    // First process: eval episodes after updates 1 (not due yet) and 2 (due): one evaluation, at 2.
    let (mut trainer, mut learner) = Trainer::open(cfg(3), opts(false)).unwrap();
    train(&mut trainer, &mut learner, 0, &[1, 2]);
    trainer.finish(&mut learner, "total_updates reached").unwrap();
    assert_eq!(updates_of(&std::fs::read_to_string(run_dir.join("evals.json")).unwrap()), vec![2]);

    // Resumed at 3: episodes after update 3 are not due (the next is 4), those after 4 and 6 are.
    let (mut trainer, mut learner) = Trainer::open(cfg(7), opts(true)).unwrap();
    assert_eq!(learner.updates(), 3);
    train(&mut trainer, &mut learner, 50, &[3, 4, 6]);
    let summary = trainer.finish(&mut learner, "total_updates reached").unwrap();
    assert_eq!(summary.updates, 7);
    let evals = std::fs::read_to_string(run_dir.join("evals.json")).unwrap();
    assert_eq!(updates_of(&evals), vec![2, 4, 6], "{evals}");
}

/// Regression (issue 61): a Transition whose Observation was refused (a bad frame) waited for ever
/// for a frame that could not come. Now the ones waiting are dropped when the Observation is
/// refused, later ones are refused naming it, and both are counted as bad.
#[test]
fn transitions_naming_a_refused_observation_are_dropped_and_counted() {
    let mut ing = ingest();
    let obs = |seq: u64| observation("env0", 0, seq, seq as u8);
    // Transition 0 arrives first and waits for Observations 0 and 1; Observation 1 is bad.
    assert!(ing.transition(transition("env0", 0, 0, false, false)).unwrap().is_none());
    assert_eq!(ing.waiting(), 1);
    assert!(ing.observation(&obs(0)).unwrap().is_empty());
    let mut bad = obs(1);
    bad.color.truncate(3);
    assert!(ing.observation(&bad).is_err());
    assert_eq!(ing.waiting(), 0, "the waiting Transition is dropped with its Observation");
    // Transition 1 (Observations 1 and 2) comes after: refused, naming the Observation.
    let e = ing.transition(transition("env0", 0, 1, false, false)).unwrap_err();
    assert_eq!((e.cause(), e.to_string().as_str()), ("orphan", "it names Observation 1, whose frame was refused"));
    // The rest of the stream is joined as usual.
    for s in [2, 3] {
        assert!(ing.observation(&obs(s)).unwrap().is_empty());
    }
    assert!(ing.transition(transition("env0", 0, 2, false, false)).unwrap().is_some());
    let n = &ing.counts;
    assert_eq!((n.transitions, n.bad, n.bad_frames, n.unmatched, ing.waiting()), (3, 2, 1, 0, 0));
}
