//! Symmetry corruptions of the RL observations (docs/paper.md §5): each a named flag, given as `none`
//! or a comma-separated set of names.

use std::fmt;
use std::str::FromStr;

use crate::ParseError;

crate::named_enum! {
    /// One symmetry corruption.
    pub enum CorruptionKind: "corruption" {
        /// §5.2: every observation independently mirrored left↔right w.p. 0.5, then up↔down w.p. 0.5.
        RandomReflection = "random_reflection",
        /// §5.3: the camera image replaced by an orthographic height map centred on the gripper.
        OcclusionProjection = "occlusion_projection",
        /// §5.1 "gripper-only" scene: a plain white floor instead of the checkerboard.
        GripperOnly = "gripper_only",
    }
}

/// A set of [`CorruptionKind`]s; the empty set is `none`. Written (`Display`, serde) as `none` or the
/// set's names comma-separated in the order of [`CorruptionKind::ALL`]; read (`FromStr`, serde) in
/// any order, each name once.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Corruption {
    /// §5.2: every observation independently mirrored left↔right w.p. 0.5, then up↔down w.p. 0.5.
    pub random_reflection: bool,
    /// §5.3: replace the camera image by an orthographic height map (0.6 m square centred on the
    /// gripper, rows toward +x) built from the camera's depth: value = gripper height − point height,
    /// missing = −0.1, the finger footprint painted 0, pushing goal +0.02. The colour buffer is zeroed.
    pub occlusion_projection: bool,
    /// §5.1 "gripper-only" scene: a plain white floor instead of the checkerboard (the arm is not
    /// drawn either).
    pub gripper_only: bool,
}

impl Corruption {
    /// No corruption.
    pub const NONE: Corruption =
        Corruption { random_reflection: false, occlusion_projection: false, gripper_only: false };

    /// Whether `kind` is in the set.
    pub fn has(&self, kind: CorruptionKind) -> bool {
        match kind {
            CorruptionKind::RandomReflection => self.random_reflection,
            CorruptionKind::OcclusionProjection => self.occlusion_projection,
            CorruptionKind::GripperOnly => self.gripper_only,
        }
    }

    fn flag(&mut self, kind: CorruptionKind) -> &mut bool {
        match kind {
            CorruptionKind::RandomReflection => &mut self.random_reflection,
            CorruptionKind::OcclusionProjection => &mut self.occlusion_projection,
            CorruptionKind::GripperOnly => &mut self.gripper_only,
        }
    }

    /// The set holding `kinds` (a kind named twice is kept once).
    pub fn of(kinds: &[CorruptionKind]) -> Self {
        let mut c = Corruption::NONE;
        for &k in kinds {
            *c.flag(k) = true;
        }
        c
    }

    /// The kinds in the set, in the order of [`CorruptionKind::ALL`].
    pub fn kinds(&self) -> Vec<CorruptionKind> {
        CorruptionKind::ALL.into_iter().filter(|&k| self.has(k)).collect()
    }

    /// `none`, or the set's names (for help texts: what [`FromStr`] accepts).
    pub fn help() -> String {
        format!("none, or a comma-separated set of {}", CorruptionKind::names())
    }
}

impl fmt::Display for Corruption {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kinds = self.kinds();
        if kinds.is_empty() {
            return f.write_str("none");
        }
        let names: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
        f.write_str(&names.join(","))
    }
}

impl FromStr for Corruption {
    type Err = ParseError;

    fn from_str(text: &str) -> Result<Self, ParseError> {
        let mut c = Corruption::NONE;
        let text = text.trim();
        if text == "none" || text.is_empty() {
            return Ok(c);
        }
        for word in text.split(',').map(str::trim) {
            let kind = CorruptionKind::from_name(word)
                .ok_or_else(|| ParseError::unknown("corruption", word, Corruption::help()))?;
            if std::mem::replace(c.flag(kind), true) {
                return Err(ParseError::Repeated { what: "corruption", name: word.to_string() });
            }
        }
        Ok(c)
    }
}

impl serde::Serialize for Corruption {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// The forms a corruption is read from: its text, or (as the simulator's env configs wrote it before
/// the text form) a map of the flags.
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum Stored {
    Text(String),
    Flags(Flags),
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
#[derive(Default)]
struct Flags {
    random_reflection: bool,
    occlusion_projection: bool,
    gripper_only: bool,
}

impl<'de> serde::Deserialize<'de> for Corruption {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match Stored::deserialize(d)? {
            Stored::Text(text) => text.parse().map_err(serde::de::Error::custom),
            Stored::Flags(f) => Ok(Corruption {
                random_reflection: f.random_reflection,
                occlusion_projection: f.occlusion_projection,
                gripper_only: f.gripper_only,
            }),
        }
    }
}
