//! Image augmentation of the replayed observations (docs/paper.md §1.11).

crate::named_enum! {
    /// The augmentation by name, as the command line gives it (`--augmentation`); DrQ's crop counts
    /// then take the paper's values (K = M = 2).
    pub enum AugmentationKind: "augmentation" {
        /// RAD: one random crop per transition, shared by obs and next_obs (the paper's default).
        Rad = "rad",
        /// DrQ: several independent crops of obs and next_obs, averaged.
        Drq = "drq",
        /// Centre crop only.
        Center = "center",
    }
}

/// Image augmentation with its parameters (a config's `augmentation`: `"rad"`, `"center"` or
/// `{"drq": {"k": K, "m": M}}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Augmentation {
    /// RAD: one random crop per transition, shared by obs and next_obs (the paper's default).
    Rad,
    /// DrQ with K next-observation crops and M observation crops (paper K = M = 2).
    Drq {
        /// Target crops.
        k: usize,
        /// Critic/actor crops.
        m: usize,
    },
    /// Centre crop only (the no-crop ablation of docs/paper.md §5.4 keeps the full frame instead).
    Center,
}

impl Augmentation {
    /// The paper's DrQ: K = M = 2.
    pub const PAPER_DRQ: Augmentation = Augmentation::Drq { k: 2, m: 2 };
    /// FERM's crops: obs and next_obs cropped independently, once each (docs/paper.md §1.10).
    pub const FERM: Augmentation = Augmentation::Drq { k: 1, m: 1 };

    /// Its kind.
    pub fn kind(self) -> AugmentationKind {
        match self {
            Augmentation::Rad => AugmentationKind::Rad,
            Augmentation::Drq { .. } => AugmentationKind::Drq,
            Augmentation::Center => AugmentationKind::Center,
        }
    }
}

impl From<AugmentationKind> for Augmentation {
    /// The augmentation of a kind, DrQ with the paper's K = M = 2.
    fn from(kind: AugmentationKind) -> Self {
        match kind {
            AugmentationKind::Rad => Augmentation::Rad,
            AugmentationKind::Drq => Augmentation::PAPER_DRQ,
            AugmentationKind::Center => Augmentation::Center,
        }
    }
}
