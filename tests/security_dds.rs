//! DDS Security (SROS2) between our nodes over loopback, in a private network namespace
//! (`tests/run_all.sh`): secured nodes exchange samples of every size; a plain participant on the
//! same domain (ours, and Cyclone DDS's Python binding) receives nothing from them and reaches none
//! of them; a keystore made with the `openssl` command by hand works; a node cannot publish what its
//! permissions do not grant; a valid identity with self-granted permissions is refused; a capture
//! of the loopback shows no plaintext of a secured sample; a node refuses to start on a bad enclave
//! under Enforce. Each test has its own domain; every loop is bounded in count and time.

mod support;

use std::path::Path;
use std::time::{Duration, Instant};

use equiarm_msgs::msg::{GripperCommand, Observation, PolicyWeights, Transition};
use equiarm_nodes::ros::{Publisher, RosNode, RosOptions, Subscriber, qos};
use equiarm_nodes::secure::Security;
use equiarm_security::{EnclaveName, Grant, Keystore, Role};
use support::golden_values::*;

/// Options for a node in `enclave` of `keystore` under Enforce.
fn secured(domain_id: u16, keystore: &Path, enclave: &str) -> RosOptions {
    RosOptions {
        domain_id,
        localhost_only: false,
        security: Security::On {
            keystore: Some(keystore.into()),
            enforce: true,
            enclave_override: Some(enclave.into()),
            key_password_file: None,
        },
    }
}

/// Options for a node in the enclave its own name gives (`/equiarm` + the node's name, as rcl
/// derives it) of `keystore` under Enforce.
fn by_node_name(domain_id: u16, keystore: &Path) -> RosOptions {
    RosOptions {
        domain_id,
        localhost_only: false,
        security: Security::On {
            keystore: Some(keystore.into()),
            enforce: true,
            enclave_override: None,
            key_password_file: None,
        },
    }
}

fn plain(domain_id: u16) -> RosOptions {
    RosOptions { domain_id, ..Default::default() }
}

/// A keystore on `domain` with the given enclaves (their suite permissions, or every topic).
fn keystore(dir: &Path, domain: u16, enclaves: &[&str]) -> Keystore {
    let ks = Keystore::create(dir, domain).unwrap();
    for e in enclaves {
        let name = EnclaveName::parse(e).unwrap();
        let grant = Role::of(&name).map_or_else(Grant::everything, |r| r.grant());
        ks.create_enclave(&name, domain, &grant, None).unwrap();
    }
    ks
}

/// What the sim and the policy received.
#[derive(Default, Debug)]
struct Received {
    /// Commands as the policy sent them.
    cmds: usize,
    /// Any other command (a forged one).
    other_cmds: usize,
    /// Observations.
    obs: usize,
}

/// The policy publishes a command and the sim an observation every 100 ms for `secs`, counting what
/// arrives, until `enough` of each came (0: run the whole time).
async fn exchange(
    cmd_pub: &Publisher<GripperCommand>,
    obs_pub: &Publisher<Observation>,
    cmd_sub: &Subscriber<GripperCommand>,
    obs_sub: &Subscriber<Observation>,
    secs: u64,
    enough: usize,
) -> Received {
    let mut r = Received::default();
    let end = Instant::now() + Duration::from_secs(secs);
    while Instant::now() < end && (enough == 0 || r.cmds < enough || r.obs < enough) {
        round(cmd_pub, obs_pub, cmd_sub, obs_sub, &mut r).await;
    }
    r
}

/// One command and one observation out, what arrived within 50 ms counted into `r`.
async fn round(
    cmd_pub: &Publisher<GripperCommand>,
    obs_pub: &Publisher<Observation>,
    cmd_sub: &Subscriber<GripperCommand>,
    obs_sub: &Subscriber<Observation>,
    r: &mut Received,
) {
    cmd_pub.publish(command_typical()).await.unwrap();
    obs_pub.publish(observation(7, 152, 3)).await.unwrap();
    while let Ok(Some((m, _))) = cmd_sub.recv_timeout(Duration::from_millis(50)).await {
        if m == command_typical() {
            r.cmds += 1;
        } else {
            r.other_cmds += 1;
        }
    }
    while let Ok(Some(_)) = obs_sub.recv_timeout(Duration::from_millis(50)).await {
        r.obs += 1;
    }
}

/// The sim and the policy of env0, each in its enclave of a new keystore in `dir`, with the
/// endpoints of the lock-step loop.
struct SecuredPair {
    _sim: RosNode,
    _policy: RosNode,
    obs_pub: Publisher<Observation>,
    cmd_sub: Subscriber<GripperCommand>,
    cmd_pub: Publisher<GripperCommand>,
    obs_sub: Subscriber<Observation>,
}

