//! The ROS 2 security variables, read as rcl reads them, and the enclave a node joins with
//! (docs/security.md):
//!
//! - `ROS_SECURITY_ENABLE=true` (exactly `true`) turns security on; anything else leaves it off.
//! - `ROS_SECURITY_STRATEGY=Enforce` refuses to start a node whose enclave is missing or invalid;
//!   any other value (rcl's `Permissive`) warns and joins without security.
//! - `ROS_SECURITY_KEYSTORE` is the keystore; the node's enclave is `enclaves/` + its enclave name.
//! - `ROS_SECURITY_ENCLAVE_OVERRIDE` names the enclave; without it a node's enclave is `/equiarm` +
//!   its node name (`/equiarm/env0/sim`), whose permissions `equiarm security create-enclave` makes.
//! - `EQUIARM_SECURITY_KEY_PASSWORD_FILE` (equiarm's own; [`KEY_PASSWORD_VAR`]) names a file holding
//!   the password of an encrypted `key.pem` (`create-enclave --key-password-file`); the key is
//!   decrypted into memory for the plugins ([`KeyInMemory`]).

use std::path::PathBuf;

use anyhow::bail;
use equiarm_security::{EnclaveName, KEY_PASSWORD_VAR, KeyInMemory, KeyPassword, check_enclave};
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
        /// EQUIARM_SECURITY_KEY_PASSWORD_FILE.
        key_password_file: Option<PathBuf>,
    },
}

/// What a secured node joined with: its enclave, and the decrypted key the participant reads while
/// it is built (keep it until then).
#[derive(Debug)]
pub(crate) struct Joined {
    /// The enclave.
    pub name: EnclaveName,
    /// The enclave's key, decrypted, when `key.pem` is encrypted.
    pub key: Option<KeyInMemory>,
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
            key_password_file: nonempty(KEY_PASSWORD_VAR).map(PathBuf::from),
        }
    }

    /// `builder` for the node `fqn`: with its enclave's files when security is on and they pass the
    /// checks; an error under Enforce (naming the variable or the file), a warning and plain DDS
    /// under Permissive. Returns the builder and what it joins with, if secured.
    pub(crate) fn apply(
        &self,
        builder: DomainParticipantBuilder,
        fqn: &str,
        domain: u16,
    ) -> anyhow::Result<(DomainParticipantBuilder, Option<Joined>)> {
        let Security::On { keystore, enforce, enclave_override, key_password_file } = self else {
            return Ok((builder, None));
        };
        let enclave = || -> anyhow::Result<(EnclaveName, PathBuf, Option<KeyInMemory>)> {
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
            let password = match key_password_file {
                Some(f) => Some(KeyPassword::read(f).map_err(|e| anyhow::anyhow!("{KEY_PASSWORD_VAR}: {e}"))?),
                None => None,
            };
            let checked =
                check_enclave(&dir, domain, password.as_ref()).map_err(|e| anyhow::anyhow!("enclave '{name}': {e}"))?;
            let key = checked.decrypted_key.as_deref().map(KeyInMemory::new).transpose()?;
            Ok((name, dir, key))
        };
        match enclave() {
            Ok((name, dir, key)) => {
                let mut files = DomainParticipantSecurityConfigFiles::with_ros_default_names(dir, String::new());
                if let Some(k) = &key {
                    // the same files, but the key from memory
                    files.participant_identity_private_key =
                        DomainParticipantSecurityConfigFiles::with_ros_default_names(k.dir(), String::new())
                            .participant_identity_private_key;
                }
                Ok((builder.builtin_security(files), Some(Joined { name, key })))
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
            Security::On { keystore: Some("k".into()), enforce: true, enclave_override: None, key_password_file: None }
        );
        assert_eq!(
            vars(&[
                ("ROS_SECURITY_ENABLE", "true"),
                ("ROS_SECURITY_STRATEGY", "enforce"),
                ("ROS_SECURITY_ENCLAVE_OVERRIDE", "/x"),
                ("EQUIARM_SECURITY_KEY_PASSWORD_FILE", "pw")
            ]),
            Security::On {
                keystore: None,
                enforce: false,
                enclave_override: Some("/x".into()),
                key_password_file: Some("pw".into())
            }
        );
    }

    #[test]
    fn enforce_refuses_and_permissive_warns_without_a_keystore() {
        let b = || DomainParticipantBuilder::new(0);
        let on = |enforce| Security::On { keystore: None, enforce, enclave_override: None, key_password_file: None };
        let e = on(true).apply(b(), "/env0/sim", 0).err().unwrap().to_string();
        assert!(e.contains("ROS_SECURITY_KEYSTORE") && e.contains("Enforce"), "{e}");
        assert!(on(false).apply(b(), "/env0/sim", 0).unwrap().1.is_none());
        let missing = Security::On {
            keystore: Some("/nonexistent".into()),
            enforce: true,
            enclave_override: None,
            key_password_file: None,
        };
        let e = missing.apply(b(), "/env0/sim", 0).err().unwrap().to_string();
        assert!(e.contains("/nonexistent/enclaves/equiarm/env0/sim"), "{e}");
    }
}
