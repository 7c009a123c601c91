//! A keystore laid out as `ros2 security create_keystore` and `create_enclave` lay it out, so that a
//! keystore made by either tool works with the other's nodes:
//!
//! ```text
//! KEYSTORE/
//!   public/ca.cert.pem            the CA's certificate; identity_ca.cert.pem and
//!                                 permissions_ca.cert.pem are links to it
//!   private/ca.key.pem            the CA's key; identity_ca.key.pem, permissions_ca.key.pem link to it
//!   enclaves/governance.xml, governance.p7s
//!   enclaves/equiarm/env0/sim/    one enclave: cert.pem, key.pem, permissions.xml, permissions.p7s,
//!                                 and links to the two CA certificates and the governance
//! ```
//!
//! Keys are ECDSA on prime256v1 (DDS Security §9.3.1), certificates X.509 v3 signed with SHA-256,
//! valid from a day ago for ten years; documents are S/MIME signed (detached, text) by the
//! permissions CA.

use std::fs;
use std::io::Write;
use std::os::unix::fs::{OpenOptionsExt, symlink};
use std::path::{Path, PathBuf};

use chrono::{DateTime, Duration, Utc};
use openssl::asn1::{Asn1Integer, Asn1Time};
use openssl::bn::{BigNum, MsbOption};
use openssl::ec::{EcGroup, EcKey};
use openssl::hash::MessageDigest;
use openssl::nid::Nid;
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::symm::Cipher;
use openssl::x509::extension::BasicConstraints;
use openssl::x509::{X509, X509Name};

use crate::documents;
use crate::graph::{EnclaveName, Grant};
use crate::{Error, io_error, ssl_error};

/// The CA's common name (as sros2 names its own).
pub const CA_COMMON_NAME: &str = "equiarmCA";
/// How long certificates and permissions are valid.
pub const VALID_DAYS: i64 = 3650;

/// A keystore on disk.
#[derive(Clone, Debug)]
pub struct Keystore {
    root: PathBuf,
}

impl Keystore {
    /// Creates a keystore at `root` (made if missing) with a new CA and a governance for `domain`.
    /// A directory that already holds a keystore is refused, so that no identity is replaced by
    /// accident.
    pub fn create(root: &Path, domain: u16) -> Result<Self, Error> {
        if Self::open(root).is_ok() {
            return Err(Error::KeystoreExists(root.to_path_buf()));
        }
        for d in ["public", "private", "enclaves"] {
            let p = root.join(d);
            fs::create_dir_all(&p).map_err(io_error(&p))?;
        }
        let ks = Self { root: root.to_path_buf() };
        let (key, cert) = new_key_and_cert(CA_COMMON_NAME, None)?;
        write_private(&ks.root.join("private/ca.key.pem"), &pem_key(&key)?)?;
        write_file(&ks.root.join("public/ca.cert.pem"), &cert.to_pem().map_err(ssl_error("encoding the CA"))?)?;
        for role in ["identity_ca", "permissions_ca"] {
            link("ca.cert.pem", &ks.root.join(format!("public/{role}.cert.pem")))?;
            link("ca.key.pem", &ks.root.join(format!("private/{role}.key.pem")))?;
        }
        let gov = documents::governance(domain);
        write_file(&ks.root.join("enclaves/governance.xml"), gov.as_bytes())?;
        let signed = ks.sign(gov.as_bytes())?;
        write_file(&ks.root.join("enclaves/governance.p7s"), &signed)?;
        Ok(ks)
    }

    /// Opens the keystore at `root`: the error names the first file a keystore needs that is missing.
    pub fn open(root: &Path) -> Result<Self, Error> {
        for f in [
            "public/identity_ca.cert.pem",
            "public/permissions_ca.cert.pem",
            "private/identity_ca.key.pem",
            "private/permissions_ca.key.pem",
            "enclaves/governance.p7s",
        ] {
            let p = root.join(f);
            if !p.is_file() {
                return Err(Error::NotAKeystore { root: root.to_path_buf(), missing: p });
            }
        }
        Ok(Self { root: root.to_path_buf() })
    }

    /// The keystore's directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Where the enclave `name`'s files are (`KEYSTORE/enclaves/<name>`).
    pub fn enclave_dir(&self, name: &EnclaveName) -> PathBuf {
        name.dir_in(&self.root)
    }