impl SecuredPair {
    fn new(dir: &Path, domain: u16) -> Self {
        keystore(dir, domain, &["/equiarm/env0/sim", "/equiarm/env0/policy"]);
        Self::in_keystore(dir, domain)
    }

    /// The pair in the keystore `dir` (which has their enclaves).
    fn in_keystore(dir: &Path, domain: u16) -> Self {
        let mut sim = RosNode::new("/env0", "sim", &secured(domain, dir, "/equiarm/env0/sim")).unwrap();
        let mut policy = RosNode::new("/env0", "policy", &secured(domain, dir, "/equiarm/env0/policy")).unwrap();
        Self {
            obs_pub: sim.publisher("observation", qos::command()).unwrap(),
            cmd_sub: sim.subscription("gripper_cmd", qos::command()).unwrap(),
            cmd_pub: policy.publisher("gripper_cmd", qos::command()).unwrap(),
            obs_sub: policy.subscription("observation", qos::command()).unwrap(),
            _sim: sim,
            _policy: policy,
        }
    }
}

/// The policy and the sim of env0 in their own enclaves: a 57-byte GripperCommand (a length RustDDS
/// 0.15.1 cannot decrypt unless padded, see `Padded` in nodes/src/endpoints.rs) and a fragmented
/// 152-pixel Observation each way they go in the suite, encrypted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn secured_nodes_exchange_commands_and_observations() {
    let tmp = tempfile::tempdir().unwrap();
    let pair = SecuredPair::new(tmp.path(), 61);
    let r = exchange(&pair.cmd_pub, &pair.obs_pub, &pair.cmd_sub, &pair.obs_sub, 30, 5).await;
    assert!(r.cmds >= 5 && r.obs >= 5, "secured nodes exchanged only {r:?} in 30 s");
}

/// A keystore made with the `openssl` command alone (tests/openssl_keystore.sh: ROS 2's layout, a
/// governance for a range of domains, permissions for every topic, PKCS#8 keys): the sim and the
/// policy of env0 join with it and exchange commands and observations, encrypted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_keystore_made_with_openssl_by_hand_works() {
    let tmp = tempfile::tempdir().unwrap();
    let made = std::process::Command::new("bash")
        .arg(support::repo().join("tests/openssl_keystore.sh"))
        .arg(tmp.path())
        .args(["/equiarm/env0/sim", "/equiarm/env0/policy"])
        .output()
        .unwrap();
    assert!(made.status.success(), "openssl_keystore.sh: {}", String::from_utf8_lossy(&made.stderr));
    let pair = SecuredPair::in_keystore(tmp.path(), 70);
    let r = exchange(&pair.cmd_pub, &pair.obs_pub, &pair.cmd_sub, &pair.obs_sub, 30, 5).await;
    assert!(r.cmds >= 5 && r.obs >= 5, "nodes with the openssl keystore exchanged only {r:?} in 30 s");
}

/// A keystore made by ROS 2's own tooling: sros2's `create_keystore` and `create_enclave` (sros2's
/// governance for domain 78, its default permissions: every topic allowed), run by
/// `bench/sros2_keystore.sh SROS2_CHECKOUT`, which passes the keystore in `EQUIARM_SROS2_KEYSTORE`.
/// Ignored in the test command: sros2 is not on PyPI. The sim and the policy of env0 join with it
/// and exchange commands and observations, encrypted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs a keystore made by sros2: bash bench/sros2_keystore.sh SROS2_CHECKOUT"]
async fn a_keystore_made_by_sros2_works() {
    let ks = std::env::var_os("EQUIARM_SROS2_KEYSTORE")
        .expect("EQUIARM_SROS2_KEYSTORE names the keystore sros2 made (bash bench/sros2_keystore.sh SROS2_CHECKOUT)");
    let pair = SecuredPair::in_keystore(Path::new(&ks), 78);
    let r = exchange(&pair.cmd_pub, &pair.obs_pub, &pair.cmd_sub, &pair.obs_sub, 30, 5).await;
    assert!(r.cmds >= 5 && r.obs >= 5, "nodes with sros2's keystore exchanged only {r:?} in 30 s");
}

