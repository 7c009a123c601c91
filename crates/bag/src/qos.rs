//! Offered QoS profiles as rosbag2 writes them: a YAML list, one entry per publisher, with integer
//! enums (the form Humble's decoder requires and every later distro and `rosbags` accept).

/// The parts of a publisher's QoS a bag records (the rest is ROS 2's defaults: infinite deadline,
/// lifespan and lease, automatic liveliness).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OfferedQos {
    /// Reliable (true) or best effort (false).
    pub reliable: bool,
    /// Transient local (true) or volatile (false).
    pub transient_local: bool,
    /// Keep-last depth; 0 when unknown (what discovery reports).
    pub depth: u32,
}

impl OfferedQos {
    /// Reliable, volatile, keep-last `depth`.
    pub const fn reliable(depth: u32) -> Self {
        Self { reliable: true, transient_local: false, depth }
    }

    /// Best effort, volatile, keep-last `depth`.
    pub const fn best_effort(depth: u32) -> Self {
        Self { reliable: false, transient_local: false, depth }
    }

    /// Reliable, transient local, keep-last `depth`.
    pub const fn latched(depth: u32) -> Self {
        Self { reliable: true, transient_local: true, depth }
    }
}

const INFINITE: &str = "\n    sec: 9223372036\n    nsec: 854775807";

/// The `offered_qos_profiles` YAML of a topic's publishers (no trailing newline, as yaml-cpp emits it).
pub fn offered_qos_yaml(profiles: &[OfferedQos]) -> String {
    if profiles.is_empty() {
        return "[]".into();
    }
    let mut out = Vec::new();
    for q in profiles {
        // history 1 = keep_last; reliability 1 reliable / 2 best effort; durability 1 transient local / 2 volatile
        out.push(format!(
            "- history: 1\n  depth: {}\n  reliability: {}\n  durability: {}\n  deadline:{INFINITE}\n  lifespan:{INFINITE}\n  liveliness: 1\n  liveliness_lease_duration:{INFINITE}\n  avoid_ros_namespace_conventions: false",
            q.depth,
            if q.reliable { 1 } else { 2 },
            if q.transient_local { 1 } else { 2 },
        ));
    }
    out.join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_form_per_publisher() {
        let y = offered_qos_yaml(&[OfferedQos::best_effort(1), OfferedQos::latched(1)]);
        assert!(y.starts_with(
            "- history: 1\n  depth: 1\n  reliability: 2\n  durability: 2\n  deadline:\n    sec: 9223372036\n"
        ));
        assert!(y.contains("\n- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n"));
        assert!(!y.ends_with('\n'));
        assert_eq!(offered_qos_yaml(&[]), "[]");
    }
}
