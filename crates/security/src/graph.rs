//! Which enclave may publish and subscribe what: the suite's topic graph (docs/nodes.md) as DDS
//! permissions. A node's enclave is `/equiarm` followed by its fully qualified node name
//! (`/equiarm/env0/sim`, `/equiarm/trainer`), so each node gets exactly its own topics.

use std::fmt;

use crate::Error;

/// The prefix of every enclave of the suite.
pub const ENCLAVE_ROOT: &str = "/equiarm";

/// An enclave name: a ROS namespace (`/a/b`, each part a letter or `_` then letters, digits, `_`).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct EnclaveName(String);

impl EnclaveName {
    /// Checks `name` as rcl checks an enclave name.
    pub fn parse(name: &str) -> Result<Self, Error> {
        let bad = |why: &str| Error::EnclaveName { name: name.to_string(), why: why.to_string() };
        let rest = name.strip_prefix('/').ok_or_else(|| bad("it must start with '/'"))?;
        if rest.is_empty() {
            return Err(bad("it names no enclave ('/' is the keystore's root)"));
        }
        for part in rest.split('/') {
            let mut chars = part.chars();
            match chars.next() {
                None => return Err(bad("it has an empty part ('//' or a trailing '/')")),
                Some(c) if !(c.is_ascii_alphabetic() || c == '_') => {
                    return Err(bad("each part must start with a letter or '_'"));
                }
                Some(_) => {}
            }
            if !chars.all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(bad("each part may hold only letters, digits and '_'"));
            }
        }
        Ok(Self(name.to_string()))
    }

    /// The enclave of the node `fqn` (`/env0/sim` → `/equiarm/env0/sim`).
    pub fn of_node(fqn: &str) -> Result<Self, Error> {
        Self::parse(&format!("{ENCLAVE_ROOT}{fqn}"))
    }

    /// The name as given (`/equiarm/env0/sim`).
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Where this enclave's files are in the keystore `root` (`root/enclaves/equiarm/env0/sim`), as
    /// rcl looks for them.
    pub fn dir_in(&self, root: &std::path::Path) -> std::path::PathBuf {
        root.join("enclaves").join(&self.0[1..])
    }

    /// The name's parts, without the leading '/'.
    pub fn parts(&self) -> impl Iterator<Item = &str> {
        self.0[1..].split('/')
    }
}

impl fmt::Display for EnclaveName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// The suite's nodes, as far as their topics go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Role {
    /// `equiarm sim` in namespace `/<env>`.
    Sim {
        /// The env's name (the namespace without '/').
        env: String,
    },
    /// `equiarm policy` in namespace `/<env>`.
    Policy {
        /// The env's name.
        env: String,
    },
    /// `equiarm train`.
    Trainer,
    /// `equiarm record`.
    Recorder,
    /// `equiarm echo`.
    Echo,
    /// `equiarm play` (it republishes what a bag holds, and answers lock-step with gripper commands
    /// from a policy).
    Player,
}

impl Role {
    /// The role of the node whose enclave is `enclave`, if it is one of the suite's.
    pub fn of(enclave: &EnclaveName) -> Option<Role> {
        let parts: Vec<&str> = enclave.parts().collect();
        match parts.as_slice() {
            ["equiarm", env, "sim"] => Some(Role::Sim { env: env.to_string() }),
            ["equiarm", env, "policy"] => Some(Role::Policy { env: env.to_string() }),
            ["equiarm", "trainer"] => Some(Role::Trainer),
            ["equiarm", "equiarm_recorder"] => Some(Role::Recorder),
            ["equiarm", "equiarm_echo"] => Some(Role::Echo),
            ["equiarm", "equiarm_player"] => Some(Role::Player),
            _ => None,
        }
    }

