//! Keystores as `ros2 security` lays them out, and the checks a node runs on its enclave: every bad
//! file is refused with an error naming it.

use std::fs;
use std::path::Path;

use equiarm_security::{EnclaveName, Error, KeyPassword, Keystore, Role, check_enclave};
use openssl::asn1::Asn1Time;
use openssl::hash::MessageDigest;
use openssl::pkey::PKey;
use openssl::x509::X509;

fn name(n: &str) -> EnclaveName {
    EnclaveName::parse(n).unwrap()
}

/// A keystore with the sim of env0 on `domain`; returns the enclave's directory.
fn keystore_with_sim(root: &Path, domain: u16) -> (Keystore, std::path::PathBuf) {
    let ks = Keystore::create(root, domain).unwrap();
    let e = name("/equiarm/env0/sim");
    let dir = ks.create_enclave(&e, domain, &Role::of(&e).unwrap().grant(), None).unwrap();
    (ks, dir)
}

fn refused(dir: &Path, domain: u16, file: &str, words: &str) {
    let e = check_enclave(dir, domain, None).unwrap_err().to_string();
    assert!(e.contains(&dir.join(file).display().to_string()), "error does not name {file}: {e}");
    assert!(e.contains(words), "error for {file} does not say '{words}': {e}");
}

#[test]
fn a_keystore_has_the_ros2_layout_and_its_enclaves_pass_the_checks() {
    let tmp = tempfile::tempdir().unwrap();
    let (ks, dir) = keystore_with_sim(tmp.path(), 7);
    for f in [
        "public/ca.cert.pem",
        "public/identity_ca.cert.pem",
        "public/permissions_ca.cert.pem",
        "private/ca.key.pem",
        "private/identity_ca.key.pem",
        "private/permissions_ca.key.pem",
        "enclaves/governance.xml",
        "enclaves/governance.p7s",
    ] {
        assert!(tmp.path().join(f).is_file(), "{f}");
    }
    for f in ["identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s"] {
        let link = fs::read_link(dir.join(f)).unwrap();
        assert!(link.is_relative(), "{f} links to {}", link.display());
    }
    let enclave = check_enclave(&dir, 7, None).unwrap();
    assert_eq!(enclave.subject, "CN=/equiarm/env0/sim");
    assert!(enclave.permissions.contains("<topic>rt/env0/observation</topic>"));
    // every topic's submessages encrypted (the payload inside them; docs/security.md on why not twice)
    assert!(enclave.governance.contains("<metadata_protection_kind>ENCRYPT</metadata_protection_kind>"));
    assert!(enclave.governance.contains("<data_protection_kind>NONE</data_protection_kind>"));
    assert_eq!(ks.enclaves().unwrap(), vec![name("/equiarm/env0/sim")]);
    use std::os::unix::fs::PermissionsExt;
    assert_eq!(fs::metadata(dir.join("key.pem")).unwrap().permissions().mode() & 0o777, 0o600);
    // A second keystore in the same place would replace every identity: refused.
    assert!(matches!(Keystore::create(tmp.path(), 7), Err(Error::KeystoreExists(_))));
    // Re-creating an enclave keeps its identity.
    let cert = fs::read(dir.join("cert.pem")).unwrap();
    ks.create_enclave(&name("/equiarm/env0/sim"), 7, &Role::Trainer.grant(), None).unwrap();
    assert_eq!(fs::read(dir.join("cert.pem")).unwrap(), cert);
}

