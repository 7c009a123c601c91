//! `equiarm_fuzz TARGET --execs N [--seed S] [--jobs J]`: fuzz one target (or `all`, J targets at a
//! time), print executions, time and crashes per target; exit 1 if any input failed. `list` names
//! the targets.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use equiarm_fuzz::runner::{self, Options};
use equiarm_fuzz::targets::{self, Target};

/// Fuzz equiarm's external inputs with mutated valid seeds; each target runs in a worker process
/// so aborts and hangs are caught too.
#[derive(Parser, Debug)]
#[command(name = "equiarm_fuzz")]
struct Args {
    /// A target name, `all`, or `list`.
    target: String,
    /// Inputs per target.
    #[arg(long, default_value_t = 10_000)]
    execs: u64,
    /// Seed of the mutations (the same seed gives the same inputs).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Seconds one input may run before it counts as a hang.
    #[arg(long, default_value_t = 5.0)]
    time_limit_s: f64,
    /// Address-space limit of a worker process, MiB (an allocation beyond it is reported as an
    /// abort). Above 4 GiB: the mcap crate reserves a string's u32 length before checking the
    /// record holds it (docs/fuzzing.md, "Limitations").
    #[arg(long, default_value_t = 8192)]
    memory_mb: u64,
    /// Targets fuzzed at a time, each in its own worker process (default: the number of cores).
    /// The inputs do not depend on it; the table keeps the targets' order.
    #[arg(long)]
    jobs: Option<usize>,
    /// Where failing inputs are written (default: the `crashes` folder of this crate).
    #[arg(long)]
    crash_dir: Option<PathBuf>,
    /// Run this one saved input in this process instead of fuzzing (to reproduce a crash).
    #[arg(long)]
    input: Option<PathBuf>,
    /// Run as a worker (started by the parent).
    #[arg(long, hide = true)]
    worker: bool,
    /// Worker: first input index.
    #[arg(long, hide = true, default_value_t = 0)]
    from: u64,
    /// Worker: the progress file shared with the parent.
    #[arg(long, hide = true)]
    progress: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let all = targets::all();
    let find = |name: &str| all.iter().chain(targets::selftest().iter()).find(|t| t.name == name).cloned();
    if args.target == "list" {
        for t in &all {
            println!("{:<24} {}", t.name, t.about);
        }
        return ExitCode::SUCCESS;
    }
    let chosen: Vec<Target> = if args.target == "all" {
        all.clone()
    } else if let Some(t) = find(&args.target) {
        vec![t]
    } else {
        eprintln!("unknown target `{}` (`equiarm_fuzz list` names them)", args.target);
        return ExitCode::from(2);
    };
    if args.worker {
        let Some(progress) = &args.progress else {
            eprintln!("--worker needs --progress");
            return ExitCode::from(2);
        };
        return match runner::worker(&chosen[0], args.seed, args.from, args.execs, args.memory_mb, progress) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("{e}");
                ExitCode::from(2)
            }
        };
    }
    if let Some(input) = &args.input {
        return match runner::run_file(&chosen[0], input) {
            Ok(accepted) => {
                println!("{}: {} {}", chosen[0].name, input.display(), if accepted { "accepted" } else { "refused" });
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("{e}");
                ExitCode::from(2)
            }
        };
    }
    if !(args.time_limit_s > 0.0 && args.time_limit_s <= 3600.0) {
        eprintln!("--time-limit-s {} is outside (0, 3600]", args.time_limit_s);
        return ExitCode::from(2);
    }
    let opts = Options {
        execs: args.execs,
        seed: args.seed,
        time_limit: Duration::from_secs_f64(args.time_limit_s),
        memory_mb: args.memory_mb,
        crash_dir: args.crash_dir.clone().unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("crashes")),
    };
    let exe = match std::env::current_exe() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("cannot find this program to start workers: {e}");
            return ExitCode::from(2);
        }
    };
    let jobs = match args.jobs {
        Some(0) => {
            eprintln!("--jobs 0: give at least 1");
            return ExitCode::from(2);
        }
        Some(j) => j,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    }
    .min(chosen.len());
    println!("{:<24} {:>10} {:>10} {:>9} {:>10} {:>7}", "target", "execs", "accepted", "time_s", "execs/s", "crashes");
    let mut failed = 0;
    let mut broken = 0;
    // `jobs` threads take the targets in order; each row is printed once the rows before it are.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (send, recv) = std::sync::mpsc::channel();
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            let send = send.clone();
            let (next, chosen, opts, exe) = (&next, &chosen, &opts, &exe);
            scope.spawn(move || {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(t) = chosen.get(i) else { break };
                    if send.send((i, runner::run_target(t, opts, exe))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(send);
        let mut done: Vec<Option<Result<runner::Outcome, runner::RunError>>> = chosen.iter().map(|_| None).collect();
        let mut printed = 0;
        for (i, result) in recv {
            done[i] = Some(result);
            while let Some(result) = done.get_mut(printed).and_then(Option::take) {
                match result {
                    Ok(o) => {
                        println!(
                            "{:<24} {:>10} {:>10} {:>9.1} {:>10.0} {:>7}",
                            o.target,
                            o.execs,
                            o.accepted,
                            o.secs,
                            o.execs as f64 / o.secs.max(1e-9),
                            o.failures.len()
                        );
                        failed += o.failures.len();
                    }
                    Err(e) => {
                        println!("ERROR {e}");
                        broken += 1;
                    }
                }
                printed += 1;
            }
        }
    });
    if failed > 0 || broken > 0 {
        println!("{failed} failing inputs, {broken} targets that could not run");
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
