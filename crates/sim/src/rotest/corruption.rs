//! The symmetry-breaking corruptions of the rotation-estimation experiment (docs/rotest.md,
//! "Corruptions"): each is a flag, a setting is a set of flags written as a comma-separated list
//! (`grid,side`), and [`PAPER_SETTINGS`] lists the experiment's 15 settings.

use crate::error::{Result, SimError};

/// One corruption flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PairCorruption {
    /// A checkerboard floor of 0.2 m tiles (BulletArm's checker plane at `globalScaling` 0.2).
    Grid,
    /// A dark-grey 0.05 × 0.10 m slab floating at (0.50, −0.05, 0.20), seen but not touched.
    Occlusion,
    /// The light's colour is drawn uniformly from [0.2, 1]³, once per pair.
    RandomLightColor,
    /// Light from direction (−1, 0, 0.7), specular 0.5, hard shadows.
    LightEffect,
    /// The left half of the image is lit with colour (1, 0.2, 0.2), the right half with (0.2, 0.2, 1).
    TwoLightColor,
    /// The left half of the image has specular 0, the right half 0.2.
    TwoSpecular,
    /// Projection aspect ratio 2: the image is squeezed to half width (twice the horizontal view).
    Squeeze,
    /// Both images are mirrored left↔right.
    Reflect,
    /// "Invert-label": the label becomes (8 − idx) mod 8 when duck 0 is left of duck 1 (smaller
    /// world y) in the first image. The images are unchanged.
    InvertLabel,
    /// The side camera: eye (1.05, 0, 0.6) looking at the workspace centre (45° elevation), FOV 40°.
    Side,
    /// Not a corruption: the ducks are placed uniformly in the disc inscribed in the workspace and
    /// their yaws drawn over the whole circle (the paper: the square, yaws in [0, π)), so that every
    /// rotation of a scene by k·45° about the centre is exactly as likely as the scene itself, as
    /// the invariant classifier's accuracy bound assumes (docs/rotest.md, "The bound").
    FullCircle,
}

impl PairCorruption {
    /// Every flag, in the order names are written.
    pub const ALL: [PairCorruption; 11] = [
        PairCorruption::Side,
        PairCorruption::Grid,
        PairCorruption::Occlusion,
        PairCorruption::RandomLightColor,
        PairCorruption::LightEffect,
        PairCorruption::TwoLightColor,
        PairCorruption::TwoSpecular,
        PairCorruption::Squeeze,
        PairCorruption::Reflect,
        PairCorruption::InvertLabel,
        PairCorruption::FullCircle,
    ];

    /// The flag's name: the paper's code's name (`condition_reverse` for invert-label).
    pub fn name(self) -> &'static str {
        match self {
            PairCorruption::Grid => "grid",
            PairCorruption::Occlusion => "occlusion",
            PairCorruption::RandomLightColor => "random_light_color",
            PairCorruption::LightEffect => "light_effect",
            PairCorruption::TwoLightColor => "two_light_color",
            PairCorruption::TwoSpecular => "two_specular",
            PairCorruption::Squeeze => "squeeze",
            PairCorruption::Reflect => "reflect",
            PairCorruption::InvertLabel => "condition_reverse",
            PairCorruption::Side => "side",
            PairCorruption::FullCircle => "full_circle",
        }
    }

    /// The flag called `name` ([`PairCorruption::name`], or `invert_label` / `invert-label`).
    pub fn from_name(name: &str) -> Option<Self> {
        if name == "invert_label" || name == "invert-label" {
            return Some(PairCorruption::InvertLabel);
        }
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// A set of corruption flags (the empty set is the clean setting, `none`).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Corruptions {
    flags: Vec<PairCorruption>,
}

