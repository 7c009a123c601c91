//! Reading a bag's `metadata.yaml` back and checking it against the files: rosbag2 tools trust it
//! (file list, counts, time span), so a stale or damaged one is reported rather than ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use yaml_rust2::{Yaml, YamlLoader};

use crate::BagInfo;

/// What `metadata.yaml` says, and where it disagrees with the files.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MetadataCheck {
    /// The file checked.
    pub path: PathBuf,
    /// Each disagreement or defect, in words (empty: the metadata matches the files).
    pub problems: Vec<String>,
}

impl MetadataCheck {
    /// Whether the metadata matches the files.
    pub fn ok(&self) -> bool {
        self.problems.is_empty()
    }
}

fn int(y: &Yaml) -> Option<u64> {
    y.as_i64().and_then(|v| u64::try_from(v).ok())
}

/// Checks `dir/metadata.yaml` against `info` (a full read of the bag's files); `None` when `dir` has
/// no `metadata.yaml` (a recorder that was killed, or a single `.mcap` file).
pub fn check(dir: &Path, info: &BagInfo) -> Option<MetadataCheck> {
    let path = dir.join("metadata.yaml");
    let text = match std::fs::read(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
        Err(e) => return Some(MetadataCheck { problems: vec![format!("cannot be read: {e}")], path }),
        Ok(bytes) => String::from_utf8_lossy(&bytes).into_owned(),
    };
    let mut problems = Vec::new();
    compare(&text, info, &mut problems);
    Some(MetadataCheck { path, problems })
}

fn compare(text: &str, info: &BagInfo, problems: &mut Vec<String>) {
    let docs = match YamlLoader::load_from_str(text) {
        Ok(d) => d,
        Err(e) => return problems.push(format!("not YAML: {e}")),
    };
    let m = match docs.first().map(|d| &d["rosbag2_bagfile_information"]) {
        Some(m @ Yaml::Hash(_)) => m,
        _ => return problems.push("has no `rosbag2_bagfile_information` map: not rosbag2 metadata".into()),
    };
    match m["storage_identifier"].as_str() {
        Some("mcap") => {}
        other => problems.push(format!("storage_identifier is {other:?}, not \"mcap\"")),
    }
    // The files: listed ones that are missing, present ones that are not listed.
    let on_disk: BTreeMap<String, &crate::FileInfo> =
        info.files.iter().filter_map(|f| Some((f.path.file_name()?.to_string_lossy().into_owned(), f))).collect();
    let listed: Vec<String> = match m["relative_file_paths"].as_vec() {
        Some(v) => v.iter().filter_map(|p| p.as_str().map(str::to_string)).collect(),
        None => {
            problems.push("relative_file_paths is missing or not a list".into());
            Vec::new()
        }
    };
    for name in &listed {
        if !on_disk.contains_key(name) {
            problems.push(format!("lists {name}, which is not in the bag directory"));
        }
    }
    for name in on_disk.keys().filter(|n| !listed.contains(n)) {
        problems.push(format!("does not list {name} (a recorder killed before it finished? `equiarm bag recover`)"));
    }
    // Counts: the bag, each file, each topic.
    match int(&m["message_count"]) {
        Some(n) if n != info.messages => {
            problems.push(format!("message_count is {n}, the files hold {} readable messages", info.messages))
        }
        Some(_) => {}
        None => problems.push("message_count is missing or not a count".into()),
    }
    for f in m["files"].as_vec().into_iter().flatten() {
        let (Some(name), Some(n)) = (f["path"].as_str(), int(&f["message_count"])) else {
            problems.push("an entry of `files` has no path or message_count".into());
            continue;
        };
        if let Some(file) = on_disk.get(name)
            && file.messages != n
        {
            problems.push(format!("says {name} holds {n} messages, it holds {} readable ones", file.messages));
        }
    }
    let mut topics = BTreeMap::new();
    for t in m["topics_with_message_count"].as_vec().into_iter().flatten() {
        let (Some(name), Some(n)) = (t["topic_metadata"]["name"].as_str(), int(&t["message_count"])) else {
            problems.push("an entry of `topics_with_message_count` has no topic name or message_count".into());
            continue;
        };
        topics.insert(name.to_string(), n);
    }
    for (name, n) in &topics {
        let got = info.topics.get(name).map_or(0, |t| t.count);
        if got != *n {
            problems.push(format!("says topic {name} has {n} messages, the files hold {got}"));
        }
    }
    for name in info.topics.keys().filter(|n| !topics.contains_key(*n)) {
        problems.push(format!("does not list topic {name}"));
    }
}