    /// Creates the enclave `name` (or completes it: an existing identity is kept, as sros2 does) with
    /// permissions `grant` on `domain`, signed by the permissions CA. Returns its directory.
    /// With `password`, a new key is written encrypted with it (PKCS#8, AES-256-CBC, as `openssl
    /// genpkey -aes-256-cbc` writes it); nodes then need it ([`KEY_PASSWORD_VAR`]).
    pub fn create_enclave(
        &self,
        name: &EnclaveName,
        domain: u16,
        grant: &Grant,
        password: Option<&KeyPassword>,
    ) -> Result<PathBuf, Error> {
        let dir = self.enclave_dir(name);
        fs::create_dir_all(&dir).map_err(io_error(&dir))?;
        let depth = name.parts().count();
        let up = "../".repeat(depth);
        for (file, target) in [
            ("identity_ca.cert.pem", format!("{up}../public/identity_ca.cert.pem")),
            ("permissions_ca.cert.pem", format!("{up}../public/permissions_ca.cert.pem")),
            ("governance.p7s", format!("{up}governance.p7s")),
        ] {
            link(&target, &dir.join(file))?;
        }
        let (cert_path, key_path) = (dir.join("cert.pem"), dir.join("key.pem"));
        if !cert_path.is_file() || !key_path.is_file() {
            let ca = (self.read_key("private/identity_ca.key.pem")?, self.read_cert("public/identity_ca.cert.pem")?);
            let (key, cert) = new_key_and_cert(name.as_str(), Some((&ca.0, &ca.1)))?;
            let pem = match password {
                None => pem_key(&key)?,
                Some(p) => key
                    .private_key_to_pem_pkcs8_passphrase(Cipher::aes_256_cbc(), p.secret())
                    .map_err(ssl_error("encrypting a key"))?,
            };
            write_private(&key_path, &pem)?;
            write_file(&cert_path, &cert.to_pem().map_err(ssl_error("encoding a certificate"))?)?;
        }
        let cert = read_cert(&cert_path)?;
        let (from, to) = (xml_time(cert.not_before()), xml_time(cert.not_after()));
        let perms = documents::permissions(name, domain, grant, &from, &to);
        write_file(&dir.join("permissions.xml"), perms.as_bytes())?;
        write_file(&dir.join("permissions.p7s"), &self.sign(perms.as_bytes())?)?;
        Ok(dir)
    }

    /// The enclaves of this keystore (directories holding a `key.pem`), sorted.
    pub fn enclaves(&self) -> Result<Vec<EnclaveName>, Error> {
        fn walk(dir: &Path, prefix: &str, out: &mut Vec<EnclaveName>) -> Result<(), Error> {
            for entry in fs::read_dir(dir).map_err(io_error(dir))? {
                let entry = entry.map_err(io_error(dir))?;
                let path = entry.path();
                if path.is_dir() && !path.is_symlink() {
                    let name = format!("{prefix}/{}", entry.file_name().to_string_lossy());
                    if path.join("key.pem").is_file()
                        && let Ok(e) = EnclaveName::parse(&name)
                    {
                        out.push(e);
                    }
                    walk(&path, &name, out)?;
                }
            }
            Ok(())
        }
        let mut out = vec![];
        walk(&self.root.join("enclaves"), "", &mut out)?;
        out.sort();
        Ok(out)
    }

    fn read_key(&self, rel: &str) -> Result<PKey<Private>, Error> {
        let p = self.root.join(rel);
        let pem = fs::read(&p).map_err(io_error(&p))?;
        PKey::private_key_from_pem(&pem)
            .map_err(|e| Error::File { path: p, why: format!("not a PEM private key: {e}") })
    }

    fn read_cert(&self, rel: &str) -> Result<X509, Error> {
        read_cert(&self.root.join(rel))
    }

    /// `data` signed by the permissions CA as S/MIME (detached signature, text/plain), as
    /// `openssl smime -sign -text` and sros2 write it (for a governance or permissions edited by hand).
    pub fn sign(&self, data: &[u8]) -> Result<Vec<u8>, Error> {
        let key = self.read_key("private/permissions_ca.key.pem")?;
        let cert = self.read_cert("public/permissions_ca.cert.pem")?;
        let flags = Pkcs7Flags::DETACHED | Pkcs7Flags::TEXT;
        let extra = Stack::new().map_err(ssl_error("signing"))?;
        let p7 = Pkcs7::sign(&cert, &key, &extra, data, flags).map_err(ssl_error("signing a document"))?;
        p7.to_smime(data, flags).map_err(ssl_error("writing S/MIME"))
    }
}

/// The environment variable that names the file holding the password of the enclaves' encrypted
/// keys (one password for a run's keystore; ROS 2 itself has no such variable: its keys are
/// unencrypted).
pub const KEY_PASSWORD_VAR: &str = "EQUIARM_SECURITY_KEY_PASSWORD_FILE";

/// The password of encrypted keys, and the file it was read from (for errors).
pub struct KeyPassword {
    /// The file.
    pub file: PathBuf,
    secret: Vec<u8>,
}

