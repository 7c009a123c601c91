//! Golden byte tests: for every message type, the bytes our CDR encoder writes equal the bytes that
//! independent implementations (Cyclone DDS's Python serializer and rosbags' CDR serializer, which
//! agree with each other) write for the same values, and each side decodes the other's bytes with
//! every field intact, floats bit for bit (NaN payloads, ±inf, -0.0, subnormals), empty and long
//! arrays, non-ASCII strings.
//!
//! The cases are written twice on purpose, here and in `tests/python/golden.py`, so that neither side
//! can agree with itself by construction.

mod support;

use support::golden_values::*;

use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, PolicyWeights, TrainerStatus, Transition};
use equiarm_msgs::rosgraph_msgs::Clock;
use equiarm_msgs::sensor_msgs::{CameraInfo, Image, RegionOfInterest};
use equiarm_msgs::std_msgs::Header;
use equiarm_msgs::{RosMessage, cdr};
use std::collections::BTreeMap;

/// One golden case: its encoder and a re-encoder of decoded bytes (to prove decode is exact).
struct Case {
    type_short: &'static str,
    definition: &'static str,
    encode: Box<dyn Fn() -> Vec<u8>>,
    reencode: fn(&[u8]) -> Result<Vec<u8>, cdr::CdrError>,
}

fn case<M: RosMessage>(value: M) -> Case {
    Case {
        type_short: M::NAME,
        definition: M::DEFINITION,
        encode: Box::new(move || cdr::encode(&value).unwrap()),
        reencode: |b| cdr::encode(&cdr::decode::<M>(b)?),
    }
}

fn cases() -> BTreeMap<String, Case> {
    let mut c = BTreeMap::new();
    let mut add = |name: &str, k: Case| {
        c.insert(name.to_string(), k);
    };
    add("Time.default", case(Time::default()));
    add("Header.default", case(Header::default()));
    add("Image.default", case(Image::default()));
    add("RegionOfInterest.default", case(RegionOfInterest::default()));
    add("CameraInfo.default", case(CameraInfo::default()));
    add("GripperCommand.default", case(GripperCommand::default()));
    add("Observation.default", case(Observation::default()));
    add("Transition.default", case(Transition::default()));
    add("EpisodeResult.default", case(EpisodeResult::default()));
    add("PolicyWeights.default", case(PolicyWeights::default()));
    add("TrainerStatus.default", case(TrainerStatus::default()));
    add("Clock.default", case(Clock::default()));
    add("Time.special", case(Time { sec: i32::MIN, nanosec: 999_999_999 }));
    add("Clock.special", case(Clock { clock: Time { sec: i32::MAX, nanosec: 166_666_667 } }));
    add("Header.special", case(header(1_700_000_000, 123_456_789, TEXT)));
    add("Image.rgb8", case(rgb8(152, 152, "camera_color_optical_frame")));
    add("Image.depth", case(depth(152, 152, TEXT, 1)));
    add(
        "RegionOfInterest.special",
        case(RegionOfInterest { x_offset: u32::MAX, y_offset: 0, height: 7, width: 8, do_rectify: true }),
    );
    add(
        "CameraInfo.special",
        case(CameraInfo {
            header: header(5, 6, "camera"),
            height: 152,
            width: 152,
            distortion_model: "plumb_bob".into(),
            d: vec![NAN64, -0.0, f64::INFINITY, f64::NEG_INFINITY, SUB64],
            k: std::array::from_fn(|i| 0.5 * i as f64 - 2.0),
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [f64::MAX, -f64::MAX, SUB64, -0.0, NAN64, f64::INFINITY, f64::NEG_INFINITY, 1.0, 2.0, 3.0, 0.25, -0.125],
            binning_x: u32::MAX,
            binning_y: 0,
            roi: RegionOfInterest { x_offset: 1, y_offset: 2, height: 3, width: 4, do_rectify: true },
        }),
    );
    add("GripperCommand.special", case(command_special()));
    add("GripperCommand.typical", case(command_typical()));
    add("Observation.special", case(observation(u64::MAX - 1, 152, 2)));
    add(
        "Transition.special",
        case(Transition {
            header: header(7, 8, "world"),
            env: TEXT.into(),
            episode: u32::MAX,
            step: 49,
            obs_seq: u64::MAX - 1,
            next_obs_seq: u64::MAX,
            action: command_special(),
            reward: 1.0,
            done: true,
            timeout: false,
            expert: true,
        }),
    );
    add(
        "EpisodeResult.special",
        case(EpisodeResult {
            header: header(9, 10, "world"),
            env: "环境1".into(),
            task: "block_picking".into(),
            seed: u64::MAX,
            episode: 7,
            steps: 50,
            success: true,
            ret: 1.0,
            discounted_return: NAN32,
            expert: false,
            eval: true,
        }),
    );
    add(
        "PolicyWeights.special",
        case(PolicyWeights {
            header: header(11, 12, ""),
            run_id: "run-7f3a".into(),
            version: 1,
            updates: 1 << 40,
            model: "equi_d4".into(),
            format: "safetensors".into(),
            data: ramp(1 << 20, 31, 17),
        }),
    );
    add(
        "TrainerStatus.special",
        case(TrainerStatus {
            header: header(13, 14, ""),
            updates: 5000,
            transitions: 1 << 33,
            buffer_size: 100_000,
            expert_transitions: 0,
            critic_loss: NAN32,
            actor_loss: -0.0,
            alpha: f32::INFINITY,
            updates_per_s: f32::NEG_INFINITY,
            transitions_per_s: SUB32,
            last_eval_return: f32::MAX,
            last_eval_success_rate: 0.75,
            last_eval_episodes: u32::MAX,
        }),
    );
    c
}

