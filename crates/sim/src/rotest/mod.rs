//! The supervised rotation-estimation experiment's scene and data (docs/rotest.md): three
//! asymmetric objects on a table seen from above (or from the side), the scene rotated by one of
//! eight angles about the workspace centre, and the symmetry-breaking corruptions of the images or
//! labels.
//!
//! - [`corruption`]: the corruption flags and the experiment's 15 settings, the label rule.
//! - [`scene`]: the ducks, their placement and settling, the scene rotation, the cameras.
//! - [`pair`]: rendering a pair of RGBD images and its label.
//!
//! Limitations: the ducks are compounds of four boxes, not the paper's duck mesh; shading is flat
//! per face (specular evaluated once per face), shadows are hard; the images are area-downsampled
//! from a supersampled rendering by an integer factor.

pub mod corruption;
pub mod pair;
pub mod scene;

pub use corruption::{Corruptions, PAPER_SETTINGS, PairCorruption};
pub use pair::{Pair, PairConfig, PairMeta, RgbdImage, generate_pair, recover_idx};
pub use scene::{DuckPose, RotScene};
