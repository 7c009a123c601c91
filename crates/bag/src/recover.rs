//! Rewrites a bag whose recorder was killed (files without summary, footer or `metadata.yaml`) as a
//! complete, indexed bag: every message of every intact chunk, with its original topics, schemas,
//! QoS metadata and times. Damaged chunks are skipped and reported, the chunks after them kept.
//!
//! Schema and channel records outside chunks carry no checksum, so each channel is checked for sense
//! before anything of it is copied (a `ros2msg` schema whose name is a ROS 2 type and whose text is a
//! message definition, `cdr` messages, a topic name): a damaged one is reported and its messages are
//! left out rather than copied into a bag that would then look complete. Files that `metadata.yaml`
//! lists but that are gone are reported too.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::{BagError, BagSummary, ReadMode, Reader, TopicId, TopicInfo, Writer, WriterOptions};

/// What [`recover`] did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecoverReport {
    /// The new bag.
    pub summary: BagSummary,
    /// Input files that ended early, with the reason reading stopped there.
    pub truncated: Vec<(PathBuf, String)>,
    /// Damaged chunks skipped, with their time ranges and (where indexed) message counts.
    pub lost: Vec<crate::LostChunk>,
    /// Channels whose schema or channel record is damaged: their messages are not copied.
    pub damaged_channels: Vec<DamagedChannel>,
    /// Files `metadata.yaml` lists that are not in the bag directory.
    pub missing_files: Vec<String>,
}

/// A channel left out by [`recover`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DamagedChannel {
    /// Its topic, as recorded (possibly damaged itself).
    pub topic: String,
    /// Its type (the schema's name), as recorded.
    pub type_name: String,
    /// What is wrong with it.
    pub reason: String,
    /// Its messages that were not copied.
    pub messages: u64,
}

/// Reads everything readable from `input` (a bag directory or an `.mcap` file) and writes it to the
/// new bag directory `output`.
pub fn recover(input: &Path, output: &Path, opts: WriterOptions) -> Result<RecoverReport, BagError> {
    let reader = Reader::open(input)?;
    let missing_files = match input.is_dir() {
        true => crate::metadata_check::listed_but_missing(input),
        false => Vec::new(),
    };
    let mut writer = Writer::create(output, opts)?;
    // per channel (topic, type): its id in the new bag, or the index of its entry in `damaged`
    let mut topics: HashMap<(String, String), Result<TopicId, usize>> = HashMap::new();
    let mut damaged: Vec<DamagedChannel> = Vec::new();
    let report = reader.for_each(ReadMode::Salvage, |m| {
        let key = (m.topic.to_string(), m.type_name.to_string());
        let id = match topics.get(&key) {
            Some(&id) => id,
            None => {
                let id = match channel_problem(m.channel) {
                    Some(reason) => {
                        let (topic, type_name) = key.clone();
                        damaged.push(DamagedChannel { topic, type_name, reason, messages: 0 });
                        Err(damaged.len() - 1)
                    }
                    None => {
                        let schema = m.channel.schema.as_ref();
                        let meta = |k: &str| m.channel.metadata.get(k).cloned().unwrap_or_default();
                        writer
                            .add_topic(TopicInfo {
                                name: m.topic.to_string(),
                                type_name: m.type_name.to_string(),
                                schema_encoding: schema.map(|s| s.encoding.clone()).unwrap_or_default(),
                                schema: schema.map(|s| s.data.to_vec()).unwrap_or_default(),
                                offered_qos: meta("offered_qos_profiles"),
                                type_hash: meta("topic_type_hash"),
                            })
                            .map(Ok)?
                    }
                };
                topics.insert(key, id);
                id
            }
        };
        match id {
            Ok(id) => writer.write(id, m.log_time, m.publish_time, m.data),
            Err(k) => {
                damaged[k].messages += 1;
                Ok(())
            }
        }
    })??;
    let summary = writer.finish()?;
    Ok(RecoverReport {
        summary,
        truncated: report.truncated,
        lost: report.lost,
        damaged_channels: damaged,
        missing_files,
    })
}

/// What is wrong with a channel and its schema, if anything: what a rosbag2 bag of ROS 2 messages
/// needs for its messages to mean anything to a reader.
fn channel_problem(ch: &mcap::Channel<'_>) -> Option<String> {
    if !ros_name(&ch.topic) {
        return Some(format!("the topic name {:?} is not a ROS 2 name", equiarm_msgs::shown(&ch.topic)));
    }
    if ch.message_encoding != "cdr" {
        return Some(format!("its messages are encoded as {:?}, not cdr", equiarm_msgs::shown(&ch.message_encoding)));
    }
    let Some(schema) = ch.schema.as_ref() else {
        return Some("it has no schema".into());
    };
    if schema.encoding != "ros2msg" {
        return Some(format!("its schema is encoded as {:?}, not ros2msg", equiarm_msgs::shown(&schema.encoding)));
    }
    if !type_name(&schema.name) {
        return Some(format!(
            "its schema's name {:?} is not a ROS 2 type (pkg/msg/Type)",
            equiarm_msgs::shown(&schema.name)
        ));
    }
    let Ok(text) = std::str::from_utf8(&schema.data) else {
        return Some("its schema's text is not UTF-8".into());
    };
    definition_problem(text).map(|p| format!("its schema's text is not a message definition: {p}"))
}