impl KeyPassword {
    /// The password in `file`: its first line, without the line end (as `openssl -passin file:`
    /// reads it). An empty password is refused.
    pub fn read(file: &Path) -> Result<Self, Error> {
        let text = fs::read(file).map_err(io_error(file))?;
        let line = text.split(|&b| b == b'\n').next().unwrap_or_default();
        let secret = line.strip_suffix(b"\r").unwrap_or(line).to_vec();
        if secret.is_empty() {
            return Err(Error::File { path: file.to_path_buf(), why: "empty: no password on its first line".into() });
        }
        Ok(KeyPassword { file: file.to_path_buf(), secret })
    }

    pub(crate) fn secret(&self) -> &[u8] {
        &self.secret
    }
}

impl std::fmt::Debug for KeyPassword {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "KeyPassword {{ file: {:?} }}", self.file)
    }
}

/// Reads a PEM certificate; the error names the file.
pub fn read_cert(path: &Path) -> Result<X509, Error> {
    let pem = fs::read(path).map_err(io_error(path))?;
    X509::from_pem(&pem)
        .map_err(|e| Error::File { path: path.to_path_buf(), why: format!("not a PEM certificate: {e}") })
}

/// An ASN.1 time as the permissions document writes it (`YYYY-MM-DDThh:mm:ss`, UTC).
fn xml_time(t: &openssl::asn1::Asn1TimeRef) -> String {
    let epoch = Asn1Time::from_unix(0).expect("the epoch is a valid time");
    let diff = epoch.diff(t).expect("two valid times have a difference");
    let secs = i64::from(diff.days) * 86_400 + i64::from(diff.secs);
    let when: DateTime<Utc> = DateTime::from_timestamp(secs, 0).unwrap_or_default();
    when.format("%Y-%m-%dT%H:%M:%S").to_string()
}

/// A new prime256v1 key and its certificate `CN=<cn>`, signed by `issuer` (its key and certificate)
/// or self-signed as a CA.
fn new_key_and_cert(cn: &str, issuer: Option<(&PKey<Private>, &X509)>) -> Result<(PKey<Private>, X509), Error> {
    let e = ssl_error("making a certificate");
    let group = EcGroup::from_curve_name(Nid::X9_62_PRIME256V1).map_err(&e)?;
    let key = PKey::from_ec_key(EcKey::generate(&group).map_err(&e)?).map_err(&e)?;
    let mut name = X509Name::builder().map_err(&e)?;
    name.append_entry_by_nid(Nid::COMMONNAME, cn).map_err(&e)?;
    let name = name.build();
    let mut b = X509::builder().map_err(&e)?;
    b.set_version(2).map_err(&e)?;
    let mut serial = BigNum::new().map_err(&e)?;
    serial.rand(159, MsbOption::MAYBE_ZERO, false).map_err(&e)?;
    let serial = Asn1Integer::from_bn(&serial).map_err(&e)?;
    b.set_serial_number(&serial).map_err(&e)?;
    let now = Utc::now();
    let (from, to) = (now - Duration::days(1), now + Duration::days(VALID_DAYS));
    let (from, to) =
        (Asn1Time::from_unix(from.timestamp()).map_err(&e)?, Asn1Time::from_unix(to.timestamp()).map_err(&e)?);
    b.set_not_before(&from).map_err(&e)?;
    b.set_not_after(&to).map_err(&e)?;
    b.set_subject_name(&name).map_err(&e)?;
    b.set_pubkey(&key).map_err(&e)?;
    match issuer {
        None => {
            b.set_issuer_name(&name).map_err(&e)?;
            b.append_extension(BasicConstraints::new().critical().ca().pathlen(1).build().map_err(&e)?).map_err(&e)?;
            b.sign(&key, MessageDigest::sha256()).map_err(&e)?;
        }
        Some((ca_key, ca_cert)) => {
            b.set_issuer_name(ca_cert.subject_name()).map_err(&e)?;
            b.append_extension(BasicConstraints::new().build().map_err(&e)?).map_err(&e)?;
            b.sign(ca_key, MessageDigest::sha256()).map_err(&e)?;
        }
    }
    Ok((key, b.build()))
}

fn pem_key(key: &PKey<Private>) -> Result<Vec<u8>, Error> {
    key.private_key_to_pem_pkcs8().map_err(ssl_error("encoding a key"))
}

fn write_file(path: &Path, data: &[u8]) -> Result<(), Error> {
    fs::write(path, data).map_err(io_error(path))
}

/// Writes a private key readable by its owner only.
fn write_private(path: &Path, data: &[u8]) -> Result<(), Error> {
    let mut f = fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .map_err(io_error(path))?;
    f.write_all(data).map_err(io_error(path))
}

/// A relative symbolic link `at` → `target` (replacing an older link, as sros2 does).
fn link(target: &str, at: &Path) -> Result<(), Error> {
    if at.is_symlink() {
        fs::remove_file(at).map_err(io_error(at))?;
    }
    symlink(target, at).map_err(io_error(at))
}