/// Enclaves whose keys are encrypted with a password (`create-enclave --key-password-file`): the
/// sim and the policy of env0, given the password file, join and exchange commands and observations
/// (the key decrypted into memory for the plugins); given a wrong password, a node does not start
/// under Enforce, and the error names `key.pem` and the password file.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nodes_with_password_protected_keys_join_with_the_password() {
    let tmp = tempfile::tempdir().unwrap();
    let ks_dir = tmp.path().join("keystore");
    let ks = Keystore::create(&ks_dir, 59).unwrap();
    let pw = tmp.path().join("password");
    std::fs::write(&pw, "correct horse\n").unwrap();
    let password = equiarm_security::KeyPassword::read(&pw).unwrap();
    for e in ["/equiarm/env0/sim", "/equiarm/env0/policy"] {
        let name = EnclaveName::parse(e).unwrap();
        let dir = ks.create_enclave(&name, 59, &Role::of(&name).unwrap().grant(), Some(&password)).unwrap();
        let key = std::fs::read_to_string(dir.join("key.pem")).unwrap();
        assert!(key.contains("BEGIN ENCRYPTED PRIVATE KEY"), "{key}");
    }
    let with_password = |enclave: &str, file: &Path| {
        let mut o = secured(59, &ks_dir, enclave);
        if let Security::On { key_password_file, .. } = &mut o.security {
            *key_password_file = Some(file.into());
        }
        o
    };
    let wrong = tmp.path().join("wrong");
    std::fs::write(&wrong, "battery staple\n").unwrap();
    let e = RosNode::new("/env0", "sim", &with_password("/equiarm/env0/sim", &wrong)).err().unwrap().to_string();
    assert!(e.contains("key.pem") && e.contains(&wrong.display().to_string()) && e.contains("Enforce"), "{e}");
    let e = RosNode::new("/env0", "sim", &secured(59, &ks_dir, "/equiarm/env0/sim")).err().unwrap().to_string();
    assert!(e.contains("key.pem") && e.contains("EQUIARM_SECURITY_KEY_PASSWORD_FILE"), "{e}");

    let mut sim = RosNode::new("/env0", "sim", &with_password("/equiarm/env0/sim", &pw)).unwrap();
    let mut policy = RosNode::new("/env0", "policy", &with_password("/equiarm/env0/policy", &pw)).unwrap();
    assert!(sim.secured() && policy.secured());
    let obs_pub = sim.publisher("observation", qos::command()).unwrap();
    let cmd_sub = sim.subscription("gripper_cmd", qos::command()).unwrap();
    let cmd_pub = policy.publisher("gripper_cmd", qos::command()).unwrap();
    let obs_sub = policy.subscription("observation", qos::command()).unwrap();
    let r = exchange(&cmd_pub, &obs_pub, &cmd_sub, &obs_sub, 30, 5).await;
    assert!(r.cmds >= 5 && r.obs >= 5, "nodes with password-protected keys exchanged only {r:?} in 30 s");
    // nothing of the decrypted key is left in the temporary directory
    let left: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(&format!("equiarm-key-{}-", std::process::id())))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// The main job's weights (reduced16 Equi: about 267 KB, sent as 256-byte fragments) from a secured
/// trainer reach a secured policy. RustDDS 0.15.1 cannot decrypt an encrypted payload of a sample
/// over 64 KB: with sros2's default governance (payloads encrypted too) nothing of 65,400 bytes or
/// more arrived, 60,000 did; ours encrypts the submessages only (docs/security.md).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn large_weights_reach_a_secured_policy() {
    let tmp = tempfile::tempdir().unwrap();
    keystore(tmp.path(), 58, &["/equiarm/trainer", "/equiarm/env0/policy"]);
    let mut trainer = RosNode::new("/", "trainer", &secured(58, tmp.path(), "/equiarm/trainer")).unwrap();
    let mut policy = RosNode::new("/env0", "policy", &secured(58, tmp.path(), "/equiarm/env0/policy")).unwrap();
    let weights_pub = trainer.publisher::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let weights_sub = policy.subscription::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let size = 267 * 1024;
    let mut got = Vec::new();
    let end = Instant::now() + Duration::from_secs(20);
    let mut version = 0;
    while Instant::now() < end && got.len() < 3 {
        version += 1;
        let w = PolicyWeights {
            run_id: "suite".into(),
            version,
            model: "equi".into(),
            data: ramp(size, 31, 17),
            ..Default::default()
        };
        weights_pub.publish(w).await.unwrap();
        let until = Instant::now() + Duration::from_secs(2);
        while Instant::now() < until {
            if let Ok(Some((w, _))) = weights_sub.recv_timeout(Duration::from_millis(100)).await {
                got.push((w.version, w.data.len()));
            }
        }
    }
    eprintln!("{size} bytes: received {got:?}");
    assert!(got.len() >= 3 && got.iter().all(|&(_, n)| n == size), "{size}-byte weights: received {got:?}");
}

