//! rosbag2's `metadata.yaml` (version 8) and the `serialized_metadata` of the `rosbag2` MCAP record,
//! written by hand: the structure is fixed and small, and strings are emitted double-quoted.

use std::fmt::Write as _;

use crate::Nanos;

/// What rosbag2 records about one topic.
#[derive(Clone, Debug)]
pub(crate) struct TopicMeta {
    pub name: String,
    pub type_name: String,
    pub offered_qos: String,
    pub type_hash: String,
    pub count: u64,
}

/// What rosbag2 records about one file of the bag.
#[derive(Clone, Debug)]
pub(crate) struct FileMeta {
    pub path: String,
    pub start: Nanos,
    pub end: Nanos,
    pub count: u64,
}

/// Everything `metadata.yaml` holds.
#[derive(Clone, Debug)]
pub(crate) struct BagMeta {
    pub topics: Vec<TopicMeta>,
    pub files: Vec<FileMeta>,
    pub ros_distro: String,
}

/// A YAML double-quoted scalar (JSON escaping is valid YAML).
fn q(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

impl BagMeta {
    fn span(&self) -> (Nanos, Nanos, u64) {
        let files: Vec<_> = self.files.iter().filter(|f| f.count > 0).collect();
        let start = files.iter().map(|f| f.start).min().unwrap_or(0);
        let end = files.iter().map(|f| f.end).max().unwrap_or(0);
        (start, end.saturating_sub(start), self.files.iter().map(|f| f.count).sum())
    }

    /// The body of BagMetadata (no top-level key), indented by `ind` spaces.
    fn body(&self, ind: &str, starting_time: Option<Nanos>) -> String {
        let (start, duration, count) = self.span();
        let start = starting_time.unwrap_or(start);
        let mut y = String::new();
        let _ = writeln!(y, "{ind}version: 8");
        let _ = writeln!(y, "{ind}storage_identifier: mcap");
        let _ = writeln!(y, "{ind}duration:\n{ind}  nanoseconds: {duration}");
        let _ = writeln!(y, "{ind}starting_time:\n{ind}  nanoseconds_since_epoch: {start}");
        let _ = writeln!(y, "{ind}message_count: {count}");
        if self.topics.is_empty() {
            let _ = writeln!(y, "{ind}topics_with_message_count: []");
        } else {
            let _ = writeln!(y, "{ind}topics_with_message_count:");
            for t in &self.topics {
                let _ = writeln!(y, "{ind}  - topic_metadata:");
                let _ = writeln!(y, "{ind}      name: {}", q(&t.name));
                let _ = writeln!(y, "{ind}      type: {}", q(&t.type_name));
                let _ = writeln!(y, "{ind}      serialization_format: cdr");
                let _ = writeln!(y, "{ind}      offered_qos_profiles: {}", q(&t.offered_qos));
                let _ = writeln!(y, "{ind}      type_description_hash: {}", q(&t.type_hash));
                let _ = writeln!(y, "{ind}    message_count: {}", t.count);
            }
        }
        let _ = writeln!(y, "{ind}compression_format: \"\"");
        let _ = writeln!(y, "{ind}compression_mode: \"\"");
        if self.files.is_empty() {
            let _ = writeln!(y, "{ind}relative_file_paths: []\n{ind}files: []");
        } else {
            let _ = writeln!(y, "{ind}relative_file_paths:");
            for f in &self.files {
                let _ = writeln!(y, "{ind}  - {}", q(&f.path));
            }
            let _ = writeln!(y, "{ind}files:");
            for f in &self.files {
                let (fstart, fdur) = if f.count > 0 { (f.start, f.end - f.start) } else { (0, 0) };
                let _ = writeln!(y, "{ind}  - path: {}", q(&f.path));
                let _ = writeln!(y, "{ind}    starting_time:\n{ind}      nanoseconds_since_epoch: {fstart}");
                let _ = writeln!(y, "{ind}    duration:\n{ind}      nanoseconds: {fdur}");
                let _ = writeln!(y, "{ind}    message_count: {}", f.count);
            }
        }
        let _ = writeln!(y, "{ind}custom_data: ~");
        let _ = writeln!(y, "{ind}ros_distro: {}", q(&self.ros_distro));
        y
    }

    /// `metadata.yaml`.
    pub fn yaml_file(&self) -> String {
        format!("rosbag2_bagfile_information:\n{}", self.body("  ", None))
    }

    /// The `serialized_metadata` of a `rosbag2` record. rosbag2 writes one at open with the
    /// starting time at i64::MAX and no topics, and the full one at close.
    pub fn serialized(&self, at_open: bool) -> String {
        if at_open {
            let empty = BagMeta { topics: vec![], files: vec![], ..self.clone() };
            empty.body("", Some(i64::MAX as u64))
        } else {
            self.body("", None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_escapes_yaml_specials() {
        assert_eq!(q("a\"b\\c\nd"), "\"a\\\"b\\\\c\\nd\"");
        assert_eq!(q("- x: 1"), "\"- x: 1\"");
    }

    #[test]
    fn empty_lists_are_written_as_brackets() {
        let m = BagMeta { topics: vec![], files: vec![], ros_distro: "jazzy".into() };
        let y = m.yaml_file();
        assert!(y.contains("  topics_with_message_count: []\n"), "{y}");
        assert!(y.contains("  relative_file_paths: []\n"), "{y}");
        assert!(m.serialized(true).contains("nanoseconds_since_epoch: 9223372036854775807"));
    }
}