#[test]
fn cdr_bytes_equal_cyclonedds_and_rosbags_and_decode_both_ways() {
    let dir = support::scratch("golden_cdr");
    let mut encode = support::python_script("golden.py");
    encode.arg("encode").arg(&dir);
    support::run_ok(encode);

    let cases = cases();
    std::fs::create_dir_all(dir.join("rs")).unwrap();
    let mut failures = Vec::new();
    let mut py_names: Vec<String> = std::fs::read_dir(dir.join("py"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().trim_end_matches(".cdr").to_string())
        .collect();
    py_names.sort();
    assert_eq!(py_names, cases.keys().cloned().collect::<Vec<_>>(), "the two case lists differ");
    for (name, c) in &cases {
        let ours = (c.encode)();
        let theirs = std::fs::read(dir.join("py").join(format!("{name}.cdr"))).unwrap();
        if ours != theirs {
            let at = ours.iter().zip(&theirs).position(|(a, b)| a != b).unwrap_or(ours.len().min(theirs.len()));
            failures.push(format!(
                "{name}: our {} bytes differ from Cyclone's {} at byte {at}",
                ours.len(),
                theirs.len()
            ));
        }
        // Decoding their bytes and encoding again gives their bytes back: since encoding is injective,
        // the decoded value equals the case bit for bit (the first check pins the encoder).
        match (c.reencode)(&theirs) {
            Ok(again) if again == theirs => {}
            Ok(_) => failures.push(format!("{name}: decoding Cyclone's bytes lost information")),
            Err(e) => failures.push(format!("{name}: Cyclone's bytes do not decode: {e}")),
        }
        std::fs::write(dir.join("rs").join(format!("{name}.cdr")), &ours).unwrap();
        std::fs::write(dir.join("rs").join(format!("{}.msgdef", c.type_short)), c.definition).unwrap();
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));

    let mut check = support::python_script("golden.py");
    check.arg("check").arg(&dir);
    let out = support::run_ok(check);
    assert!(out.contains(&format!("golden check: {} cases, 0 mismatches", cases.len())), "{out}");
}

/// Spot checks that the decoded values themselves are right (not only the bytes).
#[test]
fn decoded_special_values_keep_their_bits() {
    let b = cdr::encode(&command_special()).unwrap();
    let c: GripperCommand = cdr::decode(&b).unwrap();
    assert_eq!(c.open_ratio.to_bits(), 0x7fc0_0001);
    assert_eq!(c.dx.to_bits(), 0x8000_0000);
    assert_eq!(c.dtheta.to_bits(), 1);
    assert_eq!(c.obs_seq, u64::MAX);
    let h: Header = cdr::decode(&cdr::encode(&header(0, 0, TEXT)).unwrap()).unwrap();
    assert_eq!(h.frame_id, TEXT);
}
