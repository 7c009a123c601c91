//! `equiarm sim` over DDS: the binary is spawned for a task and driven from an in-test node acting
//! as the expert policy (it echoes `expert_action` with the right `obs_seq`). Guards the lock-step
//! protocol of docs/architecture.md#the-loop-over-dds: seqs, re-publication on timeout, stale and non-finite commands
//! ignored without a step, Transitions and EpisodeResults on the shared topics, camera topics.
//! Domains 90–99 are this file's.

use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, Transition};
use equiarm_msgs::sensor_msgs::{CameraInfo, Image};
use equiarm_nodes::ros::{RosNode, RosOptions, Subscriber, qos};

/// Kills the sim if a test panics before it exits.
struct Sim(Option<Child>);

impl Sim {
    fn spawn(domain: u16, namespace: &str, extra: &[&str]) -> Self {
        let child = Command::new(env!("CARGO_BIN_EXE_equiarm"))
            .args(["sim", "--task", "block_picking", "--namespace", namespace])
            .args(extra)
            .env("ROS_DOMAIN_ID", domain.to_string())
            .env("RUST_LOG", "info,rustdds=off,ros2_client=off")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawning equiarm sim");
        Sim(Some(child))
    }

    /// Waits (bounded) for the process to exit and returns its output.
    fn wait(mut self, limit: Duration) -> Output {
        let mut child = self.0.take().unwrap();
        let start = Instant::now();
        while child.try_wait().unwrap().is_none() {
            if start.elapsed() > limit {
                let _ = child.kill();
                let out = child.wait_with_output().unwrap();
                panic!("equiarm sim did not exit within {limit:?}:\n{}", String::from_utf8_lossy(&out.stderr));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        child.wait_with_output().unwrap()
    }

    fn signal(&self, sig: &str) {
        let pid = self.0.as_ref().unwrap().id().to_string();
        assert!(Command::new("kill").args([&format!("-{sig}"), &pid]).status().unwrap().success());
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        if let Some(c) = self.0.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn node(domain: u16, name: &str) -> RosNode {
    RosNode::new("/", name, &RosOptions { domain_id: domain, ..Default::default() }).unwrap()
}

/// The expert's action for `obs`, as a policy node in expert mode sends it.
fn expert_reply(obs: &Observation) -> GripperCommand {
    GripperCommand { obs_seq: obs.seq, ..obs.expert_action.clone() }
}

async fn next<M: equiarm_msgs::RosMessage>(sub: &Subscriber<M>, within: Duration) -> Option<M> {
    sub.recv_timeout(within).await.unwrap().map(|(m, _)| m)
}

#[test]
fn an_expert_driver_gets_a_successful_episode_with_consistent_transitions_and_camera_frames() {
    const DOMAIN: u16 = 90;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let sim = rt.block_on(async {
        let mut n = node(DOMAIN, "sim_test_expert");
        let obs_sub = n.subscription::<Observation>("/st90/observation", qos::command()).unwrap();
        let tr_sub = n.subscription::<Transition>("/transitions", qos::stream(100)).unwrap();
        let ep_sub = n.subscription::<EpisodeResult>("/episodes", qos::stream(100)).unwrap();
        let color_sub = n.subscription::<Image>("/st90/camera/color/image_raw", qos::sensor_data()).unwrap();
        let depth_sub = n.subscription::<Image>("/st90/camera/depth/image_raw", qos::sensor_data()).unwrap();
        let info_sub = n.subscription::<CameraInfo>("/st90/camera/camera_info", qos::sensor_data()).unwrap();
        let cmd_pub = n.publisher::<GripperCommand>("/st90/gripper_cmd", qos::command()).unwrap();
        let sim = Sim::spawn(DOMAIN, "/st90", &["--seed", "3", "--episodes", "1", "--timeout-ms", "300"]);

        let (mut observations, mut transitions, mut colors, mut depths, mut infos) =
            (vec![], vec![], vec![], vec![], vec![]);
        let mut result = None;
        let deadline = Instant::now() + Duration::from_secs(30);
        while result.is_none() && Instant::now() < deadline {
            tokio::select! {
                Some(o) = next(&obs_sub, Duration::from_millis(100)) => {
                    if !o.terminal {
                        cmd_pub.publish(expert_reply(&o)).await.unwrap();
                    }
                    observations.push(o);
                }
                Some(t) = next(&tr_sub, Duration::from_millis(100)) => transitions.push(t),
                Some(r) = next(&ep_sub, Duration::from_millis(100)) => result = Some(r),
                Some(c) = next(&color_sub, Duration::from_millis(100)) => colors.push(c),
                Some(d) = next(&depth_sub, Duration::from_millis(100)) => depths.push(d),
                Some(i) = next(&info_sub, Duration::from_millis(100)) => infos.push(i),
                else => {}
            }
        }
        // Transitions and the terminal frame published just before the result may still be on their way
        // (a lost sample is repaired after the sim's next heartbeat, up to 1 s later: the node lingers
        // for it before it exits).
        let (until, steps) = (Instant::now() + Duration::from_secs(5), result.as_ref().map_or(0, |r| r.steps as usize));
        while transitions.len() < steps && Instant::now() < until {
            transitions.extend(next(&tr_sub, Duration::from_millis(100)).await);
        }
        while let Some(t) = next(&tr_sub, Duration::from_millis(300)).await {
            transitions.push(t);
        }
        while !observations.iter().any(|o| o.terminal) && Instant::now() < until {
            observations.extend(next(&obs_sub, Duration::from_millis(100)).await);
        }
        while let Some(o) = next(&obs_sub, Duration::from_millis(300)).await {
            observations.push(o);
        }
        let r = result.expect("no EpisodeResult within 30 s");
        assert!(r.success && r.expert && !r.eval, "{r:?}");
        assert_eq!((r.env.as_str(), r.task.as_str(), r.episode), ("st90", "block_picking", 0));
        assert!(r.steps >= 2 && r.steps < 50, "{r:?}");
        assert_eq!(r.ret, 1.0);
        assert!((r.discounted_return - 0.99f32.powi(r.steps as i32 - 1)).abs() < 1e-5, "{r:?}");

        // Observations: each seq once per publication (re-publications repeat it), steps 0..=steps in
        // order, the last one the episode's terminal frame (published, never answered).
        let mut seqs: Vec<u64> = observations.iter().map(|o| o.seq).collect();
        seqs.dedup();
        assert_eq!(seqs, (0..=r.steps as u64).collect::<Vec<_>>());
        let by_seq: std::collections::HashMap<u64, &Observation> = observations.iter().map(|o| (o.seq, o)).collect();
        for o in &observations {
            assert_eq!(o.terminal, o.seq == r.steps as u64, "seq {}", o.seq);
            assert_eq!((o.step as u64, o.env.as_str(), o.episode), (o.seq, "st90", 0));
            assert_eq!(o.expert_action.obs_seq, o.seq);
            assert_eq!(o.expert_action.source, GripperCommand::SOURCE_EXPERT);
            assert_eq!((o.height, o.width, o.color_rgb8().unwrap().len()), (152, 152, 152 * 152 * 3));
            let depth = o.depth_m().unwrap();
            assert!(depth.iter().all(|d| (0.1..=3.0).contains(d)), "depth in metres within near..far");
            // the frame crosses DDS compressed: a rendered 152 px frame is 115 kB raw (rgb8 + f16)
            assert!(o.color.len() + o.depth.len() < 20_000, "{} + {} bytes", o.color.len(), o.depth.len());
        }
        assert!(observations.iter().any(|o| o.holding), "the expert picked the block");

        // One Transition per step, in order, naming the observation its action answered and the next one.
        assert_eq!(
            transitions.len(),
            r.steps as usize,
            "{:?}",
            transitions.iter().map(|t| t.obs_seq).collect::<Vec<_>>()
        );
        for (k, t) in transitions.iter().enumerate() {
            let k64 = k as u64;
            assert_eq!((t.env.as_str(), t.episode, t.step), ("st90", 0, k as u32));
            assert_eq!((t.obs_seq, t.action.obs_seq, t.next_obs_seq), (k64, k64, k64 + 1));
            assert_eq!(t.action.source, GripperCommand::SOURCE_EXPERT);
            let (obs, next_obs) = (by_seq[&t.obs_seq], by_seq[&t.next_obs_seq]);
            assert!(t.expert && t.header.stamp == next_obs.header.stamp);
            assert!(next_obs.header.stamp.as_nanos() > obs.header.stamp.as_nanos(), "sim clock must advance");
            let last = k + 1 == transitions.len();
            assert_eq!((t.done, t.timeout, t.reward), (last, false, if last { 1.0 } else { 0.0 }));
            assert_eq!(next_obs.terminal, last);
        }

        // Camera topics: frames with the stamp of an observation (best effort: not every one arrives).
        assert!(
            !colors.is_empty() && !depths.is_empty() && !infos.is_empty(),
            "{} {} {}",
            colors.len(),
            depths.len(),
            infos.len()
        );
        let stamps: Vec<_> = observations.iter().map(|o| o.header.stamp.clone()).collect();
        for c in &colors {
            assert!(stamps.contains(&c.header.stamp), "colour frame stamp {:?} is no observation's", c.header.stamp);
            let o = observations.iter().find(|o| o.header.stamp == c.header.stamp).unwrap();
            assert_eq!(c.data, o.color_rgb8().unwrap(), "camera frame = observation colour");
            assert_eq!((c.encoding.as_str(), c.header.frame_id.as_str()), ("rgb8", "camera_optical_frame"));
        }
        for d in &depths {
            assert!(stamps.contains(&d.header.stamp));
            assert_eq!(d.encoding, "32FC1");
            let o = observations.iter().find(|o| o.header.stamp == d.header.stamp).unwrap();
            assert_eq!(d.float32_values().unwrap(), o.depth_m().unwrap(), "camera depth = observation depth");
        }
        let i = &infos[0];
        assert_eq!((i.width, i.height), (152, 152));
        assert!(i.k[0] > 0.0 && i.k[4] > 0.0 && i.k[8] == 1.0, "{:?}", i.k);
        assert!(stamps.contains(&i.header.stamp));
        sim
    });
    let out = sim.wait(Duration::from_secs(10));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "sim exited with {}:\n{stderr}", out.status);
    assert!(stderr.contains("rejected: 0"), "{stderr}");
}

#[test]
fn stale_and_non_finite_commands_are_ignored_and_the_observation_is_republished() {
    const DOMAIN: u16 = 91;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let sim = rt.block_on(async {
        let mut n = node(DOMAIN, "sim_test_bad");
        let obs_sub = n.subscription::<Observation>("/st91/observation", qos::command()).unwrap();
        let tr_sub = n.subscription::<Transition>("/transitions", qos::stream(100)).unwrap();
        let cmd_pub = n.publisher::<GripperCommand>("/st91/gripper_cmd", qos::command()).unwrap();
        let sim = Sim::spawn(DOMAIN, "/st91", &["--seed", "5", "--timeout-ms", "200"]);

        let first = next(&obs_sub, Duration::from_secs(20)).await.expect("no Observation within 20 s");
        assert_eq!((first.seq, first.step, first.episode), (0, 0, 0));
        // No answer: the same Observation comes again (same seq, same stamp).
        let again = next(&obs_sub, Duration::from_secs(3)).await.expect("no re-publication within 3 s");
        assert_eq!((again.seq, &again.header.stamp), (first.seq, &first.header.stamp));
        assert!(n.wait_for_subscription(&cmd_pub, Duration::from_secs(5)).await, "sim never subscribed");
        tokio::time::sleep(Duration::from_millis(300)).await;

        // A command for another seq and one with NaN and inf: neither steps the env.
        let mut stale = expert_reply(&first);
        stale.obs_seq = first.seq + 7;
        cmd_pub.publish(stale).await.unwrap();
        let mut nan = expert_reply(&first);
        (nan.dx, nan.dtheta) = (f32::NAN, f32::INFINITY);
        cmd_pub.publish(nan).await.unwrap();
        assert!(next(&tr_sub, Duration::from_millis(800)).await.is_none(), "a bad command stepped the env");
        // Still alive and still waiting for seq 0.
        let waiting = next(&obs_sub, Duration::from_secs(3)).await.expect("the sim stopped publishing");
        assert_eq!(waiting.seq, first.seq);

        // A good command steps exactly once from the reset state.
        cmd_pub.publish(expert_reply(&first)).await.unwrap();
        let t = next(&tr_sub, Duration::from_secs(5)).await.expect("no Transition for a good command");
        assert_eq!((t.obs_seq, t.step, t.next_obs_seq), (0, 0, 1));
        let deadline = Instant::now() + Duration::from_secs(3);
        let mut seen_next = false;
        while !seen_next && Instant::now() < deadline {
            if let Some(o) = next(&obs_sub, Duration::from_millis(200)).await {
                seen_next = o.seq == 1 && o.step == 1 && o.header.stamp == t.header.stamp;
            }
        }
        assert!(seen_next, "no Observation with seq 1 after the step");
        sim
    });
    sim.signal("TERM");
    let out = sim.wait(Duration::from_secs(10));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "sim exited with {} on SIGTERM:\n{stderr}", out.status);
    assert!(stderr.contains("SIGTERM received"), "{stderr}");
    assert!(stderr.contains("rejecting the command for obs_seq 0: non-finite dx=NaN, dtheta=inf"), "{stderr}");
    assert!(
        stderr.contains("steps: 1,") && stderr.contains("wrong_seq: 1,") && stderr.contains("rejected: 1 "),
        "{stderr}"
    );
}

#[test]
fn a_camera_subscriber_that_matches_late_still_gets_the_first_frame_once() {
    const DOMAIN: u16 = 92;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let sim = rt.block_on(async {
        let mut n = node(DOMAIN, "sim_test_late_camera");
        let obs_sub = n.subscription::<Observation>("/st92/observation", qos::command()).unwrap();
        let cmd_pub = n.publisher::<GripperCommand>("/st92/gripper_cmd", qos::command()).unwrap();
        let sim = Sim::spawn(DOMAIN, "/st92", &["--seed", "3", "--timeout-ms", "300"]);
        let first = next(&obs_sub, Duration::from_secs(20)).await.expect("no Observation within 20 s");
        assert_eq!(first.seq, 0);
        // Only now, long after the sim published frame 0, does a camera subscriber appear.
        tokio::time::sleep(Duration::from_millis(500)).await;
        let color = n.subscription::<Image>("/st92/camera/color/image_raw", qos::sensor_data()).unwrap();
        let info = n.subscription::<CameraInfo>("/st92/camera/camera_info", qos::sensor_data()).unwrap();
        let img = next(&color, Duration::from_secs(5)).await.expect("the late subscriber never got frame 0");
        assert_eq!(img.header.stamp, first.header.stamp);
        let ci = next(&info, Duration::from_secs(5)).await.expect("no camera_info for frame 0");
        assert_eq!(ci.header.stamp, first.header.stamp);
        // Once sent, frame 0 is not sent again while the sim still waits for its command.
        assert!(next(&color, Duration::from_millis(800)).await.is_none(), "frame 0 came twice");
        assert!(n.wait_for_subscription(&cmd_pub, Duration::from_secs(5)).await, "sim never subscribed");
        tokio::time::sleep(Duration::from_millis(300)).await;
        cmd_pub.publish(expert_reply(&first)).await.unwrap();
        let img = next(&color, Duration::from_secs(5)).await.expect("no frame after the first step");
        assert!(img.header.stamp.as_nanos() > first.header.stamp.as_nanos(), "{:?}", img.header.stamp);
        sim
    });
    sim.signal("INT");
    let out = sim.wait(Duration::from_secs(20));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}
