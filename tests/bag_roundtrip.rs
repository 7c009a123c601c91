//! Bags written by equiarm read back with identical values by third-party readers: Python `mcap` +
//! `mcap-ros2-support` (decoding from the embedded schemas) and `rosbags`' AnyReader (from the
//! definitions in the file). Every compression, a split bag, our own reader, and damaged input.

mod support;

use std::path::Path;

use equiarm_bag::qos::OfferedQos;
use equiarm_bag::{BagError, Compression, ReadMode, Reader, TopicInfo, Writer, WriterOptions};
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation};
use equiarm_msgs::sensor_msgs::Image;
use equiarm_msgs::{RosMessage, cdr};
use support::golden_values::*;

const T0: u64 = 1_700_000_000_000_000_000;
const DT: u64 = 1_000_000;

fn gripper(k: u32) -> GripperCommand {
    GripperCommand {
        header: header(k as i32, 7, "world"),
        obs_seq: k as u64,
        open_ratio: k as f32 * 0.25,
        dx: k as f32 * -0.5,
        dy: 0.125,
        dz: if k == 0 { NAN32 } else { 0.0 },
        dtheta: k as f32,
        source: (k % 4) as u8,
    }
}

fn episode(k: u32) -> EpisodeResult {
    let success = k.is_multiple_of(3);
    EpisodeResult {
        header: header(k as i32, 0, "world"),
        env: format!("env{}", k % 2),
        task: "block_pulling".into(),
        seed: k as u64,
        episode: k,
        steps: 10 + k,
        success,
        ret: if success { 1.0 } else { 0.0 },
        discounted_return: 0.5,
        expert: k.is_multiple_of(2),
        eval: false,
    }
}

/// Topic name, type, count, and the k-th payload.
struct Stream {
    topic: &'static str,
    info: TopicInfo,
    count: u32,
    make: Box<dyn Fn(u32) -> Vec<u8>>,
}

fn streams() -> Vec<Stream> {
    fn s<M: RosMessage>(topic: &'static str, qos: OfferedQos, count: u32, f: fn(u32) -> M) -> Stream {
        Stream {
            topic,
            info: TopicInfo::of::<M>(topic, &[qos]),
            count,
            make: Box::new(move |k| cdr::encode(&f(k)).unwrap()),
        }
    }
    vec![
        s("/env0/gripper_cmd", OfferedQos::reliable(10), 40, gripper),
        s("/env0/observation", OfferedQos::reliable(10), 25, |k| observation(k as u64, 64, k)),
        s("/episodes", OfferedQos::reliable(100), 12, episode),
        s("/env0/camera/color/image_raw", OfferedQos::best_effort(1), 30, |_| rgb8(8, 8, "camera")),
    ]
}

/// Writes the streams interleaved, message i of the whole bag at T0 + i*DT per topic index.
fn write_bag(dir: &Path, opts: WriterOptions) -> equiarm_bag::BagSummary {
    let streams = streams();
    let mut w = Writer::create(dir, opts).unwrap();
    let ids: Vec<_> = streams.iter().map(|s| w.add_topic(s.info.clone()).unwrap()).collect();
    let max = streams.iter().map(|s| s.count).max().unwrap();
    for k in 0..max {
        for (s, id) in streams.iter().zip(&ids) {
            if k < s.count {
                let t = T0 + k as u64 * DT;
                w.write(*id, t, t - 1000, &(s.make)(k)).unwrap();
            }
        }
        w.flush_if_due(k as u64 * DT).unwrap();
    }
    w.finish().unwrap()
}

fn expected_json(dir: &Path) -> std::path::PathBuf {
    let streams = streams();
    let counts: serde_json::Map<_, _> = streams.iter().map(|s| (s.topic.to_string(), s.count.into())).collect();
    let types: serde_json::Map<_, _> =
        streams.iter().map(|s| (s.topic.to_string(), s.info.type_name.clone().into())).collect();
    let v = serde_json::json!({"counts": counts, "types": types, "values": "synthetic", "t0": T0, "dt": DT});
    let p = dir.with_extension("expected.json");
    std::fs::write(&p, v.to_string()).unwrap();
    p
}

fn python_check(bag: &Path) -> serde_json::Value {
    let mut c = support::python_script("bag_check.py");
    c.arg(bag).arg(expected_json(bag));
    let out = support::run_ok(c);
    serde_json::from_str(out.lines().last().unwrap()).unwrap()
}

