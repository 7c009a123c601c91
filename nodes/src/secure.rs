//! The ROS 2 security variables, read as rcl reads them, and the enclave a node joins with
//! (docs/security.md):
//!
//! - `ROS_SECURITY_ENABLE=true` (exactly `true`) turns security on; anything else leaves it off.
//! - `ROS_SECURITY_STRATEGY=Enforce` refuses to start a node whose enclave is missing or invalid;
//!   any other value (rcl's `Permissive`) warns and joins without security.
//! - `ROS_SECURITY_KEYSTORE` is the keystore; the node's enclave is `enclaves/` + its enclave name.
//! - `ROS_SECURITY_ENCLAVE_OVERRIDE` names the enclave; without it a node's enclave is `/equiarm` +
//!   its node name (`/equiarm/env0/sim`), whose permissions `equiarm security create-enclave` makes.

use std::path::PathBuf;

use anyhow::bail;
use equiarm_security::{EnclaveName, check_enclave};
use log::warn;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::dds::rustdds::DomainParticipantSecurityConfigFiles;

/// The security settings of a node.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub enum Security {
    /// Plain DDS (ROS_SECURITY_ENABLE unset or not `true`).
    #[default]
    Off,
    /// DDS Security with the node's enclave.
    On {
        /// ROS_SECURITY_KEYSTORE.
        keystore: Option<PathBuf>,
        /// ROS_SECURITY_STRATEGY=Enforce.
        enforce: bool,
        /// ROS_SECURITY_ENCLAVE_OVERRIDE.
        enclave_override: Option<String>,
    },
}

impl Security {
    /// Reads the ROS 2 security variables through `get`.
    pub fn from_vars(get: impl Fn(&str) -> Option<String>) -> Self {
        if get("ROS_SECURITY_ENABLE").as_deref() != Some("true") {
            return Security::Off;
        }
        let nonempty = |k: &str| get(k).filter(|v| !v.is_empty());
        Security::On {
            keystore: nonempty("ROS_SECURITY_KEYSTORE").map(PathBuf::from),
            enforce: get("ROS_SECURITY_STRATEGY").as_deref() == Some("Enforce"),
            enclave_override: nonempty("ROS_SECURITY_ENCLAVE_OVERRIDE"),
        }
    }

    /// `builder` for the node `fqn`: with its enclave's files when security is on and they pass the
    /// checks; an error under Enforce (naming the variable or the file), a warning and plain DDS
    /// under Permissive. Returns the builder and the enclave joined with, if any.
    pub(crate) fn apply(
        &self,
        builder: DomainParticipantBuilder,
        fqn: &str,
        domain: u16,
    ) -> anyhow::Result<(DomainParticipantBuilder, Option<EnclaveName>)> {
        let Security::On { keystore, enforce, enclave_override } = self else { return Ok((builder, None)) };
        let enclave = || -> anyhow::Result<(EnclaveName, PathBuf)> {
            let Some(keystore) = keystore else {
                bail!("ROS_SECURITY_ENABLE=true but ROS_SECURITY_KEYSTORE is not set");
            };
            let name = match enclave_override {
                Some(o) => EnclaveName::parse(o).map_err(|e| anyhow::anyhow!("ROS_SECURITY_ENCLAVE_OVERRIDE: {e}"))?,
                None => EnclaveName::of_node(fqn)?,
            };
            let dir = name.dir_in(keystore);
            if !dir.is_dir() {
                bail!(
                    "enclave '{name}': no directory {} (create it with `equiarm security create-enclave {} {name}`)",
                    dir.display(),
                    keystore.display()
                );
            }
            check_enclave(&dir, domain).map_err(|e| anyhow::anyhow!("enclave '{name}': {e}"))?;
            Ok((name, dir))
        };
        match enclave() {
            Ok((name, dir)) => {
                let files = DomainParticipantSecurityConfigFiles::with_ros_default_names(dir, String::new());
                Ok((builder.builtin_security(files), Some(name)))
            }
            Err(e) if *enforce => bail!("security (ROS_SECURITY_STRATEGY=Enforce): {fqn}: {e:#}"),
            Err(e) => {
                warn!("security (Permissive): {fqn}: {e:#}; joining without security");
                Ok((builder, None))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(pairs: &[(&str, &str)]) -> Security {
        let map: std::collections::HashMap<String, String> =
            pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Security::from_vars(|k| map.get(k).cloned())
    }

    #[test]
    fn the_variables_are_read_as_rcl_reads_them() {
        assert_eq!(vars(&[]), Security::Off);
        assert_eq!(vars(&[("ROS_SECURITY_ENABLE", "True"), ("ROS_SECURITY_KEYSTORE", "k")]), Security::Off);
        assert_eq!(
            vars(&[
                ("ROS_SECURITY_ENABLE", "true"),
                ("ROS_SECURITY_KEYSTORE", "k"),
                ("ROS_SECURITY_STRATEGY", "Enforce")
            ]),
            Security::On { keystore: Some("k".into()), enforce: true, enclave_override: None }
        );
        assert_eq!(
            vars(&[
                ("ROS_SECURITY_ENABLE", "true"),
                ("ROS_SECURITY_STRATEGY", "enforce"),
                ("ROS_SECURITY_ENCLAVE_OVERRIDE", "/x")
            ]),
            Security::On { keystore: None, enforce: false, enclave_override: Some("/x".into()) }
        );
    }

    #[test]
    fn enforce_refuses_and_permissive_warns_without_a_keystore() {
        let b = || DomainParticipantBuilder::new(0);
        let on = |enforce| Security::On { keystore: None, enforce, enclave_override: None };
        let e = on(true).apply(b(), "/env0/sim", 0).err().unwrap().to_string();
        assert!(e.contains("ROS_SECURITY_KEYSTORE") && e.contains("Enforce"), "{e}");
        assert_eq!(on(false).apply(b(), "/env0/sim", 0).unwrap().1, None);
        let missing = Security::On { keystore: Some("/nonexistent".into()), enforce: true, enclave_override: None };
        let e = missing.apply(b(), "/env0/sim", 0).err().unwrap().to_string();
        assert!(e.contains("/nonexistent/enclaves/equiarm/env0/sim"), "{e}");
    }
}
