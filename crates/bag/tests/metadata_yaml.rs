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

/// Regression (issue 61): a 4 KB `metadata.yaml` of aliases of aliases made `bag info` grow past
/// 11 GB (the loader copies each alias's node), and a version 99 was accepted as matching; deep
/// nesting is refused by the YAML parser itself.
#[test]
fn an_alias_bomb_a_deep_nest_and_an_unknown_version_are_reported_without_expanding() {
    let dir = bag("aliases");
    let mut bomb = String::from("a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n");
    for k in 1..40 {
        let prev = format!("*a{}", k - 1);
        bomb.push_str(&format!("a{k}: &a{k} [{}]\n", vec![prev; 10].join(", ")));
    }
    bomb.push_str("rosbag2_bagfile_information: *a39\n");
    std::fs::write(dir.join("metadata.yaml"), &bomb).unwrap();
    assert!(bomb.len() < 4096, "{}", bomb.len());
    let p = problems(&dir).unwrap();
    assert_eq!(p.len(), 1, "{p:?}");
    assert!(p[0].contains("uses a YAML alias (line 2)"), "{p:?}");

    std::fs::write(dir.join("metadata.yaml"), format!("{}1{}", "[".repeat(100_000), "]".repeat(100_000))).unwrap();
    let p = problems(&dir).unwrap();
    assert!(p[0].contains("not YAML: recursion limit exceeded"), "the parser's own bound: {p:?}");

    let dir = bag("version");
    edit(&dir, |y| y.replacen("version: 8", "version: 99", 1));
    let p = problems(&dir).unwrap();
    assert_eq!(p.len(), 1, "{p:?}");
    assert!(p[0].contains("version is 99, which this reader does not know (1..=8)"), "{p:?}");
}
