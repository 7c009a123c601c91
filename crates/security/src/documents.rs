//! The two XML documents of DDS Security's access control (OMG DDS Security 1.1, §9.4.1): the domain
//! governance (what the domain protects) and an enclave's permissions (what it may publish and
//! subscribe), as ROS 2's `sros2` writes them.

use std::fmt::Write;

use crate::graph::{EnclaveName, Grant};

const GOVERNANCE_SCHEMA: &str = "http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd";
const PERMISSIONS_SCHEMA: &str = "http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd";

/// The governance of a secured suite on `domain`: only authenticated participants may join; discovery
/// and liveliness are encrypted, every RTPS message signed; every topic's submessages (the samples
/// they carry included) encrypted and authenticated, and reading and writing checked against each
/// participant's permissions. sros2's default, except that a sample's payload is not encrypted a
/// second time on its own (`data_protection_kind` NONE): RustDDS 0.15.1 fails to decrypt payloads
/// of samples over 64 KB (docs/security.md), and the encrypted submessage holds the payload anyway.
pub fn governance(domain: u16) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="{GOVERNANCE_SCHEMA}">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id>{domain}</id>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>NONE</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"#
    )
}

/// The permissions of `enclave` (subject `CN=<enclave>`, the subject of its identity certificate) on
/// `domain`, valid from `not_before` to `not_after` (`YYYY-MM-DDThh:mm:ss`, UTC): the deny rule
/// first, then the allow rule; anything else is denied.
pub fn permissions(enclave: &EnclaveName, domain: u16, grant: &Grant, not_before: &str, not_after: &str) -> String {
    let mut x = String::new();
    let _ = write!(
        x,
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="{PERMISSIONS_SCHEMA}">
  <permissions>
    <grant name="{name}">
      <subject_name>CN={name}</subject_name>
      <validity>
        <not_before>{not_before}</not_before>
        <not_after>{not_after}</not_after>
      </validity>
"#,
        name = escape(enclave.as_str()),
    );
    if !grant.deny_publish.is_empty() {
        rule(&mut x, "deny_rule", domain, &grant.deny_publish, &[]);
    }
    rule(&mut x, "allow_rule", domain, &grant.publish, &grant.subscribe);
    x.push_str("      <default>DENY</default>\n    </grant>\n  </permissions>\n</dds>\n");
    x
}

fn rule(x: &mut String, kind: &str, domain: u16, publish: &[String], subscribe: &[String]) {
    let _ = writeln!(x, "      <{kind}>\n        <domains>\n          <id>{domain}</id>\n        </domains>");
    for (what, topics) in [("publish", publish), ("subscribe", subscribe)] {
        if topics.is_empty() {
            continue;
        }
        let _ = writeln!(x, "        <{what}>\n          <topics>");
        for t in topics {
            let _ = writeln!(x, "            <topic>{}</topic>", escape(t));
        }
        let _ = writeln!(x, "          </topics>\n        </{what}>");
    }
    let _ = writeln!(x, "      </{kind}>");
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::Role;

    #[test]
    fn permissions_put_the_deny_rule_first_and_deny_by_default() {
        let e = EnclaveName::parse("/equiarm/equiarm_player").unwrap();
        let x = permissions(&e, 7, &Role::Player.grant(), "2026-01-01T00:00:00", "2036-01-01T00:00:00");
        let deny = x.find("<deny_rule>").unwrap();
        let allow = x.find("<allow_rule>").unwrap();
        assert!(deny < allow);
        assert!(x.contains("<subject_name>CN=/equiarm/equiarm_player</subject_name>"));
        assert!(x.contains("<id>7</id>"));
        assert!(x.trim_end().ends_with("<default>DENY</default>\n    </grant>\n  </permissions>\n</dds>"));
        assert!(governance(7).contains("<id>7</id>"));
    }
}
