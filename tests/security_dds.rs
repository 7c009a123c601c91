//! DDS Security (SROS2) between our nodes over loopback, in a private network namespace
//! (`tests/run_all.sh`): secured nodes exchange samples of every size; a plain participant on the
//! same domain receives nothing from them and reaches none of them; a node cannot publish what its
//! permissions do not grant; a node refuses to start on a bad enclave under Enforce. Each test has
//! its own domain; every loop is bounded in count and time.

mod support;

use std::path::Path;
use std::time::{Duration, Instant};

use equiarm_msgs::msg::{GripperCommand, Observation};
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
        ks.create_enclave(&name, domain, &grant).unwrap();
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
    r
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
    permissive.security = Security::On { keystore: Some(tmp.path().into()), enforce: false, enclave_override: None };
    RosNode::new("/env0", "sim", &permissive).unwrap();
}
