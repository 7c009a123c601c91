//! The network input (docs/paper.md §1.1): one image of [`OBS_PLANES`] planes per observation.

/// The planes of the network input, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    /// Red, colour byte / 255.
    Red,
    /// Green, colour byte / 255.
    Green,
    /// Blue, colour byte / 255.
    Blue,
    /// Depth in metres.
    Depth,
    /// The gripper's holding flag, 0 or 1, over the whole plane.
    Holding,
}

impl Plane {
    /// Every plane, in the order of the network input.
    pub const ALL: [Plane; 5] = [Plane::Red, Plane::Green, Plane::Blue, Plane::Depth, Plane::Holding];
}

/// Planes of the network input: R, G, B, depth, holding.
pub const OBS_PLANES: usize = Plane::ALL.len();