fn check_with_our_reader(bag: &Path) {
    let streams = streams();
    let reader = Reader::open(bag).unwrap();
    let mut k = std::collections::HashMap::<String, u32>::new();
    let report = reader
        .for_each(ReadMode::Strict, |m| {
            let s = streams.iter().find(|s| s.topic == m.topic).expect("unknown topic");
            let i = k.entry(m.topic.to_string()).or_default();
            assert_eq!(m.data, (s.make)(*i).as_slice(), "{}[{i}]", m.topic);
            assert_eq!(m.type_name, s.info.type_name);
            assert_eq!(m.log_time, T0 + *i as u64 * DT);
            *i += 1;
            Ok::<(), ()>(())
        })
        .unwrap()
        .unwrap();
    assert_eq!(report.messages, streams.iter().map(|s| s.count as u64).sum::<u64>());
    let info = reader.info().unwrap();
    assert_eq!(info.topics["/env0/observation"].count, 25);
    assert_eq!(info.topics["/env0/observation"].type_name, Observation::TYPE_NAME);
    assert!(info.files.iter().all(|f| f.complete));
}

#[test]
fn bags_read_back_identically_in_mcap_and_rosbags_for_every_compression() {
    for (name, compression) in [("zstd", Compression::Zstd), ("lz4", Compression::Lz4), ("none", Compression::None)] {
        let dir = support::scratch(&format!("bag_{name}")).join("run");
        let summary = write_bag(&dir, WriterOptions { compression, chunk_size: 64 << 10, ..Default::default() });
        assert_eq!(summary.files, ["run_0.mcap"]);
        assert_eq!(summary.messages, 107);
        let yaml = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
        assert!(yaml.starts_with("rosbag2_bagfile_information:\n  version: 8\n"), "{yaml}");
        assert!(yaml.contains("message_count: 107"));
        check_with_our_reader(&dir);
        let seen = python_check(&dir);
        assert_eq!(seen["errors"], 0, "{name}: {seen}");
    }
}

#[test]
fn a_bag_split_by_size_reads_as_one() {
    let dir = support::scratch("bag_split").join("split");
    let opts = WriterOptions { split_bytes: Some(8 << 10), chunk_size: 16 << 10, ..Default::default() };
    let summary = write_bag(&dir, opts);
    assert!(summary.files.len() >= 3, "{:?}", summary.files);
    assert_eq!(Reader::open(&dir).unwrap().paths().len(), summary.files.len());
    check_with_our_reader(&dir);
    let seen = python_check(&dir);
    assert_eq!(seen["errors"], 0, "{seen}");
}

#[test]
fn bad_files_give_errors_naming_the_file() {
    let dir = support::scratch("bag_bad");
    let empty = dir.join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let e = Reader::open(&empty).err().unwrap();
    assert!(matches!(e, BagError::Empty { .. }) && e.to_string().contains("empty.mcap"), "{e}");

    let text = dir.join("notes.mcap");
    std::fs::write(&text, b"this is not a bag\n").unwrap();
    let e = Reader::open(&text).err().unwrap();
    assert!(matches!(e, BagError::NotMcap { .. }) && e.to_string().contains("notes.mcap"), "{e}");

    let e = Reader::open(&dir.join("missing")).err().unwrap();
    assert!(e.to_string().contains("missing"), "{e}");
    let nothing = dir.join("nothing");
    std::fs::create_dir(&nothing).unwrap();
    assert!(matches!(Reader::open(&nothing).err().unwrap(), BagError::NoFiles { .. }));

    // a good bag cut short: strict reading fails naming the file, salvage reading gets the whole chunks
    let good = dir.join("good");
    write_bag(&good, WriterOptions { chunk_size: 16 << 10, ..Default::default() });
    let file = good.join("good_0.mcap");
    let bytes = std::fs::read(&file).unwrap();
    for cut in [9, bytes.len() / 2, bytes.len() - 10] {
        let cut_file = dir.join(format!("cut_{cut}.mcap"));
        std::fs::write(&cut_file, &bytes[..cut]).unwrap();
        let r = Reader::open(&cut_file).unwrap();
        let e = r.for_each(ReadMode::Strict, |_| Ok::<(), ()>(())).err().unwrap();
        assert!(e.to_string().contains(&format!("cut_{cut}.mcap")), "{e}");
        let report = r.for_each(ReadMode::Salvage, |_| Ok::<(), ()>(())).unwrap().unwrap();
        assert_eq!(report.truncated.len(), 1);
        assert!(report.messages <= 107);
        if cut == bytes.len() - 10 {
            assert_eq!(report.messages, 107, "only the footer was cut");
        }
    }
    // writing into a non-empty directory is refused
    let e = Writer::create(&good, WriterOptions::default()).err().unwrap();
    assert!(matches!(e, BagError::Exists { .. }), "{e}");
    let _ = Image::default();
}
