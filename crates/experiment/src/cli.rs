//! The `equiarm experiment` subcommands (clap derive): `run`, `status`, `report`, and the internal
//! `run-one` each run's child process executes.

use std::path::{Path, PathBuf};

use crate::error::Result;
use crate::grid::Grid;
use crate::runner::{RunState, RunnerOptions, STOPPED_EXIT, run_state};

/// `equiarm experiment …`.
#[derive(Debug, clap::Subcommand)]
pub enum ExperimentCommand {
    /// Run every unfinished run of a grid (`experiments/NAME.toml`): finished runs are skipped,
    /// interrupted ones resume from their latest checkpoint. Ctrl-C stops the runs with a
    /// checkpoint; run the same command again to continue.
    #[command(
        after_help = "Examples:\n  equiarm experiment run tasks --parallel 2\n  equiarm experiment run my_grid --file my_grid.toml --runs /data/runs"
    )]
    Run {
        /// The grid and its runs.
        #[command(flatten)]
        at: Where,
        /// Runs at a time (default: one per core).
        #[arg(long)]
        parallel: Option<usize>,
        /// Threads per run.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=256))]
        threads: u64,
        /// Write the report when every run is finished (to --out).
        #[arg(long)]
        report: bool,
        /// Where the report goes (default: docs/results/NAME).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Only the runs whose path matches this glob (`task/variant/view/corruption/sN`, e.g.
        /// `block_picking/cnn/*/*/*` or `*/cnn/**`); repeat for several. The report still covers the
        /// whole grid.
        #[arg(long, value_name = "GLOB")]
        only: Vec<String>,
    },
    /// Print each run's state: finished (with its held-out success), interrupted at N updates, or new.
    Status {
        /// The grid and its runs.
        #[command(flatten)]
        at: Where,
        /// Only the runs whose path matches this glob (as `run --only`); repeatable.
        #[arg(long, value_name = "GLOB")]
        only: Vec<String>,
    },
    /// Write the report (README.md with the table, and the figures) from the run directories.
    #[command(after_help = "Example:\n  equiarm experiment report tasks   # writes docs/results/tasks/")]
    Report {
        /// The grid and its runs.
        #[command(flatten)]
        at: Where,
        /// Output directory (default: docs/results/NAME).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Train one run directory (its config.json) to the end, or from its latest checkpoint, then
    /// evaluate it on held-out episodes (what `run` starts for each run).
    #[command(hide = true)]
    RunOne {
        /// The run directory.
        dir: PathBuf,
        /// Held-out evaluation episodes.
        #[arg(long, default_value_t = 100)]
        heldout_episodes: usize,
        /// Checkpoint at least this often, minutes of training.
        #[arg(long, default_value_t = 10.0)]
        checkpoint_minutes: f64,
    },
}

/// Which grid and where its runs are.
#[derive(Clone, Debug, clap::Args)]
pub struct Where {
    /// The grid's name: experiments/NAME.toml.
    pub name: String,
    /// The grid file (default: experiments/NAME.toml).
    #[arg(long)]
    pub file: Option<PathBuf>,
    /// The directory of the runs (default: the grid file's `runs`, else runs/experiments, shared by
    /// the grids: runs they have in common are made once).
    #[arg(long)]
    pub runs: Option<PathBuf>,
    /// Where the reports are: each report's runs.json archives its finished runs, which count as
    /// done here (and are drawn) when the runs directory does not have them.
    #[arg(long, default_value = "docs/results")]
    pub archive: PathBuf,
}

impl Where {
    fn grid(&self) -> Result<Grid> {
        let file = self.file.clone().unwrap_or_else(|| Path::new("experiments").join(format!("{}.toml", self.name)));
        let mut g = Grid::read(&file)?;
        g.name = self.name.clone();
        Ok(g)
    }

    fn runs(&self, grid: &Grid) -> PathBuf {
        self.runs.clone().or_else(|| grid.runs.clone()).unwrap_or_else(|| PathBuf::from("runs/experiments"))
    }

    /// The command that regenerates the report, as the report quotes it. A runs directory given
    /// as an absolute path is left out: it names one machine, and the report's archive (runs.json)
    /// holds every finished run it drew, so the command without it makes the same page on a clone.
    fn report_command(&self, out: &Path) -> String {
        let mut c = format!("equiarm experiment report {}", self.name);
        if let Some(f) = &self.file {
            c += &format!(" --file {}", f.display());
        }
        if let Some(r) = self.runs.as_ref().filter(|r| r.is_relative()) {
            c += &format!(" --runs {}", r.display());
        }
        if self.archive != Path::new("docs/results") {
            c += &format!(" --archive {}", self.archive.display());
        }
        if out != default_out(&self.name) {
            c += &format!(" --out {}", out.display());
        }
        c
    }
}

