//! Reading a bag's `metadata.yaml` back and checking it against the files: rosbag2 tools trust it
//! (file list, counts, time span), so a stale or damaged one is reported rather than ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use yaml_rust2::parser::{Event, Parser};
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
    let size = match std::fs::metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
        Err(e) => return Some(MetadataCheck { problems: vec![format!("cannot be read: {e}")], path }),
        Ok(m) => m.len(),
    };
    if size > MAX_BYTES {
        let why = format!("is {size} bytes, more than the {MAX_BYTES} read: not read");
        return Some(MetadataCheck { problems: vec![why], path });
    }
    let text = match std::fs::read(&path) {
        Err(e) => return Some(MetadataCheck { problems: vec![format!("cannot be read: {e}")], path }),
        Ok(bytes) => String::from_utf8_lossy(&bytes).into_owned(),
    };
    let mut problems = Vec::new();
    compare(&text, info, &mut problems);
    Some(MetadataCheck { path, problems })
}

/// The files `dir/metadata.yaml` lists that are not in `dir` (empty when it has no readable
/// metadata: `check` reports why).
pub(crate) fn listed_but_missing(dir: &Path) -> Vec<String> {
    let path = dir.join("metadata.yaml");
    let small = std::fs::metadata(&path).is_ok_and(|m| m.len() <= MAX_BYTES);
    let Some(text) = small.then(|| std::fs::read(&path).ok()).flatten() else { return Vec::new() };
    let text = String::from_utf8_lossy(&text);
    if unbounded(&text).is_some() {
        return Vec::new();
    }
    let docs = YamlLoader::load_from_str(&text).unwrap_or_default();
    let Some(listed) = docs.first().and_then(|d| d["rosbag2_bagfile_information"]["relative_file_paths"].as_vec())
    else {
        return Vec::new();
    };
    listed.iter().filter_map(Yaml::as_str).filter(|n| !dir.join(n).exists()).map(str::to_string).collect()
}

/// The `metadata.yaml` versions rosbag2 has written, up to Jazzy's 8 (the one we write); the fields
/// checked here have meant the same in all of them.
const KNOWN_VERSIONS: std::ops::RangeInclusive<u64> = 1..=8;
/// Largest `metadata.yaml` read (one of a bag of 10,000 files and 1,000 topics is about 2 MB).
const MAX_BYTES: u64 = 16 << 20;

/// Why `text` is not loaded into a tree, if it is not: YAML that uses an alias, which the loader
/// expands by copying the node it names, so a few kB of aliases of aliases become gigabytes; rosbag2
/// never writes one. Read as a stream of events, which costs the text's size; a syntax error is left
/// to the loader to report (its parser also refuses nesting deeper than about 250 levels).
fn unbounded(text: &str) -> Option<String> {
    let mut parser = Parser::new_from_str(text);
    loop {
        match parser.next_token() {
            Err(_) | Ok((Event::StreamEnd, _)) => return None,
            Ok((Event::Alias(_), mark)) => {
                return Some(format!(
                    "uses a YAML alias (line {}): rosbag2 never writes one, and its expansion is unbounded; not read",
                    mark.line()
                ));
            }
            Ok(_) => {}
        }
    }
}

fn compare(text: &str, info: &BagInfo, problems: &mut Vec<String>) {
    if let Some(why) = unbounded(text) {
        return problems.push(why);
    }
    let docs = match YamlLoader::load_from_str(text) {
        Ok(d) => d,
        Err(e) => return problems.push(format!("not YAML: {e}")),
    };
    let m = match docs.first().map(|d| &d["rosbag2_bagfile_information"]) {
        Some(m @ Yaml::Hash(_)) => m,
        _ => return problems.push("has no `rosbag2_bagfile_information` map: not rosbag2 metadata".into()),
    };
    match int(&m["version"]) {
        Some(v) if KNOWN_VERSIONS.contains(&v) => {}
        Some(v) => problems.push(format!(
            "version is {v}, which this reader does not know ({}..={}): its fields may mean something else",
            KNOWN_VERSIONS.start(),
            KNOWN_VERSIONS.end()
        )),
        None => problems.push("version is missing or not a number".into()),
    }
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
