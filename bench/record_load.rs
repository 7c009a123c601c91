//! Benchmark: the recorder under the suite's load. N simulated env nodes (default 10, each its own
//! DDS participant in namespace /envK) publish a 152x152 RGBD `Observation` the simulator rendered at R Hz (default 50) for
//! S seconds (default 10) while `equiarm record --all` records them; prints published vs recorded
//! counts per env (drops), the recorder's peak RSS, CPU time and the data rate.
//!
//! With `--foxglove-rounds K` it runs K pairs of rounds, one without and one with a Foxglove
//! WebSocket client attached to `equiarm record --foxglove` (subscribed to every channel, counting
//! what it receives), alternating, and prints the medians of the recorder's messages/s and CPU time
//! per message of each side and their ratios.
//!
//! Run on loopback in a private network namespace: `bash bench/recorder_load.sh [N R S] [--foxglove-rounds K]`.

use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::Parser;
use equiarm_bag::{ReadMode, Reader};
use equiarm_msgs::msg::Observation;
use equiarm_nodes::ros::{RosNode, RosOptions, qos};
use equiarm_sim::EnvConfig;
use equiarm_train::stepper::Stepper;
use equiarm_types::TaskKind;
use tungstenite::client::IntoClientRequest;

fn vm(pid: u32, key: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with(key)).and_then(|l| l.split_whitespace().nth(1)?.parse().ok()))
        .unwrap_or(0.0)
        / 1024.0
}

/// User + system CPU seconds of a process so far (/proc/PID/stat fields 14 and 15, in clock ticks).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // the command name (field 2) may hold spaces: count fields after its closing parenthesis
    let rest = stat.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
    let f: Vec<f64> = rest.split_whitespace().map(|x| x.parse().unwrap_or(0.0)).collect();
    let ticks = f.get(11).copied().unwrap_or(0.0) + f.get(12).copied().unwrap_or(0.0);
    // SAFETY: sysconf only reads a configuration value.
    ticks / (unsafe { libc::sysconf(libc::_SC_CLK_TCK) }).max(1) as f64
}