/// A participant without an identity from the run's CA, on the same domain and topics: it receives
/// nothing the secured nodes publish, and nothing it publishes reaches them, while they still talk.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plain_participant_sees_nothing_and_reaches_nobody() {
    let tmp = tempfile::tempdir().unwrap();
    let pair = SecuredPair::new(tmp.path(), 62);
    let (obs_pub, cmd_sub, cmd_pub, obs_sub) = (&pair.obs_pub, &pair.cmd_sub, &pair.cmd_pub, &pair.obs_sub);
    let mut outsider = RosNode::new("/env0", "outsider", &plain(62)).unwrap();
    let spy_obs = outsider.subscription::<Observation>("observation", qos::command()).unwrap();
    let forged_cmd = outsider.publisher::<GripperCommand>("gripper_cmd", qos::command()).unwrap();

    let mut r = Received::default();
    let mut spied = 0;
    let end = Instant::now() + Duration::from_secs(15);
    while Instant::now() < end {
        forged_cmd.publish(command_special()).await.unwrap();
        let round = exchange(cmd_pub, obs_pub, cmd_sub, obs_sub, 1, 0).await;
        r.cmds += round.cmds;
        r.other_cmds += round.other_cmds;
        r.obs += round.obs;
        while let Ok(Some(_)) = spy_obs.recv_timeout(Duration::from_millis(10)).await {
            spied += 1;
        }
    }
    assert!(r.cmds >= 5 && r.obs >= 5, "the secured pair itself exchanged only {r:?}");
    assert_eq!(r.other_cmds, 0, "forged commands reached the secured sim: {r:?}");
    assert_eq!(spied, 0, "the plain participant received {spied} observations");
    assert_eq!(forged_cmd.subscription_count(&outsider), 0, "a secured reader matched the plain writer");
}

/// What the suite's three nodes received in [`beside_an_intruder`], real and forged apart.
#[derive(Default, Debug)]
struct Counts {
    cmds: usize,
    forged_cmds: usize,
    obs: usize,
    transitions: usize,
    forged_transitions: usize,
    weights: usize,
    forged_weights: usize,
}

/// The reward and run id of `dds_peer.py intrude`'s forged samples.
const FORGED_REWARD: f32 = 1234.5;
const FORGED_RUN: &str = "intruder";

/// A sim, a policy and a trainer of env0 (nodes made by `node(namespace, name)`) exchange commands,
/// observations, transitions and weights for `secs` while a plain Cyclone DDS participant
/// (`dds_peer.py intrude`) listens on the same domain and forges commands, transitions and weights:
/// what the nodes received, and the peer's report.
async fn beside_an_intruder(
    domain: u16,
    secs: u64,
    node: impl Fn(&str, &str) -> RosNode,
) -> (Counts, serde_json::Value) {
    let mut peer = support::python_script("dds_peer.py");
    peer.args(["intrude", &domain.to_string(), &secs.to_string()]).stdout(std::process::Stdio::piped());
    let peer = peer.spawn().unwrap_or_else(|e| panic!("starting dds_peer.py: {e}"));
    let (mut sim, mut policy, mut trainer) = (node("/env0", "sim"), node("/env0", "policy"), node("/", "trainer"));
    let obs_pub = sim.publisher::<Observation>("observation", qos::command()).unwrap();
    let cmd_sub = sim.subscription::<GripperCommand>("gripper_cmd", qos::command()).unwrap();
    let trans_pub = sim.publisher::<Transition>("/transitions", qos::stream(100)).unwrap();
    let cmd_pub = policy.publisher::<GripperCommand>("gripper_cmd", qos::command()).unwrap();
    let obs_sub = policy.subscription::<Observation>("observation", qos::command()).unwrap();
    let weights_sub = policy.subscription::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let weights_pub = trainer.publisher::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let trans_sub = trainer.subscription::<Transition>("/transitions", qos::stream(100)).unwrap();
    let real_transition = Transition { env: "env0".into(), episode: 1, step: 1, reward: 0.25, ..Default::default() };
    let (mut c, mut r) = (Counts::default(), Received::default());
    let end = Instant::now() + Duration::from_secs(secs);
    let mut version = 0;
    while Instant::now() < end {
        version += 1;
        let weights = PolicyWeights { run_id: "suite".into(), version, model: "equi".into(), ..Default::default() };
        weights_pub.publish(weights).await.unwrap();
        trans_pub.publish(real_transition.clone()).await.unwrap();
        round(&cmd_pub, &obs_pub, &cmd_sub, &obs_sub, &mut r).await;
        while let Ok(Some((t, _))) = trans_sub.recv_timeout(Duration::from_millis(10)).await {
            *(if t.reward == FORGED_REWARD { &mut c.forged_transitions } else { &mut c.transitions }) += 1;
        }
        while let Ok(Some((w, _))) = weights_sub.recv_timeout(Duration::from_millis(10)).await {
            *(if w.run_id == FORGED_RUN { &mut c.forged_weights } else { &mut c.weights }) += 1;
        }
    }
    (c.cmds, c.forged_cmds, c.obs) = (r.cmds, r.other_cmds, r.obs);
    let out = peer.wait_with_output().unwrap();
    assert!(out.status.success(), "dds_peer.py intrude failed: {}", out.status);
    let report = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["event"] == "done")
        .expect("dds_peer.py printed no report");
    (c, report)
}