fn default_out(name: &str) -> PathBuf {
    Path::new("docs/results").join(name)
}

/// Runs one subcommand; `stop` turns true on Ctrl-C / SIGTERM. Returns the process's exit code.
pub fn run(cmd: ExperimentCommand, stop: &dyn Fn() -> bool) -> Result<i32> {
    match cmd {
        ExperimentCommand::Run { at, parallel, threads, report, out, only } => {
            let grid = at.grid()?;
            let chosen = grid.only(&only)?;
            let runs = at.runs(&grid);
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            let opts = RunnerOptions {
                exe: std::env::current_exe()
                    .map_err(|e| crate::ExperimentError::Io { path: "equiarm".into(), message: e.to_string() })?,
                parallel: parallel.unwrap_or((cores / threads as usize).max(1)).max(1),
                threads: threads as usize,
                verbose: true,
            };
            let archive = crate::report::read_archives(&at.archive)?;
            let s = crate::runner::run(&chosen, &runs, &archive, &opts, stop)?;
            println!(
                "experiment {}: {} finished before, {} finished now, {} failed, {} left unfinished",
                grid.name,
                s.already_done,
                s.finished,
                s.failed.len(),
                s.stopped
            );
            for (dir, _) in &s.failed {
                println!("failed: {} (see its {})", dir.display(), crate::runner::LOG_FILE);
            }
            if report && crate::report::all_finished(&grid, &runs, &archive)? {
                let out = out.unwrap_or_else(|| default_out(&at.name));
                for f in crate::report::write(&grid, &runs, &archive, &out, &at.report_command(&out))? {
                    println!("{}", f.display());
                }
            }
            Ok(if !s.failed.is_empty() {
                1
            } else if s.stopped > 0 {
                STOPPED_EXIT
            } else {
                0
            })
        }
        ExperimentCommand::Status { at, only } => {
            let grid = at.grid()?.only(&only)?;
            let runs = at.runs(&grid);
            let archive = crate::report::read_archives(&at.archive)?;
            let (mut done, mut partial, mut new) = (0, 0, 0);
            for cell in grid.cells() {
                let cfg = grid.config(cell)?;
                let dir = runs.join(cell.rel_dir());
                let line = match run_state(&dir, &cfg)? {
                    RunState::Done(r) => {
                        done += 1;
                        format!(
                            "finished: {} updates, held-out success {:.2}, discounted return {:.3}",
                            r.updates, r.heldout.success_rate, r.heldout.discounted_return
                        )
                    }
                    RunState::Partial(_) | RunState::New if crate::report::archived(&archive, cell, &cfg).is_some() => {
                        done += 1;
                        let r = &crate::report::archived(&archive, cell, &cfg).expect("checked").result;
                        format!(
                            "finished (archived in {}): {} updates, held-out success {:.2}, discounted return {:.3}",
                            at.archive.display(),
                            r.updates,
                            r.heldout.success_rate,
                            r.heldout.discounted_return
                        )
                    }
                    RunState::Partial(u) => {
                        partial += 1;
                        format!("interrupted at {u} of {} updates", cfg.total_updates)
                    }
                    RunState::New => {
                        new += 1;
                        "not started".into()
                    }
                };
                println!("{}  {line}", cell.rel_dir().display());
            }
            println!("{done} finished, {partial} interrupted, {new} not started ({} runs)", grid.cells().len());
            Ok(0)
        }
        ExperimentCommand::Report { at, out } => {
            let grid = at.grid()?;
            let out = out.unwrap_or_else(|| default_out(&at.name));
            let archive = crate::report::read_archives(&at.archive)?;
            for f in crate::report::write(&grid, &at.runs(&grid), &archive, &out, &at.report_command(&out))? {
                println!("{}", f.display());
            }
            Ok(0)
        }
        ExperimentCommand::RunOne { dir, heldout_episodes, checkpoint_minutes } => {
            // Stop with a checkpoint on Ctrl-C / SIGTERM, and when the runner that started us is gone.
            let parent = std::os::unix::process::parent_id();
            let stop_or_orphan = || stop() || std::os::unix::process::parent_id() != parent;
            match crate::runner::run_one(&dir, heldout_episodes, checkpoint_minutes * 60.0, &stop_or_orphan)? {
                Some(r) => {
                    println!(
                        "{}: {} updates, held-out success {:.2} (discounted return {:.3}) over {} episodes",
                        dir.display(),
                        r.updates,
                        r.heldout.success_rate,
                        r.heldout.discounted_return,
                        r.heldout.episodes
                    );
                    Ok(0)
                }
                None => Ok(STOPPED_EXIT),
            }
        }
    }
}