#[test]
fn missing_tampered_foreign_and_wrong_domain_files_are_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (ks, dir) = keystore_with_sim(&tmp.path().join("ours"), 7);
    let (_, other) = keystore_with_sim(&tmp.path().join("theirs"), 7);
    let keep = |f: &str| fs::read(dir.join(f)).unwrap();
    let restore = |f: &str, data: &[u8]| {
        let p = dir.join(f);
        let _ = fs::remove_file(&p);
        fs::write(p, data).unwrap();
    };

    // Another domain.
    refused(&dir, 8, "governance.p7s", "domain 8");

    // Missing.
    let key = keep("key.pem");
    fs::remove_file(dir.join("key.pem")).unwrap();
    refused(&dir, 7, "key.pem", "missing");
    restore("key.pem", &key);

    // Tampered with: a weights topic written into the signed permissions.
    let perms = keep("permissions.p7s");
    let forged = String::from_utf8(perms.clone()).unwrap().replace("rt/env0/observation", "rt/policy/weights");
    restore("permissions.p7s", forged.as_bytes());
    refused(&dir, 7, "permissions.p7s", "does not verify");
    // Signed by another CA.
    restore("permissions.p7s", &fs::read(other.join("permissions.p7s")).unwrap());
    refused(&dir, 7, "permissions.p7s", "does not verify");
    restore("permissions.p7s", &perms);

    // An identity from another CA, and a key that is not the certificate's.
    let cert = keep("cert.pem");
    restore("cert.pem", &fs::read(other.join("cert.pem")).unwrap());
    refused(&dir, 7, "cert.pem", "not issued by");
    restore("cert.pem", &cert);
    restore("key.pem", &fs::read(other.join("key.pem")).unwrap());
    refused(&dir, 7, "key.pem", "not the key");
    restore("key.pem", &key);

    // A governance that does not parse, properly signed.
    let gov = keep("governance.p7s");
    restore("governance.p7s", &ks.sign(b"<dds><domain_access_rules></dds>").unwrap());
    refused(&dir, 7, "governance.p7s", "does not parse");
    restore("governance.p7s", &gov);

    // An expired identity certificate from the right CA.
    let ca_key = PKey::private_key_from_pem(&fs::read(ks.root().join("private/ca.key.pem")).unwrap()).unwrap();
    let ca = X509::from_pem(&fs::read(ks.root().join("public/ca.cert.pem")).unwrap()).unwrap();
    let old = X509::from_pem(&cert).unwrap();
    let mut b = X509::builder().unwrap();
    b.set_version(2).unwrap();
    b.set_subject_name(old.subject_name()).unwrap();
    b.set_issuer_name(ca.subject_name()).unwrap();
    b.set_pubkey(&old.public_key().unwrap()).unwrap();
    b.set_not_before(&Asn1Time::from_unix(1_600_000_000).unwrap()).unwrap();
    b.set_not_after(&Asn1Time::from_unix(1_700_000_000).unwrap()).unwrap();
    b.sign(&ca_key, MessageDigest::sha256()).unwrap();
    restore("cert.pem", &b.build().to_pem().unwrap());
    refused(&dir, 7, "cert.pem", "expired");
    restore("cert.pem", &cert);

    // A key encrypted with a password: refused without the password or with a wrong one (naming the
    // password's file), decrypted with the right one.
    let pkey = PKey::private_key_from_pem(&key).unwrap();
    let enc = pkey.private_key_to_pem_pkcs8_passphrase(openssl::symm::Cipher::aes_256_cbc(), b"secret").unwrap();
    restore("key.pem", &enc);
    refused(
        &dir,
        7,
        "key.pem",
        "encrypted with a password, and none was given (set EQUIARM_SECURITY_KEY_PASSWORD_FILE",
    );
    let pw_dir = tempfile::tempdir().unwrap();
    let pw = |text: &str| {
        let f = pw_dir.path().join(format!("pw{}", text.len()));
        fs::write(&f, text).unwrap();
        KeyPassword::read(&f).unwrap()
    };
    let wrong = pw("not the secret\n");
    let e = check_enclave(&dir, 7, Some(&wrong)).unwrap_err().to_string();
    assert!(e.contains(&dir.join("key.pem").display().to_string()), "{e}");
    assert!(e.contains(&format!("the password in {} does not decrypt it", wrong.file.display())), "{e}");
    let right = pw("secret\r\n");
    let enclave = check_enclave(&dir, 7, Some(&right)).unwrap();
    let plain = enclave.decrypted_key.expect("the decrypted key");
    assert!(PKey::private_key_from_pem(&plain).unwrap().public_eq(&pkey));
    restore("key.pem", &key);
    // an unencrypted key needs no password and is handed over as it is
    assert!(check_enclave(&dir, 7, Some(&right)).unwrap().decrypted_key.is_none());

    check_enclave(&dir, 7, None).unwrap();
}

/// `create-enclave --key-password-file`: the new key is encrypted with the password; an empty
/// password file is refused, naming it.
#[test]
fn an_enclave_made_with_a_password_has_an_encrypted_key() {
    let tmp = tempfile::tempdir().unwrap();
    let ks = Keystore::create(&tmp.path().join("ks"), 7).unwrap();
    let f = tmp.path().join("pw");
    fs::write(&f, "").unwrap();
    let e = KeyPassword::read(&f).unwrap_err().to_string();
    assert!(e.contains(&f.display().to_string()) && e.contains("empty"), "{e}");
    let e = KeyPassword::read(&tmp.path().join("none")).unwrap_err().to_string();
    assert!(e.contains("none"), "{e}");
    fs::write(&f, "hunter2\n").unwrap();
    let pw = KeyPassword::read(&f).unwrap();
    let e = name("/equiarm/env0/sim");
    let dir = ks.create_enclave(&e, 7, &Role::of(&e).unwrap().grant(), Some(&pw)).unwrap();
    assert!(fs::read_to_string(dir.join("key.pem")).unwrap().contains("BEGIN ENCRYPTED PRIVATE KEY"));
    refused(&dir, 7, "key.pem", "none was given");
    assert!(check_enclave(&dir, 7, Some(&pw)).unwrap().decrypted_key.is_some());
}

#[test]
fn a_directory_without_a_keystore_is_named_with_what_it_lacks() {
    let tmp = tempfile::tempdir().unwrap();
    let e = Keystore::open(tmp.path()).unwrap_err().to_string();
    assert!(e.contains("identity_ca.cert.pem") && e.contains("create-keystore"), "{e}");
}
