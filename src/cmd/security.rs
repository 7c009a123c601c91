//! `equiarm security`: keystores and enclaves for a secured suite, laid out as `ros2 security` lays
//! them out (docs/security.md).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::Subcommand;
use equiarm_nodes::ros::RosOptions;
use equiarm_security::{EnclaveName, Grant, KeyPassword, Keystore, Role};

/// `equiarm security` subcommands.
#[derive(Subcommand)]
pub enum SecurityCommand {
    /// Creates a keystore: one CA (identities and permissions), the governance for the domain
    /// (authenticated participants only; discovery, liveliness and every topic encrypted), signed.
    CreateKeystore {
        /// The keystore's directory (created if missing; one that holds a keystore is refused).
        dir: PathBuf,
        /// Domain of the governance (default: ROS_DOMAIN_ID, else 0, as `ros2 security` does).
        #[arg(long)]
        domain: Option<u16>,
    },
    /// Creates a node's enclave: its identity (key and certificate from the keystore's CA) and its
    /// permissions, signed. A suite node's enclave is `/equiarm` + its node name (`/equiarm/env0/sim`,
    /// `/equiarm/trainer`); its permissions are exactly its topics (docs/nodes.md). An existing
    /// identity is kept; the permissions are rewritten.
    CreateEnclave {
        /// The keystore's directory.
        dir: PathBuf,
        /// The enclave, e.g. `/equiarm/env0/policy`.
        name: String,
        /// Domain of the permissions (default: ROS_DOMAIN_ID, else 0).
        #[arg(long)]
        domain: Option<u16>,
        /// Every topic (what `ros2 security create_enclave` grants), for a node that is not the suite's.
        #[arg(long)]
        all_topics: bool,
        /// Encrypt a new key with the password on this file's first line (nodes then need
        /// EQUIARM_SECURITY_KEY_PASSWORD_FILE naming a file with it; an existing key is kept as it is).
        #[arg(long, value_name = "FILE")]
        key_password_file: Option<PathBuf>,
    },
    /// Lists a keystore's enclaves.
    ListEnclaves {
        /// The keystore's directory.
        dir: PathBuf,
    },
}

/// Runs `equiarm security`.
pub fn run(c: SecurityCommand) -> anyhow::Result<ExitCode> {
    match c {
        SecurityCommand::CreateKeystore { dir, domain } => {
            let domain = domain_or_env(domain)?;
            Keystore::create(&dir, domain)?;
            println!("created keystore {} (domain {domain})", dir.display());
        }
        SecurityCommand::CreateEnclave { dir, name, domain, all_topics, key_password_file } => {
            let domain = domain_or_env(domain)?;
            let ks = Keystore::open(&dir)?;
            let name = EnclaveName::parse(&name)?;
            let grant = match (Role::of(&name), all_topics) {
                (_, true) => Grant::everything(),
                (Some(role), false) => role.grant(),
                (None, false) => bail!(
                    "enclave '{name}' is none of the suite's nodes (/equiarm/<env>/sim, /equiarm/<env>/policy, \
                     /equiarm/trainer, /equiarm/equiarm_recorder, /equiarm/equiarm_echo, \
                     /equiarm/equiarm_player); --all-topics grants it every topic"
                ),
            };
            let password = key_password_file.as_deref().map(KeyPassword::read).transpose()?;
            let at = ks
                .create_enclave(&name, domain, &grant, password.as_ref())
                .with_context(|| format!("creating enclave '{name}'"))?;
            println!("created enclave {name} in {} (domain {domain})", at.display());
        }
        SecurityCommand::ListEnclaves { dir } => {
            for e in Keystore::open(&dir)?.enclaves()? {
                println!("{e}");
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `--domain`, else ROS_DOMAIN_ID as the nodes read it.
fn domain_or_env(domain: Option<u16>) -> anyhow::Result<u16> {
    match domain {
        Some(d) if d > 232 => bail!("--domain {d} is not a DDS domain id (0..=232)"),
        Some(d) => Ok(d),
        None => Ok(RosOptions::from_env()?.domain_id),
    }
}
