//! What a node checks on its enclave before it joins a secured domain, so that a missing, expired or
//! tampered-with file stops it with an error naming that file (the DDS Security plugins would refuse
//! the same files, but without saying which).

use std::fs;
use std::path::{Path, PathBuf};

use openssl::asn1::Asn1Time;
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::x509::X509;
use openssl::x509::store::X509StoreBuilder;

use crate::keystore::{KEY_PASSWORD_VAR, KeyPassword, read_cert};
use crate::xml::{Element, domains_hold};
use crate::{Error, io_error};

/// The six files of an enclave, in ROS 2's names.
pub const ENCLAVE_FILES: [&str; 6] =
    ["identity_ca.cert.pem", "cert.pem", "key.pem", "permissions_ca.cert.pem", "governance.p7s", "permissions.p7s"];

/// An enclave's files that passed [`check_enclave`].
#[derive(Clone, Debug)]
pub struct Enclave {
    /// The enclave's directory.
    pub dir: PathBuf,
    /// The subject of its identity certificate (`CN=/equiarm/env0/sim`).
    pub subject: String,
    /// The signed governance's XML.
    pub governance: String,
    /// The signed permissions' XML.
    pub permissions: String,
    /// `key.pem` decrypted (unencrypted PKCS#8 PEM), when it is encrypted with a password: the DDS
    /// Security plugins read only unencrypted keys, so a node hands them this one from memory
    /// ([`KeyInMemory`](crate::KeyInMemory)).
    pub decrypted_key: Option<Vec<u8>>,
}