fn ident(s: &str) -> bool {
    let mut c = s.chars();
    c.next().is_some_and(|f| f.is_ascii_alphabetic()) && c.all(|x| x.is_ascii_alphanumeric() || x == '_')
}

/// `/a/b_c` (or a relative `a/b`): segments of letters, digits and `_`, not starting with a digit.
fn ros_name(s: &str) -> bool {
    let s = s.strip_prefix('/').unwrap_or(s);
    !s.is_empty()
        && s.split('/').all(|seg| {
            seg.chars().next().is_some_and(|f| !f.is_ascii_digit())
                && seg.chars().all(|x| x.is_ascii_alphanumeric() || x == '_')
                && !seg.is_empty()
        })
}

/// `pkg/msg/Type` (or `pkg/Type`).
fn type_name(s: &str) -> bool {
    match s.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, "msg", ty] | [pkg, ty] => ident(pkg) && ident(ty),
        _ => false,
    }
}

/// The first line of `text` that is not a line of a `.msg` definition (a field `TYPE NAME [DEFAULT]`,
/// a constant `TYPE NAME=VALUE`, a comment, a blank line, or the `===` / `MSG: pkg/Type` separators of
/// nested definitions), if any.
fn definition_problem(text: &str) -> Option<String> {
    let mut fields = 0;
    for (i, line) in text.lines().enumerate() {
        let code = line.split('#').next().unwrap_or("").trim();
        if code.is_empty() || (code.starts_with("===") && code.chars().all(|c| c == '=')) {
            continue;
        }
        if let Some(t) = code.strip_prefix("MSG:") {
            if type_name(t.trim()) {
                continue;
            }
            return Some(format!("line {}: {:?} names no type", i + 1, equiarm_msgs::shown(line)));
        }
        let mut parts = code.splitn(2, char::is_whitespace);
        let (ty, rest) = (parts.next().unwrap_or(""), parts.next().unwrap_or("").trim_start());
        let name = rest.split(|c: char| c == '=' || c.is_whitespace()).next().unwrap_or("");
        if !field_type(ty) || !ident(name) {
            return Some(format!("line {}: {:?} is not `TYPE NAME`", i + 1, equiarm_msgs::shown(line)));
        }
        fields += 1;
    }
    (fields == 0).then(|| "it declares no field".to_string())
}

/// A field type: a name (`float32`, `Header`, `std_msgs/Header`), with a string bound (`string<=8`)
/// and an array suffix (`[]`, `[4]`, `[<=4]`) allowed.
fn field_type(t: &str) -> bool {
    let (base, array) = match t.split_once('[') {
        Some((b, a)) => (b, Some(a)),
        None => (t, None),
    };
    let array_ok = array.is_none_or(|a| {
        a.strip_suffix(']').is_some_and(|n| {
            let n = n.strip_prefix("<=").unwrap_or(n);
            n.is_empty() || n.chars().all(|c| c.is_ascii_digit())
        })
    });
    let base = match base.split_once("<=") {
        Some((b, n)) if !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()) => b,
        Some(_) => return false,
        None => base,
    };
    let name_ok = match base.split('/').collect::<Vec<_>>().as_slice() {
        [ty] => ident(ty),
        [pkg, ty] | [pkg, "msg", ty] => ident(pkg) && ident(ty),
        _ => false,
    };
    array_ok && name_ok
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_definition_we_write_is_one_and_damaged_lines_are_not() {
        for t in equiarm_msgs::ALL_TYPES {
            assert_eq!(definition_problem(t.definition), None, "{}", t.type_name);
            assert!(type_name(t.type_name), "{}", t.type_name);
        }
        for ok in
            ["string<=8 name", "float32[4] q", "uint8[<=16] b", "int32 X=3", "bool flag true", "geometry_msgs/Pose p"]
        {
            assert_eq!(definition_problem(ok), None, "{ok}");
        }
        for bad in ["uint64obs_seq", "uint64 1seq", "float32[x] q", "string<= s", "a/b/c/d x", "", "# only a comment"] {
            assert!(definition_problem(bad).is_some(), "{bad:?}");
        }
        assert!(ros_name("/env0/gripper_cmd") && !ros_name("/env0//x") && !ros_name("/0env") && !ros_name(""));
    }
}