/// The recorder under N simulated envs publishing RGBD observations at R Hz for S seconds.
#[derive(Parser, Debug)]
#[command(name = "record_load")]
struct Args {
    /// Simulated env nodes.
    #[arg(default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    envs: u64,
    /// Observations per second per env.
    #[arg(default_value_t = 50.0)]
    hz: f64,
    /// Seconds of publishing.
    #[arg(default_value_t = 10.0)]
    secs: f64,
    /// Pairs of rounds without and with a Foxglove client attached (0: one round, no client).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=20))]
    foxglove_rounds: u64,
    /// Internal: run one round in this process on this DDS domain and print it as JSON (each round
    /// of a comparison runs in a fresh process, so no DDS state of one round reaches the next).
    #[arg(long, hide = true)]
    one_round: Option<u16>,
    /// Internal: with --one-round, attach a Foxglove client.
    #[arg(long, hide = true)]
    with_client: bool,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

/// What one round measured.
#[derive(serde::Serialize, serde::Deserialize)]
struct Round {
    published: Vec<u64>,
    recorded: Vec<u64>,
    cdr_bytes: u64,
    disk_bytes: u64,
    rss_mb: f64,
    cpu_s: f64,
    /// Messages and bytes the Foxglove client received, when one was attached.
    client: Option<(u64, u64)>,
}

/// A Foxglove WebSocket client (protocol v1) on a thread: connects (retrying until the server is up),
/// subscribes to every channel advertised, counts the message-data frames until `stop`.
fn foxglove_client(port: u16, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<(u64, u64)> {
    std::thread::spawn(move || {
        let deadline = Instant::now() + Duration::from_secs(30);
        let tcp = loop {
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(s) => break s,
                Err(e) => {
                    assert!(Instant::now() < deadline, "no Foxglove server on port {port}: {e}");
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        };
        tcp.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
        let mut req = format!("ws://127.0.0.1:{port}").into_client_request().unwrap();
        req.headers_mut().insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1, foxglove.websocket.v1".parse().unwrap());
        let (mut ws, _) = tungstenite::client(req, tcp).expect("WebSocket handshake");
        let (mut msgs, mut bytes, mut next_sub) = (0u64, 0u64, 1u64);
        while !stop.load(Ordering::Relaxed) {
            match ws.read() {
                Ok(tungstenite::Message::Text(t)) => {
                    let m: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                    if m["op"] == "advertise" {
                        let subs: Vec<_> = m["channels"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|ch| {
                                next_sub += 1;
                                serde_json::json!({"id": next_sub, "channelId": ch["id"]})
                            })
                            .collect();
                        let sub = serde_json::json!({"op": "subscribe", "subscriptions": subs});
                        ws.send(tungstenite::Message::text(sub.to_string())).unwrap();
                    }
                }
                Ok(tungstenite::Message::Binary(b)) if b.first() == Some(&1) => {
                    msgs += 1;
                    bytes += b.len() as u64;
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
                Err(e) => panic!("Foxglove client: {e}"),
            }
        }
        // a closing handshake, so the server does not log a reset (errors here change no count)
        let _ = ws.close(None);
        let _ = ws.flush();
        (msgs, bytes)
    })
}

/// A child process killed (SIGKILL) when dropped, unless it already ended.
struct KillOnDrop(std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn round(args: &Args, domain: u16, foxglove: bool) -> Round {
    let (envs, hz, secs) = (args.envs as usize, args.hz, args.secs);
    let dir = std::env::temp_dir().join(format!("equiarm_record_load_{}_{domain}", std::process::id()));
    let bag = dir.join("load");
    let port = free_port();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_equiarm"));
    cmd.args(["record", "-q", "--all", "--compression", "zstd", "-o"]).arg(&bag);
    if foxglove {
        cmd.args(["--foxglove", &format!("127.0.0.1:{port}")]);
    }
    let rec = cmd
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("starting equiarm record");
    // killed if this round fails (a panic below), so no recorder outlives it
    let mut rec = KillOnDrop(rec);
    let stop = Arc::new(AtomicBool::new(false));
    let client = foxglove.then(|| foxglove_client(port, stop.clone()));

    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let published: Vec<u64> = rt.block_on(async {
        let opts = RosOptions { domain_id: domain, ..Default::default() };
        // a frame the simulator rendered (the paper's 152 px view of block pulling), so the messages
        // compress as the suite's do
        let mut stepper = Stepper::new(EnvConfig::new(TaskKind::BlockPulling), "env0", 0, false).unwrap();
        let frame = stepper.reset().unwrap().clone();
        let mut tasks = Vec::new();
        let matched = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        for e in 0..envs {
            let mut node = RosNode::new(&format!("/env{e}"), "sim", &opts).unwrap();
            let publ = node.publisher::<Observation>("observation", qos::command()).unwrap();
            let obs = Observation { env: format!("env{e}"), ..frame.clone() };
            let matched = matched.clone();
            tasks.push(tokio::spawn(async move {
                // wait until the recorder (which discovers topics every second) has matched every env:
                // publishing before that measures discovery under load (RustDDS then loses discovery
                // messages to full socket buffers), not recording
                let deadline = Instant::now() + Duration::from_secs(60);
                assert!(node.wait_for_subscription(&publ, Duration::from_secs(60)).await, "recorder never subscribed");
                matched.fetch_add(1, Ordering::SeqCst);
                while matched.load(Ordering::SeqCst) < envs {
                    assert!(Instant::now() < deadline, "the recorder did not subscribe to every env within 60 s");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                tokio::time::sleep(Duration::from_millis(500)).await;
                let start = Instant::now();
                let mut k = 0u64;
                while start.elapsed().as_secs_f64() < secs {
                    let mut o = obs.clone();
                    o.seq = k;
                    publ.publish(o).await.unwrap();
                    k += 1;
                    let next = Duration::from_secs_f64(k as f64 / hz);
                    if let Some(w) = next.checked_sub(start.elapsed()) {
                        tokio::time::sleep(w).await;
                    }
                }
                tokio::time::sleep(Duration::from_secs(2)).await; // let reliable delivery finish
                drop(node);
                k
            }));
        }
        let mut out = Vec::new();
        for t in tasks {
            out.push(t.await.unwrap());
        }
        out
    });
    let (rss_mb, cpu_s) = (vm(rec.0.id(), "VmHWM:"), cpu_seconds(rec.0.id()));
    stop.store(true, Ordering::Relaxed);
    let client = client.map(|c| c.join().expect("the Foxglove client failed"));
    Command::new("kill").args(["-INT", &rec.0.id().to_string()]).status().unwrap();
    let status = rec.0.wait().unwrap();
    assert!(status.success(), "recorder exit: {status}");

    let mut recorded = vec![0u64; envs];
    let mut cdr_bytes = 0u64;
    Reader::open(&bag)
        .unwrap()
        .for_each(ReadMode::Strict, |m| {
            if let Some(e) = m.topic.strip_prefix("/env").and_then(|t| t.strip_suffix("/observation")) {
                recorded[e.parse::<usize>().unwrap()] += 1;
                cdr_bytes += m.data.len() as u64;
            }
            Ok::<(), ()>(())
        })
        .unwrap()
        .unwrap();
    let disk_bytes: u64 = std::fs::read_dir(&bag).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum();
    let _ = std::fs::remove_dir_all(&dir);
    Round { published, recorded, cdr_bytes, disk_bytes, rss_mb, cpu_s, client }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 }
}

fn main() {
    let args = Args::parse();
    let (envs, hz, secs) = (args.envs as usize, args.hz, args.secs);
    println!(
        "recorder load: {envs} envs x {hz} Hz x {secs} s of 152x152 RGBD Observations ({:.0} messages/s offered)",
        envs as f64 * hz
    );
    if let Some(domain) = args.one_round {
        println!("{}", serde_json::to_string(&round(&args, domain, args.with_client)).unwrap());
        return;
    }
    if args.foxglove_rounds == 0 {
        let r = round(&args, 90, false);
        for e in 0..envs {
            println!(
                "  /env{e}/observation: published {:>6}, recorded {:>6}, dropped {}",
                r.published[e],
                r.recorded[e],
                r.published[e] as i64 - r.recorded[e] as i64
            );
        }
        let (p, n): (u64, u64) = (r.published.iter().sum(), r.recorded.iter().sum());
        println!(
            "total: published {p}, recorded {n}, dropped {}; {:.1} MB of CDR, {:.1} MB on disk (zstd)",
            p as i64 - n as i64,
            r.cdr_bytes as f64 / 1e6,
            r.disk_bytes as f64 / 1e6
        );
        println!("recorder peak RSS: {:.0} MB (budget 300 MB), CPU {:.1} s", r.rss_mb, r.cpu_s);
        return;
    }
    // (recorded messages/s, recorder CPU ms per recorded message) of each side, rounds alternating
    let (mut without, mut with) = (Vec::new(), Vec::new());
    println!("round  client  published  recorded  recorded/s  CDR MB/s  CPU s  CPU ms/msg  peak RSS MB  client got");
    for k in 0..args.foxglove_rounds {
        for attached in [false, true] {
            // a round whose DDS discovery failed (RustDDS with ten participants in one process
            // sometimes never matches one of them) is run again on another domain, and said so
            let mut attempt = 0u16;
            let r: Round = loop {
                let domain = 90 + (2 * k) as u16 + attached as u16 + 45 * attempt;
                let mut child = Command::new(std::env::current_exe().unwrap());
                child.args([args.envs.to_string(), hz.to_string(), secs.to_string()]);
                child.args(["--one-round", &domain.to_string()]).stderr(Stdio::inherit());
                if attached {
                    child.arg("--with-client");
                }
                let out = child.output().expect("running a round");
                let text = String::from_utf8_lossy(&out.stdout);
                match serde_json::from_str(text.lines().last().unwrap_or("")) {
                    Ok(r) if out.status.success() => break r,
                    _ if attempt < 2 => {
                        attempt += 1;
                        println!("round {k} (client: {attached}) failed ({}); running it again", out.status);
                    }
                    _ => panic!("round {k} (client: {attached}) failed three times: {}", out.status),
                }
            };
            let (p, n): (u64, u64) = (r.published.iter().sum(), r.recorded.iter().sum());
            let (rate, per) = (n as f64 / secs, 1e3 * r.cpu_s / n.max(1) as f64);
            let got = r.client.map(|(m, b)| format!("{m} msgs, {:.1} MB", b as f64 / 1e6)).unwrap_or("-".into());
            println!(
                "{k:>5}  {:>6}  {p:>9}  {n:>8}  {rate:>10.1}  {:>8.2}  {:>5.1}  {per:>10.3}  {:>11.0}  {got}",
                if attached { "yes" } else { "no" },
                r.cdr_bytes as f64 / 1e6 / secs,
                r.cpu_s,
                r.rss_mb
            );
            if attached { &mut with } else { &mut without }.push((rate, per));
        }
    }
    let med = |v: &[(f64, f64)], f: fn(&(f64, f64)) -> f64| median(v.iter().map(f).collect());
    let (rate0, rate1) = (med(&without, |x| x.0), med(&with, |x| x.0));
    let (cpu0, cpu1) = (med(&without, |x| x.1), med(&with, |x| x.1));
    println!(
        "medians of {} rounds each: recorded/s {rate0:.1} without, {rate1:.1} with a Foxglove client (ratio {:.3}); \
         recorder CPU per message {cpu0:.3} ms without, {cpu1:.3} ms with (ratio {:.2})",
        args.foxglove_rounds,
        rate1 / rate0,
        cpu1 / cpu0
    );
}
