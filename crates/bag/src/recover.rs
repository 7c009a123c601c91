//! Rewrites a bag whose recorder was killed (files without summary, footer or `metadata.yaml`) as a
//! complete, indexed bag: every message of every intact chunk, with its original topics, schemas,
//! QoS metadata and times. Damaged chunks are skipped and reported, the chunks after them kept.

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
}

/// Reads everything readable from `input` (a bag directory or an `.mcap` file) and writes it to the
/// new bag directory `output`.
pub fn recover(input: &Path, output: &Path, opts: WriterOptions) -> Result<RecoverReport, BagError> {
    let reader = Reader::open(input)?;
    let mut writer = Writer::create(output, opts)?;
    let mut topics: HashMap<(String, String), TopicId> = HashMap::new();
    let report = reader.for_each(ReadMode::Salvage, |m| {
        let key = (m.topic.to_string(), m.type_name.to_string());
        let id = match topics.get(&key) {
            Some(&id) => id,
            None => {
                let schema = m.channel.schema.as_ref();
                let meta = |k: &str| m.channel.metadata.get(k).cloned().unwrap_or_default();
                let info = TopicInfo {
                    name: m.topic.to_string(),
                    type_name: m.type_name.to_string(),
                    schema_encoding: schema.map(|s| s.encoding.clone()).unwrap_or_default(),
                    schema: schema.map(|s| s.data.to_vec()).unwrap_or_default(),
                    offered_qos: meta("offered_qos_profiles"),
                    type_hash: meta("topic_type_hash"),
                };
                let id = writer.add_topic(info)?;
                topics.insert(key, id);
                id
            }
        };
        writer.write(id, m.log_time, m.publish_time, m.data)
    })??;
    let summary = writer.finish()?;
    Ok(RecoverReport { summary, truncated: report.truncated, lost: report.lost })
}