/// Cyclone DDS (Python binding, what rclpy on rmw_cyclonedds uses), plain, beside the suite's nodes:
/// with the nodes plain it receives their observations, transitions and weights and its forgeries
/// reach them (the control); with the nodes secured it receives nothing, and none of its commands,
/// transitions or weights reaches a node, counted at each node, while the nodes still talk.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plain_cyclone_peer_sees_nothing_and_reaches_nobody() {
    let (plain_counts, plain_peer) =
        beside_an_intruder(65, 8, |ns, name| RosNode::new(ns, name, &plain(65)).unwrap()).await;
    let got = &plain_peer["received"];
    assert!(
        got["rt/env0/observation"].as_u64() > Some(0)
            && got["rt/transitions"].as_u64() > Some(0)
            && got["rt/policy/weights"].as_u64() > Some(0),
        "the control: a plain peer should receive from plain nodes: {plain_peer}"
    );
    let c = &plain_counts;
    assert!(c.forged_cmds > 0 && c.forged_transitions > 0 && c.forged_weights > 0, "the control: {c:?}");

    let tmp = tempfile::tempdir().unwrap();
    keystore(tmp.path(), 66, &["/equiarm/env0/sim", "/equiarm/env0/policy", "/equiarm/trainer"]);
    let (c, peer) =
        beside_an_intruder(66, 15, |ns, name| RosNode::new(ns, name, &by_node_name(66, tmp.path())).unwrap()).await;
    eprintln!("plain nodes: {plain_counts:?}, peer {plain_peer}\nsecured nodes: {c:?}, peer {peer}");
    assert!(c.cmds >= 5 && c.obs >= 5 && c.transitions >= 5 && c.weights >= 5, "the secured nodes themselves: {c:?}");
    assert_eq!((c.forged_cmds, c.forged_transitions, c.forged_weights), (0, 0, 0), "forgeries reached a node: {c:?}");
    for topic in ["rt/env0/observation", "rt/transitions", "rt/policy/weights"] {
        assert_eq!(peer["received"][topic].as_u64(), Some(0), "the plain peer received {topic}: {peer}");
    }
    for topic in ["rt/env0/gripper_cmd", "rt/transitions", "rt/policy/weights"] {
        assert!(peer["sent"][topic].as_u64() > Some(0), "{peer}");
        assert_eq!(
            peer["matched"][topic].as_u64(),
            Some(0),
            "a secured reader matched the peer's {topic} writer: {peer}"
        );
    }
}

/// The UDP payloads to one DDS domain's ports (RTPS: 7400 + 250 × domain and the 250 above) on the
/// network namespace's interfaces (only `lo` here) while it runs, through a raw packet socket (the
/// test command runs these tests as root of a private network namespace; other tests' domains are
/// left out).
struct Capture {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<Vec<u8>>,
}