    /// What this node may do on the graph.
    pub fn grant(&self) -> Grant {
        let mut g = Grant::ros_node();
        match self {
            Role::Sim { env } => {
                g.publish(&[
                    &format!("rt/{env}/observation"),
                    "rt/transitions",
                    "rt/episodes",
                    &format!("rt/{env}/camera/color/image_raw"),
                    &format!("rt/{env}/camera/depth/image_raw"),
                    &format!("rt/{env}/camera/camera_info"),
                    "rt/clock",
                    "rt/tf_static",
                    "rt/tf",
                ]);
                g.subscribe(&[&format!("rt/{env}/gripper_cmd")]);
            }
            Role::Policy { env } => {
                g.publish(&[&format!("rt/{env}/gripper_cmd")]);
                g.subscribe(&[&format!("rt/{env}/observation"), "rt/policy/weights", "rt/trainer/status"]);
            }
            Role::Trainer => {
                g.publish(&["rt/policy/weights", "rt/trainer/status"]);
                g.subscribe(&["rt/*/observation", "rt/transitions", "rt/episodes"]);
            }
            Role::Recorder | Role::Echo => g.subscribe(&["*"]),
            Role::Player => {
                // Everything a bag may hold, but not what steers the learner or the gripper.
                g.deny_publish(&["rt/policy/weights", "rt/*/gripper_cmd"]);
                g.publish(&["rt/*"]);
                g.subscribe(&["rt/*/gripper_cmd"]);
            }
        }
        g
    }
}

/// Topic rules of one enclave, in DDS topic names (`rt/` + the ROS name without its leading '/';
/// `*` and `?` match as in fnmatch). Deny rules come before allow rules; what no rule names is denied.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Grant {
    /// Topics it must not publish, whatever the allow rules say.
    pub deny_publish: Vec<String>,
    /// Topics it may publish.
    pub publish: Vec<String>,
    /// Topics it may subscribe to.
    pub subscribe: Vec<String>,
}

impl Grant {
    /// What every ROS 2 node of ours does besides its own topics: the graph information ROS 2 tools
    /// read (`ros_discovery_info`), its log (`/rosout`), parameter events and the `/clock` reader
    /// ros2-client creates for simulated time.
    pub fn ros_node() -> Grant {
        Grant {
            deny_publish: vec![],
            publish: vec!["ros_discovery_info".into(), "rt/rosout".into(), "rt/parameter_events".into()],
            subscribe: vec!["ros_discovery_info".into(), "rt/rosout".into(), "rt/clock".into()],
        }
    }

    /// Everything (what `ros2 security create_enclave` grants by default).
    pub fn everything() -> Grant {
        Grant { deny_publish: vec![], publish: vec!["*".into()], subscribe: vec!["*".into()] }
    }

    fn publish(&mut self, topics: &[&str]) {
        self.publish.extend(topics.iter().map(|t| t.to_string()));
    }

    fn subscribe(&mut self, topics: &[&str]) {
        self.subscribe.extend(topics.iter().map(|t| t.to_string()));
    }

    fn deny_publish(&mut self, topics: &[&str]) {
        self.deny_publish.extend(topics.iter().map(|t| t.to_string()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enclave_names_are_checked_as_ros_namespaces() {
        assert!(EnclaveName::parse("/equiarm/env0/sim").is_ok());
        for bad in ["equiarm", "/", "/a//b", "/a/", "/0a", "/a-b", "/a/b c"] {
            let e = EnclaveName::parse(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("'{bad}'")), "{e}");
        }
        assert_eq!(EnclaveName::of_node("/env3/policy").unwrap().as_str(), "/equiarm/env3/policy");
    }

    #[test]
    fn each_node_gets_its_own_topics_and_only_the_trainer_publishes_weights() {
        let role = |n: &str| Role::of(&EnclaveName::parse(n).unwrap());
        assert_eq!(role("/equiarm/env1/sim"), Some(Role::Sim { env: "env1".into() }));
        assert_eq!(role("/equiarm/eval/policy"), Some(Role::Policy { env: "eval".into() }));
        assert_eq!(role("/equiarm/a/b/sim"), None);
        assert_eq!(role("/other/trainer"), None);
        let sim = role("/equiarm/env1/sim").unwrap().grant();
        assert!(sim.publish.contains(&"rt/env1/observation".to_string()));
        assert!(!sim.publish.iter().any(|t| t.contains("gripper_cmd") || t.contains("weights")));
        let policy = role("/equiarm/env1/policy").unwrap().grant();
        assert!(policy.publish.contains(&"rt/env1/gripper_cmd".to_string()));
        assert!(!policy.publish.iter().any(|t| t.contains("weights")));
        assert!(Role::Trainer.grant().publish.contains(&"rt/policy/weights".to_string()));
        assert!(Role::Player.grant().deny_publish.contains(&"rt/policy/weights".to_string()));
    }
}