impl Enclave {
    /// The path of one of [`ENCLAVE_FILES`].
    pub fn file(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

/// Checks the enclave in `dir` for joining `domain`: every file there and readable; the identity
/// certificate issued by the identity CA and valid now; the key the certificate's; the governance and
/// permissions signed by the permissions CA, parsing, with a rule for `domain`, and a grant for the
/// certificate's subject that is valid now and allows something on `domain`. An encrypted `key.pem`
/// needs `password`.
pub fn check_enclave(dir: &Path, domain: u16, password: Option<&KeyPassword>) -> Result<Enclave, Error> {
    for f in ENCLAVE_FILES {
        let p = dir.join(f);
        if !p.is_file() {
            return Err(Error::File { path: p, why: "missing".into() });
        }
    }
    let bad = |f: &str, why: String| Error::File { path: dir.join(f), why };
    let identity_ca = read_cert(&dir.join("identity_ca.cert.pem"))?;
    let cert = read_cert(&dir.join("cert.pem"))?;
    let ca_key = identity_ca.public_key().map_err(|e| bad("identity_ca.cert.pem", format!("no public key: {e}")))?;
    if !cert.verify(&ca_key).unwrap_or(false) {
        return Err(bad("cert.pem", "not issued by identity_ca.cert.pem (another CA, or tampered with)".into()));
    }
    valid_now(&cert).map_err(|why| bad("cert.pem", why))?;
    valid_now(&identity_ca).map_err(|why| bad("identity_ca.cert.pem", why))?;
    let (key, decrypted_key) = read_key(&dir.join("key.pem"), password)?;
    let cert_key = cert.public_key().map_err(|e| bad("cert.pem", format!("no public key: {e}")))?;
    if !key.public_eq(&cert_key) {
        return Err(bad("key.pem", "not the key of cert.pem".into()));
    }
    let permissions_ca = read_cert(&dir.join("permissions_ca.cert.pem"))?;
    valid_now(&permissions_ca).map_err(|why| bad("permissions_ca.cert.pem", why))?;
    let governance = signed_content(&dir.join("governance.p7s"), &permissions_ca)?;
    let permissions = signed_content(&dir.join("permissions.p7s"), &permissions_ca)?;
    let subject = cert
        .subject_name()
        .entries()
        .map(|e| {
            let key = e.object().nid().short_name().unwrap_or("?");
            format!("{key}={}", e.data().to_string().unwrap_or_default())
        })
        .collect::<Vec<_>>()
        .join(",");
    check_governance(&governance, domain).map_err(|why| bad("governance.p7s", why))?;
    check_permissions(&permissions, &subject, domain).map_err(|why| bad("permissions.p7s", why))?;
    Ok(Enclave { dir: dir.to_path_buf(), subject, governance, permissions, decrypted_key })
}

fn check_governance(xml: &str, domain: u16) -> Result<(), String> {
    let doc = Element::parse(xml).map_err(|e| format!("the signed governance does not parse: {e}"))?;
    let rules = doc.at("domain_access_rules/domain_rule");
    if rules.iter().any(|r| r.get("domains").is_some_and(|d| domains_hold(d, domain))) {
        Ok(())
    } else {
        Err(format!("the governance has no rule for domain {domain} (a keystore for another domain?)"))
    }
}

fn check_permissions(xml: &str, subject: &str, domain: u16) -> Result<(), String> {
    let doc = Element::parse(xml).map_err(|e| format!("the signed permissions do not parse: {e}"))?;
    let grants = doc.at("permissions/grant");
    let Some(grant) = grants.iter().find(|g| g.get("subject_name").is_some_and(|s| same_subject(&s.text, subject)))
    else {
        return Err(format!("no grant for the identity {subject} of cert.pem"));
    };
    let now = chrono::Utc::now().format("%Y-%m-%dT%H:%M:%S").to_string();
    let when = |path: &str| grant.at(path).first().map(|e| e.text.trim_end_matches('Z').to_string());
    if let (Some(from), Some(to)) = (when("validity/not_before"), when("validity/not_after"))
        && !(from.as_str() <= now.as_str() && now.as_str() <= to.as_str())
    {
        return Err(format!("the grant for {subject} is valid from {from} to {to}, not now ({now} UTC)"));
    }
    let allows = grant.all("allow_rule").any(|r| r.get("domains").is_some_and(|d| domains_hold(d, domain)));
    if allows {
        Ok(())
    } else {
        Err(format!("the grant for {subject} allows nothing on domain {domain} (a keystore for another domain?)"))
    }
}

/// Whether two distinguished names (`CN=a,O=b`) hold the same attributes, in any order.
fn same_subject(a: &str, b: &str) -> bool {
    let parts = |s: &str| {
        let mut v: Vec<String> = s.split(',').map(|p| p.trim().replace(" = ", "=")).filter(|p| !p.is_empty()).collect();
        v.sort();
        v
    };
    parts(a) == parts(b)
}

fn valid_now(cert: &X509) -> Result<(), String> {
    let now = Asn1Time::days_from_now(0).map_err(|e| e.to_string())?;
    if cert.not_after() < now {
        return Err(format!("expired on {}", cert.not_after()));
    }
    if cert.not_before() > now {
        return Err(format!("not valid before {}", cert.not_before()));
    }
    Ok(())
}

/// The key in `path`, and its unencrypted PEM when the file is encrypted.
fn read_key(path: &Path, password: Option<&KeyPassword>) -> Result<(PKey<Private>, Option<Vec<u8>>), Error> {
    let bad = |why: String| Error::File { path: path.to_path_buf(), why };
    let pem = fs::read(path).map_err(io_error(path))?;
    if !String::from_utf8_lossy(&pem).contains("ENCRYPTED") {
        return Ok((PKey::private_key_from_pem(&pem).map_err(|e| bad(format!("not a PEM private key: {e}")))?, None));
    }
    let Some(password) = password else {
        return Err(bad(format!(
            "encrypted with a password, and none was given (set {KEY_PASSWORD_VAR} to a file that holds it)"
        )));
    };
    let key = PKey::private_key_from_pem_passphrase(&pem, password.secret()).map_err(|_| {
        bad(format!("the password in {} does not decrypt it (or it is not a PEM private key)", password.file.display()))
    })?;
    let plain = key.private_key_to_pem_pkcs8().map_err(|e| bad(format!("re-encoding the decrypted key: {e}")))?;
    Ok((key, Some(plain)))
}

/// The content of the S/MIME document `path` after checking its signature against `ca`.
fn signed_content(path: &Path, ca: &X509) -> Result<String, Error> {
    let bad = |why: String| Error::File { path: path.to_path_buf(), why };
    let smime = fs::read(path).map_err(io_error(path))?;
    let (p7, content) = Pkcs7::from_smime(&smime).map_err(|e| bad(format!("not an S/MIME signed document: {e}")))?;
    let content = content.ok_or_else(|| bad("its signature is not detached from the document".into()))?;
    let mut store = X509StoreBuilder::new().map_err(|e| bad(e.to_string()))?;
    store.add_cert(ca.clone()).map_err(|e| bad(e.to_string()))?;
    let store = store.build();
    let certs = Stack::new().map_err(|e| bad(e.to_string()))?;
    let mut out = Vec::new();
    p7.verify(&certs, &store, Some(&content), Some(&mut out), Pkcs7Flags::TEXT)
        .map_err(|_| bad("its signature does not verify against permissions_ca.cert.pem (tampered with, or signed by another CA)".into()))?;
    String::from_utf8(out).map_err(|_| bad("the signed document is not UTF-8".into()))
}
