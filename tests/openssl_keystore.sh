#!/usr/bin/env bash
# Makes a DDS Security keystore in ROS 2's layout with the `openssl` command only, as someone without
# `equiarm security` (or `ros2 security`) would by hand: a self-signed prime256v1 CA used as identity
# and permissions CA, a governance for domains 0-230 (sros2's default domain range), and per enclave
# a PKCS#8 key, a certificate `CN=<enclave>` issued by the CA and permissions for every topic, all
# S/MIME-signed. tests/security_dds.rs checks that our nodes join with it.
#
#   bash tests/openssl_keystore.sh DIR ENCLAVE...
set -euo pipefail
dir=$1
shift
mkdir -p "$dir/public" "$dir/private" "$dir/enclaves"
cd "$dir"
openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out private/ca.key.pem 2>/dev/null
openssl req -new -x509 -key private/ca.key.pem -subj "/CN=openssl keystore CA" -days 3650 -sha256 \
  -out public/ca.cert.pem
for role in identity_ca permissions_ca; do
  ln -sf ca.cert.pem "public/$role.cert.pem"
  ln -sf ca.key.pem "private/$role.key.pem"
done
sign() { openssl smime -sign -text -in "$1" -out "$2" -signer public/ca.cert.pem -inkey private/ca.key.pem; }
cat > enclaves/governance.xml <<'XML'
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>230</max></id_range></domains>
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
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
sign enclaves/governance.xml enclaves/governance.p7s
from=$(date -u -d '1 day ago' +%Y-%m-%dT%H:%M:%S) to=$(date -u -d '10 years' +%Y-%m-%dT%H:%M:%S)
for enclave in "$@"; do
  e="enclaves/${enclave#/}"
  mkdir -p "$e"
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$e/key.pem" 2>/dev/null
  chmod 600 "$e/key.pem"
  # '/' separates the parts of -subj: the enclave's slashes are escaped
  openssl req -new -key "$e/key.pem" -subj "/CN=${enclave//\//\\/}" -out "$e/req.csr"
  openssl x509 -req -in "$e/req.csr" -CA public/ca.cert.pem -CAkey private/ca.key.pem -CAcreateserial \
    -days 3650 -sha256 -out "$e/cert.pem" 2>/dev/null
  rm "$e/req.csr"
  cat > "$e/permissions.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$enclave">
      <subject_name>CN=$enclave</subject_name>
      <validity><not_before>$from</not_before><not_after>$to</not_after></validity>
      <allow_rule>
        <domains><id_range><min>0</min><max>230</max></id_range></domains>
        <publish><topics><topic>*</topic></topics></publish>
        <subscribe><topics><topic>*</topic></topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  sign "$e/permissions.xml" "$e/permissions.p7s"
  cp public/ca.cert.pem "$e/identity_ca.cert.pem"
  cp public/ca.cert.pem "$e/permissions_ca.cert.pem"
  cp enclaves/governance.p7s "$e/governance.p7s"
done
