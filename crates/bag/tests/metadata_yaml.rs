//! Regression (issue 28): `metadata.yaml` was ignored whatever it held. It is read back and checked
//! against the files; `bag info` reports each disagreement.

use std::path::{Path, PathBuf};

use equiarm_bag::{Reader, TopicInfo, Writer, WriterOptions};
use equiarm_msgs::cdr;
use equiarm_msgs::msg::GripperCommand;

const T0: u64 = 1_700_000_000_000_000_000;

/// A finished bag of 12 commands on two topics.
fn bag(name: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("metadata_yaml").join(name);
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let mut w = Writer::create(&root.join("bag"), WriterOptions::default()).unwrap();
    let qos = [equiarm_bag::qos::OfferedQos::reliable(10)];
    let a = w.add_topic(TopicInfo::of::<GripperCommand>("/env0/gripper_cmd", &qos)).unwrap();
    let b = w.add_topic(TopicInfo::of::<GripperCommand>("/env1/gripper_cmd", &qos)).unwrap();
    for k in 0..12u64 {
        let m = GripperCommand { obs_seq: k, ..Default::default() };
        w.write(if k % 3 == 0 { b } else { a }, T0 + k, T0 + k, &cdr::encode(&m).unwrap()).unwrap();
    }
    w.finish().unwrap().dir
}

fn problems(dir: &Path) -> Option<Vec<String>> {
    Reader::open(dir).unwrap().info().unwrap().metadata.map(|m| m.problems)
}

fn edit(dir: &Path, f: impl Fn(String) -> String) {
    let p = dir.join("metadata.yaml");
    std::fs::write(&p, f(std::fs::read_to_string(&p).unwrap())).unwrap();
}

#[test]
fn metadata_as_written_matches_the_files() {
    let dir = bag("as_written");
    assert_eq!(problems(&dir), Some(vec![]));
}

#[test]
fn stale_or_damaged_metadata_is_reported_naming_what_disagrees() {
    let dir = bag("counts");
    edit(&dir, |y| {
        y.replacen("message_count: 12", "message_count: 13", 1).replacen("message_count: 8", "message_count: 9", 1)
    });
    let p = problems(&dir).unwrap();
    assert!(p.iter().any(|s| s.contains("message_count is 13") && s.contains("12 readable")), "{p:?}");
    assert!(p.iter().any(|s| s.contains("/env0/gripper_cmd has 9 messages") && s.contains("hold 8")), "{p:?}");

    let dir = bag("files");
    edit(&dir, |y| y.replace("bag_0.mcap", "bag_7.mcap"));
    let p = problems(&dir).unwrap();
    assert!(p.iter().any(|s| s.contains("lists bag_7.mcap, which is not in the bag directory")), "{p:?}");
    assert!(p.iter().any(|s| s.contains("does not list bag_0.mcap")), "{p:?}");

    let dir = bag("garbage");
    std::fs::write(dir.join("metadata.yaml"), "{ not: [ yaml").unwrap();
    assert!(problems(&dir).unwrap()[0].contains("not YAML"));
    std::fs::write(dir.join("metadata.yaml"), "just: text\n").unwrap();
    assert!(problems(&dir).unwrap()[0].contains("not rosbag2 metadata"));

    // No metadata.yaml (a killed recorder): nothing to check, and said so by `None`.
    std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
    assert_eq!(problems(&dir), None);
}