impl Capture {
    fn start(domain: u16) -> Self {
        use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
        let proto = i32::from((libc::ETH_P_ALL as u16).to_be());
        // SAFETY: plain socket(2); the descriptor is owned (and closed) by `fd` from here on.
        let raw = unsafe { libc::socket(libc::AF_PACKET, libc::SOCK_RAW, proto) };
        assert!(raw >= 0, "a raw packet socket: {}", std::io::Error::last_os_error());
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        let timeout = libc::timeval { tv_sec: 0, tv_usec: 100_000 };
        // SAFETY: a valid descriptor and a timeval of the size given.
        let set = unsafe {
            libc::setsockopt(
                fd.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_RCVTIMEO,
                (&raw const timeout).cast(),
                size_of::<libc::timeval>() as libc::socklen_t,
            )
        };
        assert_eq!(set, 0, "SO_RCVTIMEO: {}", std::io::Error::last_os_error());
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = stop.clone();
        let base = 7400 + 250 * domain;
        let ports = base..base + 250;
        let thread = std::thread::spawn(move || {
            let (mut all, mut buf) = (Vec::new(), vec![0u8; 1 << 16]);
            while !flag.load(std::sync::atomic::Ordering::Relaxed) && all.len() < 256 << 20 {
                // SAFETY: `buf` is writable for its length.
                let n = unsafe { libc::recv(fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len(), 0) };
                if let Some(payload) = udp_payload(&buf[..n.max(0) as usize], ports.clone()) {
                    all.extend_from_slice(payload);
                }
            }
            all
        });
        Capture { stop, thread }
    }

    fn finish(self) -> Vec<u8> {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// The payload of an Ethernet frame holding an IPv4 UDP datagram to a port in `ports`.
fn udp_payload(frame: &[u8], ports: std::ops::Range<u16>) -> Option<&[u8]> {
    let ip = frame.get(14..).filter(|_| frame.get(12..14) == Some(&[0x08, 0x00]))?;
    let ihl = usize::from(ip.first()? & 0x0f) * 4;
    let udp = ip.get(ihl..).filter(|_| ip.get(9) == Some(&17))?;
    let port = u16::from_be_bytes([*udp.get(2)?, *udp.get(3)?]);
    ports.contains(&port).then(|| udp.get(8..)).flatten()
}

/// How many of `needles` occur in `hay`.
fn found(hay: &[u8], needles: &[Vec<u8>]) -> usize {
    needles.iter().filter(|n| hay.windows(n.len()).any(|w| w == &n[..])).count()
}

/// A sim publishes a known Transition and 152-pixel Observation every 100 ms for `secs`, to a trainer
/// and a policy, and the trainer the weights to the policy twice (nodes made by `node`, on `domain`),
/// while the loopback is captured: (the fewest of the three received, the capture).
async fn captured(
    domain: u16,
    secs: u64,
    node: impl Fn(&str, &str) -> RosNode,
    (transition, obs, weights): (&Transition, &Observation, &PolicyWeights),
) -> (usize, Vec<u8>) {
    let capture = Capture::start(domain);
    let (mut sim, mut policy, mut trainer) = (node("/env0", "sim"), node("/env0", "policy"), node("/", "trainer"));
    let obs_pub = sim.publisher::<Observation>("observation", qos::command()).unwrap();
    let trans_pub = sim.publisher::<Transition>("/transitions", qos::stream(100)).unwrap();
    let obs_sub = policy.subscription::<Observation>("observation", qos::command()).unwrap();
    let trans_sub = trainer.subscription::<Transition>("/transitions", qos::stream(100)).unwrap();
    let weights_pub = trainer.publisher::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let weights_sub = policy.subscription::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let (mut n_trans, mut n_obs, mut n_weights) = (0, 0, 0);
    let end = Instant::now() + Duration::from_secs(secs);
    while Instant::now() < end {
        trans_pub.publish(transition.clone()).await.unwrap();
        obs_pub.publish(obs.clone()).await.unwrap();
        if n_weights < 2 {
            weights_pub.publish(weights.clone()).await.unwrap();
        }
        while let Ok(Some(_)) = weights_sub.recv_timeout(Duration::from_millis(10)).await {
            n_weights += 1;
        }
        while let Ok(Some(_)) = trans_sub.recv_timeout(Duration::from_millis(50)).await {
            n_trans += 1;
        }
        while let Ok(Some(_)) = obs_sub.recv_timeout(Duration::from_millis(50)).await {
            n_obs += 1;
        }
    }
    drop((sim, policy, trainer));
    (n_trans.min(n_obs).min(n_weights), capture.finish())
}

/// A capture of the loopback traffic: the plain nodes' Transitions (a recognisable reward) and frame
/// bytes are there in plaintext; the secured nodes', exchanged the same way, are not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_capture_of_the_loopback_holds_no_plaintext_of_secured_samples() {
    let transition = Transition {
        env: "env0".into(),
        episode: 3,
        step: 17,
        obs_seq: 41,
        next_obs_seq: 42,
        reward: 0.123_456_79,
        action: command_typical(),
        ..Default::default()
    };
    let obs = observation(7, 152, 3);
    // weights over 64 KB, as the main job's (fragmented; see large_weights_reach_a_secured_policy)
    let weights =
        PolicyWeights { run_id: "suite".into(), version: 1, data: hash_words(96 * 1024, 5), ..Default::default() };
    let samples = (&transition, &obs, &weights);
    // the Transition's body from its action on (its reward included), 32-byte windows of the
    // Observation's frame planes and of the weights
    let t = equiarm_msgs::cdr::encode(&transition).unwrap();
    let mut needles = vec![t[t.len() - 40..].to_vec()];
    let o = equiarm_msgs::cdr::encode(&obs).unwrap();
    needles.extend((1..8).map(|k| o[k * o.len() / 8..][..32].to_vec()));
    needles.extend((1..8).map(|k| weights.data[k * weights.data.len() / 8..][..32].to_vec()));

    let (n, plain_capture) = captured(67, 6, |ns, name| RosNode::new(ns, name, &plain(67)).unwrap(), samples).await;
    assert!(n > 0, "the plain nodes exchanged only {n} of each sample");
    let in_plain = found(&plain_capture, &needles);
    assert!(
        found(&plain_capture, &needles[..1]) == 1 && in_plain >= 8,
        "the capture of plain nodes should show the payloads ({in_plain} of {} found in {} bytes)",
        needles.len(),
        plain_capture.len()
    );

    let tmp = tempfile::tempdir().unwrap();
    keystore(tmp.path(), 68, &["/equiarm/env0/sim", "/equiarm/env0/policy", "/equiarm/trainer"]);
    let (n, secured_capture) =
        captured(68, 12, |ns, name| RosNode::new(ns, name, &by_node_name(68, tmp.path())).unwrap(), samples).await;
    eprintln!(
        "plain: {in_plain} of {} payload windows in {} captured bytes; secured: at least {n} of each sample received, {} bytes captured",
        needles.len(),
        plain_capture.len(),
        secured_capture.len()
    );
    assert!(n >= 2, "the secured nodes exchanged only {n} of each sample");
    assert_eq!(found(&secured_capture, &needles), 0, "plaintext of a secured sample on the wire");
}

/// The policy's permissions do not include publishing weights: the node cannot create the writer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_cannot_publish_what_its_permissions_do_not_grant() {
    let tmp = tempfile::tempdir().unwrap();
    keystore(tmp.path(), 63, &["/equiarm/env0/policy"]);
    let mut policy = RosNode::new("/env0", "policy", &secured(63, tmp.path(), "/equiarm/env0/policy")).unwrap();
    let e = policy
        .publisher::<equiarm_msgs::msg::PolicyWeights>("/policy/weights", qos::latched())
        .err()
        .expect("a policy node may not publish weights")
        .to_string();
    assert!(e.contains("/policy/weights") && e.contains("security"), "{e}");
    // What it is granted works.
    policy.publisher::<GripperCommand>("gripper_cmd", qos::command()).unwrap();
}

