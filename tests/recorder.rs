//! The recorder node over DDS: a clean stop (SIGINT) leaves a complete bag holding every message
//! published after the recorder matched; a SIGKILL during a steady stream loses at most 0.5 s, and
//! `equiarm bag recover` turns the remains into a bag both Python readers open.

mod support;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use equiarm_bag::{ReadMode, Reader};
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation};
use equiarm_msgs::sensor_msgs::Image;
use equiarm_msgs::{RosMessage, cdr};
use equiarm_nodes::ros::{RosNode, RosOptions, qos};
use support::golden_values::*;

fn equiarm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_equiarm"))
}

fn record(domain: u16, out: &Path, args: &[&str]) -> Child {
    equiarm()
        .args(["record", "-q", "-o"])
        .arg(out)
        .args(args)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Starts `equiarm bag play BAG ARGS` on `domain`.
fn play(domain: u16, bag: &Path, args: &[&str]) -> Child {
    equiarm()
        .args(["bag", "play"])
        .args(args)
        .arg(bag)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits for a player to exit successfully and returns what it printed.
fn play_output(mut child: Child) -> String {
    let status = wait_exit(&mut child, 20);
    assert!(status.success(), "player exit: {status}");
    let mut out = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut out).unwrap();
    out
}

fn wait_exit(child: &mut Child, secs: u64) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(start.elapsed() < Duration::from_secs(secs), "recorder did not exit within {secs} s");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn cmd(k: u64) -> GripperCommand {
    GripperCommand { obs_seq: k, ..command_typical() }
}

/// obs_seq of every recorded GripperCommand, in file order.
fn recorded_seqs(bag: &Path) -> Vec<u64> {
    let mut seqs = Vec::new();
    Reader::open(bag)
        .unwrap()
        .for_each(ReadMode::Strict, |m| {
            if m.type_name == GripperCommand::TYPE_NAME {
                seqs.push(cdr::decode::<GripperCommand>(m.data).unwrap().obs_seq);
            }
            Ok::<(), ()>(())
        })
        .unwrap()
        .unwrap();
    seqs
}

fn python_counts(bag: &Path, counts: serde_json::Value, types: serde_json::Value) {
    let expected = bag.with_extension("expected.json");
    std::fs::write(&expected, serde_json::json!({"counts": counts, "types": types, "values": null}).to_string())
        .unwrap();
    let mut c = support::python_script("bag_check.py");
    c.arg(bag).arg(&expected);
    support::run_ok(c);
}

#[test]
fn sigint_leaves_a_complete_bag_with_every_message_after_the_match() {
    let dir = support::scratch("recorder_clean");
    let bag = dir.join("clean");
    let mut rec = record(81, &bag, &["--all", "--compression", "lz4"]);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let published = rt.block_on(async {
        let mut node = RosNode::new("/", "rec_pub", &RosOptions { domain_id: 81, ..Default::default() }).unwrap();
        let cmds = node.publisher::<GripperCommand>("/rec/gripper_cmd", qos::command()).unwrap();
        let eps = node.publisher::<EpisodeResult>("/episodes", qos::stream(100)).unwrap();
        // the recorder discovers topics once a second, then matches
        assert!(node.wait_for_subscription(&cmds, Duration::from_secs(15)).await, "recorder never subscribed");
        assert!(node.wait_for_subscription(&eps, Duration::from_secs(15)).await, "recorder never subscribed");
        tokio::time::sleep(Duration::from_millis(500)).await;
        for k in 0..60 {
            cmds.publish(cmd(k)).await.unwrap();
            if k % 10 == 0 {
                eps.publish(EpisodeResult { episode: k as u32, success: true, ..Default::default() }).await.unwrap();
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        tokio::time::sleep(Duration::from_millis(700)).await;
        60
    });
    Command::new("kill").args(["-INT", &rec.id().to_string()]).status().unwrap();
    let status = wait_exit(&mut rec, 15);
    assert!(status.success(), "recorder exit: {status}");
    assert!(bag.join("metadata.yaml").exists());
    assert_eq!(recorded_seqs(&bag), (0..published).collect::<Vec<_>>());
    python_counts(
        &bag,
        serde_json::json!({"/rec/gripper_cmd": 60, "/episodes": 6}),
        serde_json::json!({"/rec/gripper_cmd": GripperCommand::TYPE_NAME, "/episodes": EpisodeResult::TYPE_NAME}),
    );
    let out = equiarm().args(["bag", "eval", "--json"]).arg(&bag).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["episodes"], 6, "{v}");
}

/// Regression (issue 28): in a main job the sims' writers lost the recorder and the bag silently
/// stopped holding their topics. The recorder now says when a recorded topic has no publisher left.
#[test]
fn the_recorder_says_when_a_topic_loses_its_last_publisher() {
    let dir = support::scratch("recorder_lost");
    let mut rec = record(93, &dir.join("lost"), &["--all"]);
    let stderr = rec.stderr.take().unwrap();
    let (tx, lines) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in std::io::BufRead::lines(std::io::BufReader::new(stderr)).map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut node = RosNode::new("/", "lost_pub", &RosOptions { domain_id: 93, ..Default::default() }).unwrap();
        let cmds = node.publisher::<GripperCommand>("/lost/gripper_cmd", qos::command()).unwrap();
        assert!(node.wait_for_subscription(&cmds, Duration::from_secs(15)).await, "recorder never subscribed");
        for k in 0..5 {
            cmds.publish(cmd(k)).await.unwrap();
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
        // the publisher ends with its node
    });
    drop(rt);
    let wanted = "/lost/gripper_cmd: every publisher is gone";
    let start = Instant::now();
    let mut seen = Vec::new();
    while start.elapsed() < Duration::from_secs(60) && !seen.iter().any(|l: &String| l.contains(wanted)) {
        if let Ok(l) = lines.recv_timeout(Duration::from_millis(200)) {
            seen.push(l);
        }
    }
    Command::new("kill").args(["-INT", &rec.id().to_string()]).status().unwrap();
    let status = wait_exit(&mut rec, 15);
    assert!(status.success(), "recorder exit: {status}");
    while let Ok(l) = lines.recv_timeout(Duration::from_secs(2)) {
        seen.push(l);
    }
    let log = seen.join("\n");
    assert!(log.contains(wanted), "{log}");
    assert!(log.contains("had no publisher left when recording stopped: /lost/gripper_cmd"), "{log}");
}

#[test]
fn sigkill_loses_at_most_half_a_second_and_recover_makes_a_readable_bag() {
    let dir = support::scratch("recorder_kill");
    let bag = dir.join("killed");
    let mut rec =
        record(82, &bag, &["/rec/gripper_cmd:equiarm_msgs/msg/GripperCommand", "/rec/image:sensor_msgs/msg/Image"]);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let (published_at_kill, rate_hz) = rt.block_on(async {
        let mut node = RosNode::new("/", "rec_pub", &RosOptions { domain_id: 82, ..Default::default() }).unwrap();
        let cmds = node.publisher::<GripperCommand>("/rec/gripper_cmd", qos::command()).unwrap();
        let imgs = node.publisher::<Image>("/rec/image", qos::sensor_data()).unwrap();
        assert!(node.wait_for_subscription(&cmds, Duration::from_secs(15)).await, "recorder never subscribed");
        let image = rgb8(152, 152, "camera");
        // a steady 100 Hz stream; SIGKILL the recorder after 3 s while it keeps going
        let start = Instant::now();
        let mut k = 0u64;
        let mut killed_at = None;
        while start.elapsed() < Duration::from_secs(4) {
            cmds.publish(cmd(k)).await.unwrap();
            if k.is_multiple_of(5) {
                imgs.publish(image.clone()).await.unwrap();
            }
            k += 1;
            if killed_at.is_none() && start.elapsed() >= Duration::from_secs(3) {
                rec.kill().unwrap();
                killed_at = Some(k);
            }
            let next = Duration::from_millis(10 * k);
            if let Some(wait) = next.checked_sub(start.elapsed()) {
                tokio::time::sleep(wait).await;
            }
        }
        (killed_at.unwrap(), k as f64 / start.elapsed().as_secs_f64())
    });
    wait_exit(&mut rec, 5);
    assert!(!bag.join("metadata.yaml").exists(), "a killed recorder cannot have written metadata.yaml");

    let info = equiarm().args(["bag", "info"]).arg(&bag).output().unwrap();
    assert!(String::from_utf8_lossy(&info.stdout).contains("TRUNCATED"), "{}", String::from_utf8_lossy(&info.stdout));

    let fixed = dir.join("recovered");
    let out = equiarm().args(["bag", "recover"]).arg(&bag).arg(&fixed).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let seqs = recorded_seqs(&fixed);
    assert!(!seqs.is_empty(), "nothing survived the kill");
    let last = *seqs.last().unwrap();
    // every message between the first and last recorded one is there, in order
    assert_eq!(seqs, (seqs[0]..=last).collect::<Vec<_>>());
    let lost = published_at_kill - 1 - last;
    let lost_s = lost as f64 / rate_hz;
    eprintln!(
        "kill test: published {published_at_kill} before the kill at {rate_hz:.0} Hz, last recorded {last}: lost {lost} ({lost_s:.3} s)"
    );
    assert!(lost_s <= 0.5, "lost {lost} messages = {lost_s:.3} s at {rate_hz:.0} Hz");

    let images = {
        let mut n = 0u64;
        Reader::open(&fixed)
            .unwrap()
            .for_each(ReadMode::Strict, |m| {
                n += (m.type_name == Image::TYPE_NAME) as u64;
                Ok::<(), ()>(())
            })
            .unwrap()
            .unwrap();
        n
    };
    assert!(images > 0, "no camera image survived");
    python_counts(
        &fixed,
        serde_json::json!({"/rec/gripper_cmd": seqs.len(), "/rec/image": images}),
        serde_json::json!({"/rec/gripper_cmd": GripperCommand::TYPE_NAME, "/rec/image": Image::TYPE_NAME}),
    );
}

/// Regression (issue 28): `bag play` ignored SIGINT/SIGTERM while it waited for the next recorded
/// timestamp, so a bag with a far-future log time could only be killed.
#[test]
fn bag_play_stops_on_sigint_while_waiting_for_a_far_timestamp() {
    use equiarm_bag::qos::OfferedQos;
    use equiarm_bag::{TopicInfo, Writer, WriterOptions};
    let dir = support::scratch("recorder_play_wait");
    let bag = dir.join("far");
    let mut w = Writer::create(&bag, WriterOptions::default()).unwrap();
    let c = w.add_topic(TopicInfo::of::<GripperCommand>("/far/gripper_cmd", &[OfferedQos::reliable(10)])).unwrap();
    let t0 = 1_700_000_000_000_000_000u64;
    // the second message is recorded 100 days after the first
    for (k, t) in [(0u64, t0), (1, t0 + 100 * 86_400 * 1_000_000_000)] {
        w.write(c, t, t, &cdr::encode(&cmd(k)).unwrap()).unwrap();
    }
    w.finish().unwrap();
    let mut player = play(92, &bag, &["--wait-ms", "500"]);
    std::thread::sleep(Duration::from_secs(3));
    std::process::Command::new("kill").args(["-INT", &player.id().to_string()]).status().unwrap();
    // the next message is due in 100 days: exiting at all means the wait woke on the signal
    let status = wait_exit(&mut player, 10);
    assert!(status.success(), "player exit: {status}");
    let mut out = String::new();
    std::io::Read::read_to_string(&mut player.stdout.take().unwrap(), &mut out).unwrap();
    assert!(out.contains("published 1 messages (0 skipped)"), "{out}");
}

#[test]
fn bag_play_republishes_every_message_in_order_on_remapped_topics() {
    use equiarm_bag::qos::OfferedQos;
    use equiarm_bag::{TopicInfo, Writer, WriterOptions};
    let dir = support::scratch("recorder_play");
    let bag = dir.join("toplay");
    let mut w = Writer::create(&bag, WriterOptions::default()).unwrap();
    let c = w.add_topic(TopicInfo::of::<GripperCommand>("/rec/gripper_cmd", &[OfferedQos::reliable(10)])).unwrap();
    let t0 = 1_700_000_000_000_000_000u64;
    for k in 0..20u64 {
        w.write(c, t0 + k * 10_000_000, t0, &cdr::encode(&cmd(k)).unwrap()).unwrap();
    }
    w.finish().unwrap();

    let player =
        play(83, &bag, &["--rate", "2", "--wait-ms", "2000", "--remap", "/rec/gripper_cmd:/played/gripper_cmd"]);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let got = rt.block_on(async {
        let mut node = RosNode::new("/", "play_sub", &RosOptions { domain_id: 83, ..Default::default() }).unwrap();
        let sub = node.subscription::<GripperCommand>("/played/gripper_cmd", qos::stream(100)).unwrap();
        let mut got = Vec::new();
        let start = Instant::now();
        while got.len() < 20 && start.elapsed() < Duration::from_secs(20) {
            if let Some((m, _)) = sub.recv_timeout(Duration::from_millis(500)).await.unwrap() {
                got.push(m);
            }
        }
        got
    });
    let out = play_output(player);
    assert!(out.contains("published 20 messages (0 skipped)"), "{out}");
    assert_eq!(got, (0..20).map(cmd).collect::<Vec<_>>());
}

#[test]
fn bag_play_lockstep_waits_for_the_command_naming_each_observation() {
    use equiarm_bag::qos::OfferedQos;
    use equiarm_bag::{TopicInfo, Writer, WriterOptions};
    let dir = support::scratch("recorder_lockstep");
    let bag = dir.join("obs");
    let mut w = Writer::create(&bag, WriterOptions::default()).unwrap();
    let o = w.add_topic(TopicInfo::of::<Observation>("/env0/observation", &[OfferedQos::reliable(10)])).unwrap();
    let t0 = 1_700_000_000_000_000_000u64;
    for seq in 10..15u64 {
        // recorded an hour apart: lock-step must not keep that pace
        w.write(o, t0 + (seq - 10) * 3_600_000_000_000, t0, &cdr::encode(&observation(seq, 4, 1)).unwrap()).unwrap();
    }
    w.finish().unwrap();

    let mut player =
        play(84, &bag, &["--lockstep", "300", "--wait-ms", "2000", "--remap", "/env0/observation:/ls/observation"]);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let seen = rt.block_on(async {
        let mut node = RosNode::new("/", "policy", &RosOptions { domain_id: 84, ..Default::default() }).unwrap();
        let sub = node.subscription::<Observation>("/ls/observation", qos::command()).unwrap();
        let cmds = node.publisher::<GripperCommand>("/ls/gripper_cmd", qos::command()).unwrap();
        let mut seen = Vec::new();
        let mut snubbed = false;
        let start = Instant::now();
        while seen.last() != Some(&14) && start.elapsed() < Duration::from_secs(25) {
            let Some((obs, _)) = sub.recv_timeout(Duration::from_millis(500)).await.unwrap() else { continue };
            seen.push(obs.seq);
            if obs.seq == 12 && !snubbed {
                snubbed = true; // no answer: the player must publish seq 12 again
                continue;
            }
            cmds.publish(cmd(obs.seq)).await.unwrap();
        }
        // Stay up (answering re-publications) until the player is done: dropping the node right
        // after the last command can lose it on a loaded machine.
        let start = Instant::now();
        while player.try_wait().unwrap().is_none() && start.elapsed() < Duration::from_secs(20) {
            if let Some((obs, _)) = sub.recv_timeout(Duration::from_millis(100)).await.unwrap() {
                cmds.publish(cmd(obs.seq)).await.unwrap();
            }
        }
        seen
    });
    let out = play_output(player);
    assert!(out.contains("published 5 messages (0 skipped)"), "{out}");
    assert_eq!(seen, [10, 11, 12, 12, 13, 14], "observations as the policy saw them");
}
