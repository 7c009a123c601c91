//! Decoding recorded messages with the definition they were recorded with in mind: a bag carries
//! each type's definition text (the MCAP `ros2msg` schema), so a message recorded under another
//! definition of one of our types (an older equiarm, before a message change) is refused with an
//! error naming the topic and type instead of being decoded into wrong fields.
//!
//! Definitions are compared by their fields (per type: each line without its comment, trimmed), so
//! comments, blank lines and the order of the nested definitions (rosbag2 and our recorder may
//! concatenate them differently) do not matter.

use std::collections::BTreeMap;

use equiarm_msgs::{RosMessage, cdr};

use crate::RecordedMessage;

/// Why a recorded message does not decode.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// The bag's definition of the type is not this build's.
    #[error(
        "'{topic}': recorded with another definition of {type_name} than this equiarm's (a bag from another version; \
         read it with that version, or with a reader that follows the bag's own schema, e.g. rosbags)"
    )]
    OtherDefinition {
        /// Topic.
        topic: String,
        /// ROS 2 type name.
        type_name: &'static str,
    },
    /// The payload does not decode as the type.
    #[error("'{topic}': {cause}")]
    Cdr {
        /// Topic.
        topic: String,
        /// The CDR error.
        cause: cdr::CdrError,
    },
}

/// A definition's field lines per type (the main type under its own name).
fn fields_by_type(main: &str, text: &str) -> BTreeMap<String, Vec<String>> {
    let mut out = BTreeMap::new();
    let (mut name, mut lines) = (main.to_string(), Vec::new());
    for raw in text.lines() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.starts_with("===") {
            out.insert(std::mem::take(&mut name), std::mem::take(&mut lines));
        } else if let Some(n) = line.strip_prefix("MSG:") {
            name = n.trim().to_string();
        } else if !line.is_empty() {
            lines.push(line.split_whitespace().collect::<Vec<_>>().join(" "));
        }
    }
    out.insert(name, lines);
    out
}

/// Whether `recorded` (a bag's schema text for `M`) defines every type it shares with this build's
/// definition of `M` with the same fields.
pub fn same_definition<M: RosMessage>(recorded: &[u8]) -> bool {
    same_fields(M::TYPE_NAME, M::DEFINITION, recorded)
}

fn same_fields(type_name: &str, definition: &str, recorded: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(recorded) else { return false };
    let ours = fields_by_type(type_name, definition);
    let theirs = fields_by_type(type_name, text);
    let short = |n: &str| n.replace("/msg/", "/");
    let theirs: BTreeMap<String, &Vec<String>> = theirs.iter().map(|(k, v)| (short(k), v)).collect();
    ours.iter().all(|(k, v)| theirs.get(&short(k)).is_none_or(|t| *t == v))
}

impl RecordedMessage<'_> {
    /// Whether the message's type, if it is one this build knows, was recorded with this build's
    /// definition (for readers that pass payloads on without decoding them, like `bag play`).
    pub fn recorded_as_built(&self) -> bool {
        match (self.channel.schema.as_ref(), equiarm_msgs::TypeInfo::find(self.type_name)) {
            (Some(schema), Some(info)) => same_fields(info.type_name, info.definition, &schema.data),
            _ => true,
        }
    }

    /// The message as `M`, refused if the bag recorded `M` under another definition.
    pub fn decode<M: RosMessage>(&self) -> Result<M, DecodeError> {
        if let Some(schema) = self.channel.schema.as_ref()
            && schema.name == M::TYPE_NAME
            && !same_definition::<M>(&schema.data)
        {
            return Err(DecodeError::OtherDefinition { topic: self.topic.to_string(), type_name: M::TYPE_NAME });
        }
        cdr::decode(self.data).map_err(|cause| DecodeError::Cdr { topic: self.topic.to_string(), cause })
    }
}

#[cfg(test)]
mod tests {
    use equiarm_msgs::msg::{Observation, Transition};

    use super::*;

    #[test]
    fn comments_and_nested_order_do_not_matter_but_fields_do() {
        let ours = Transition::DEFINITION;
        assert!(same_definition::<Transition>(ours.as_bytes()));
        let uncommented: String = ours.lines().map(|l| l.split('#').next().unwrap()).collect::<Vec<_>>().join("\n");
        assert!(same_definition::<Transition>(uncommented.as_bytes()));
        // The definition of schema 1, where a Transition carried both Observations.
        let old = ours.replacen("string env", "Observation obs", 1);
        assert!(!same_definition::<Transition>(old.as_bytes()));
        // A nested type changed: an Observation without `terminal`.
        let old_obs = Observation::DEFINITION.replace("bool terminal", "");
        assert!(!same_definition::<Observation>(old_obs.as_bytes()));
        assert!(!same_definition::<Observation>(b"\xff\xfe"));
    }
}