/// The experiment's 15 settings, as [`Corruptions::parse`] reads them.
pub const PAPER_SETTINGS: [&str; 15] = [
    "none",
    "grid",
    "occlusion",
    "random_light_color",
    "light_effect",
    "two_light_color",
    "two_specular",
    "squeeze",
    "reflect",
    "condition_reverse",
    "side",
    "side,grid",
    "side,light_effect",
    "side,squeeze",
    "side,reflect",
];

impl Corruptions {
    /// The clean setting.
    pub fn none() -> Self {
        Self::default()
    }

    /// Parses a comma-separated list of flag names (`none` or an empty string for no flag). An
    /// unknown or repeated name, or `none` with other names, is a [`SimError::Config`] naming it.
    pub fn parse(text: &str) -> Result<Self> {
        let mut flags = Vec::new();
        let words: Vec<&str> = text.split(',').map(str::trim).filter(|w| !w.is_empty()).collect();
        for w in &words {
            if *w == "none" {
                if words.len() > 1 {
                    return Err(SimError::Config {
                        field: "corrupt",
                        message: format!("`none` cannot be combined with other corruptions in `{text}`"),
                    });
                }
                continue;
            }
            let c = PairCorruption::from_name(w).ok_or_else(|| SimError::Config {
                field: "corrupt",
                message: format!(
                    "unknown corruption `{w}` in `{text}`; known: none, {}",
                    PairCorruption::ALL.map(|c| c.name()).join(", ")
                ),
            })?;
            if flags.contains(&c) {
                return Err(SimError::Config { field: "corrupt", message: format!("`{w}` is repeated in `{text}`") });
            }
            flags.push(c);
        }
        flags.sort_by_key(|c| PairCorruption::ALL.iter().position(|a| a == c));
        Ok(Self { flags })
    }

    /// Whether `flag` is set.
    pub fn has(&self, flag: PairCorruption) -> bool {
        self.flags.contains(&flag)
    }

    /// The flags, in [`PairCorruption::ALL`] order.
    pub fn flags(&self) -> &[PairCorruption] {
        &self.flags
    }

    /// The canonical name: the flags joined by commas in [`PairCorruption::ALL`] order, or `none`.
    pub fn name(&self) -> String {
        if self.flags.is_empty() {
            "none".into()
        } else {
            self.flags.iter().map(|c| c.name()).collect::<Vec<_>>().join(",")
        }
    }

    /// The label of a pair whose scene was rotated by `idx`·45° and whose first image has duck 0 at
    /// world y `y0` and duck 1 at `y1`: `idx`, or with invert-label and `y0 < y1`, (8 − idx) mod 8.
    pub fn label(&self, idx: u8, y0: f32, y1: f32) -> u8 {
        if self.has(PairCorruption::InvertLabel) && y0 < y1 { (8 - idx % 8) % 8 } else { idx % 8 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for s in PAPER_SETTINGS {
            let c = Corruptions::parse(s).unwrap();
            assert_eq!(Corruptions::parse(&c.name()).unwrap(), c);
        }
        assert_eq!(Corruptions::parse("grid,side").unwrap().name(), "side,grid");
        assert_eq!(Corruptions::parse("invert-label").unwrap().name(), "condition_reverse");
        let e = Corruptions::parse("grid,blur").unwrap_err().to_string();
        assert!(e.contains("`blur`") && e.contains("corrupt"), "{e}");
        assert!(Corruptions::parse("grid,grid").unwrap_err().to_string().contains("repeated"));
        assert!(Corruptions::parse("none,grid").is_err());
    }

    #[test]
    fn invert_label_flips_exactly_when_duck0_is_left_of_duck1() {
        let inv = Corruptions::parse("condition_reverse").unwrap();
        let clean = Corruptions::none();
        for idx in 0..8u8 {
            assert_eq!(clean.label(idx, -0.1, 0.1), idx);
            assert_eq!(inv.label(idx, 0.1, -0.1), idx);
            assert_eq!(inv.label(idx, -0.1, 0.1), (8 - idx) % 8);
        }
    }
}