/// A participant with a valid identity from the run's CA that grants itself permissions (signed by a
/// permissions CA of its own, with a governance to match): its own participant lets it create a
/// weights writer, the run's nodes refuse it: its weights reach no policy, and it receives none of
/// the trainer's, while the trainer's reach the policy.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_valid_identity_with_self_granted_permissions_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (run, own, forged) = (tmp.path().join("run"), tmp.path().join("own"), tmp.path().join("forged"));
    let ks = keystore(&run, 69, &["/equiarm/trainer", "/equiarm/env0/policy", "/equiarm/eval/policy"]);
    let mine = keystore(&own, 69, &[]);
    let name = EnclaveName::parse("/equiarm/eval/policy").unwrap();
    mine.create_enclave(&name, 69, &Grant::everything(), None).unwrap();
    // its own enclave's documents and CA for permissions; the run's certificate, key and identity CA
    let dir = forged.join("enclaves/equiarm/eval/policy");
    std::fs::create_dir_all(&dir).unwrap();
    for f in ["governance.p7s", "permissions.p7s", "permissions_ca.cert.pem"] {
        std::fs::copy(mine.enclave_dir(&name).join(f), dir.join(f)).unwrap();
    }
    for f in ["cert.pem", "key.pem", "identity_ca.cert.pem"] {
        std::fs::copy(ks.enclave_dir(&name).join(f), dir.join(f)).unwrap();
    }
    let mut intruder = RosNode::new("/eval", "policy", &secured(69, &forged, "/equiarm/eval/policy")).unwrap();
    let forged_pub =
        intruder.publisher::<PolicyWeights>("/policy/weights", qos::latched()).expect("granted by its own CA");
    let spy = intruder.subscription::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let mut trainer = RosNode::new("/", "trainer", &secured(69, &run, "/equiarm/trainer")).unwrap();
    let mut policy = RosNode::new("/env0", "policy", &secured(69, &run, "/equiarm/env0/policy")).unwrap();
    let weights_pub = trainer.publisher::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let weights_sub = policy.subscription::<PolicyWeights>("/policy/weights", qos::latched()).unwrap();
    let (mut real, mut fake, mut spied) = (0, 0, 0);
    let end = Instant::now() + Duration::from_secs(15);
    let mut version = 0;
    while Instant::now() < end {
        version += 1;
        let w = |run: &str| PolicyWeights { run_id: run.into(), version, model: "equi".into(), ..Default::default() };
        weights_pub.publish(w("suite")).await.unwrap();
        forged_pub.publish(w(FORGED_RUN)).await.unwrap();
        while let Ok(Some((w, _))) = weights_sub.recv_timeout(Duration::from_millis(50)).await {
            *(if w.run_id == FORGED_RUN { &mut fake } else { &mut real }) += 1;
        }
        while let Ok(Some((w, _))) = spy.recv_timeout(Duration::from_millis(50)).await {
            spied += usize::from(w.run_id != FORGED_RUN);
        }
    }
    assert!(real >= 5, "the trainer's weights reached the policy only {real} times");
    assert_eq!(fake, 0, "the self-granted weights reached the policy");
    assert_eq!(spied, 0, "the intruder received the trainer's weights");
    assert_eq!(forged_pub.subscription_count(&intruder), 1, "a reader besides the intruder's own matched its writer");
}

/// Under Enforce a node does not start on an enclave whose permissions were tampered with; the error
/// names the file. Under Permissive it starts without security.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_refuses_a_tampered_enclave_under_enforce() {
    let tmp = tempfile::tempdir().unwrap();
    let ks = keystore(tmp.path(), 64, &["/equiarm/env0/sim"]);
    let dir = ks.enclave_dir(&EnclaveName::parse("/equiarm/env0/sim").unwrap());
    let p7s = dir.join("permissions.p7s");
    let text = std::fs::read_to_string(&p7s).unwrap().replace("rt/env0/observation", "rt/policy/weights");
    std::fs::write(&p7s, text).unwrap();
    let e = RosNode::new("/env0", "sim", &secured(64, tmp.path(), "/equiarm/env0/sim")).err().unwrap().to_string();
    assert!(e.contains(&p7s.display().to_string()) && e.contains("Enforce"), "{e}");
    let mut permissive = secured(64, tmp.path(), "/equiarm/env0/sim");
    permissive.security = Security::On {
        keystore: Some(tmp.path().into()),
        enforce: false,
        enclave_override: None,
        key_password_file: None,
    };
    RosNode::new("/env0", "sim", &permissive).unwrap();
}

/// RustDDS 0.15.1 makes a reader under its security plugins' lock and then takes the participant's,
/// and makes a topic the other way round: a secured node whose spinner made its readers on a tokio
/// worker while the node made its own topics could hang at start-up (docs/security.md, "Two locks in
/// opposite orders"). A secured node made and given 30 topics at once, 200 times in a row, starts
/// every time.
#[test]
fn a_secured_node_makes_its_endpoints_while_its_spinner_starts() {
    const NODES: usize = 200;
    let tmp = tempfile::tempdir().unwrap();
    // an enclave outside the suite's roles: every topic granted
    keystore(tmp.path(), 57, &["/equiarm/test/starts"]);
    let opts = secured(57, tmp.path(), "/equiarm/test/starts");
    let (tx, rx) = std::sync::mpsc::channel();
    // A thread and a runtime of their own, so that a node hung in RustDDS shows as a timeout here,
    // not as a hung test (a runtime whose worker is stuck never finishes dropping).
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
        let _in_runtime = runtime.enter();
        for i in 0..NODES {
            let mut node = RosNode::new("/test", "starts", &opts).unwrap();
            let _pubs: Vec<Publisher<GripperCommand>> =
                (0..30).map(|t| node.publisher(&format!("t{t}"), qos::command()).unwrap()).collect();
            if tx.send(i).is_err() {
                return;
            }
        }
    });
    for i in 0..NODES {
        if let Err(e) = rx.recv_timeout(Duration::from_secs(30)) {
            panic!("secured node {} of {NODES} did not start within 30 s ({e})", i + 1);
        }
    }
}
