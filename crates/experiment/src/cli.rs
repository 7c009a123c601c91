//! The `equiarm experiment` subcommands (clap derive): `run`, `status`, `report`, `claims`, and the internal
//! `run-one` each run's child process executes.

use std::path::{Path, PathBuf};

use equiarm_train::grid::RunnerOptions;
use equiarm_train::rundir::RunDirLock;

use crate::error::Result;
use crate::grid::Grid;
use crate::runner::{ExperimentGrid, STOPPED_EXIT};

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
        /// Runs at a time, 1..=64 (default: one per core).
        #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=64))]
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
    /// Check the paper's claims (a TOML file of claims, each naming two cells of a grid) on the
    /// archived runs of the reports, and write the table between its markers in a page.
    #[command(
        after_help = "Example:\n  equiarm experiment claims   # docs/results/claims.toml into docs/results/README.md"
    )]
    Claims {
        /// The claims (default: ARCHIVE/claims.toml).
        #[arg(long)]
        file: Option<PathBuf>,
        /// Where the reports are (each GRID/runs.json).
        #[arg(long, default_value = "docs/results")]
        archive: PathBuf,
        /// The page the table goes into, between its claims table markers (default: ARCHIVE/README.md).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Evaluate a run's final weights on held-out episodes, as the grids do at the end of each run
    /// (the same episodes for every run of a task): a run of `equiarm train`, in-process or over
    /// DDS (the trainer node's run directory). Prints the result and writes RUN/heldout.json.
    #[command(after_help = "Example:\n  equiarm experiment heldout runs/block_pulling-2026-12-08 --episodes 100")]
    Heldout {
        /// The run directory (its config.json and checkpoints/).
        dir: PathBuf,
        /// Held-out episodes.
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..=100_000))]
        episodes: u64,
        /// The checkpoint (default: the run's latest).
        #[arg(long)]
        checkpoint: Option<PathBuf>,
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

    /// The grid's runs named by `only` (all when empty), with its runs directory and archive.
    fn experiment_grid(&self, only: &[String]) -> Result<ExperimentGrid> {
        let grid = self.grid()?;
        Ok(ExperimentGrid {
            runs: self.runs(&grid),
            grid: grid.only(only)?,
            archive: crate::report::read_archives(&self.archive)?,
            archive_dir: self.archive.clone(),
            exe: std::env::current_exe().map_err(equiarm_types::files::at("equiarm (this program's executable)"))?,
            threads: 1,
            report: None,
        })
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
            let mut grid = at.experiment_grid(&only)?;
            grid.threads = threads as usize;
            if report {
                let out = out.unwrap_or_else(|| default_out(&at.name));
                grid.report = Some((at.grid()?, out.clone(), at.report_command(&out)));
            }
            // One runner per grid; grids may share a runs directory (and the runs they have in
            // common: a run's directory is named by its cell, and its config must agree).
            let run_err = |message: String| crate::ExperimentError::Run { dir: grid.runs.clone(), message };
            let _claim = match RunDirLock::try_acquire(&grid.runs.join(".grids").join(&at.name)) {
                Ok(Some(claim)) => claim,
                Ok(None) => return Err(run_err(format!("another runner works on grid {} here", at.name))),
                // (the runs directory cannot be made or written: say that, not that it is busy)
                Err(e) => {
                    return Err(run_err(format!("cannot claim grid {} in the runs directory: {e}", at.name)));
                }
            };
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            let opts = RunnerOptions {
                parallel: parallel.unwrap_or((cores / threads as usize).max(1)),
                // a killed runner's children write their checkpoint before they end
                wait_for_locked: std::time::Duration::from_secs(600),
            };
            let plan = grid.plan()?;
            let title = equiarm_train::grid::Grid::title(&grid);
            let summary = equiarm_train::grid::run(&mut grid, plan, &opts, stop)?;
            for line in summary.lines(&title) {
                println!("{line}");
            }
            Ok(summary.exit_code())
        }
        ExperimentCommand::Status { at, only } => {
            let grid = at.experiment_grid(&only)?;
            print!("{}", equiarm_train::grid::status(&grid.plan()?, &at.archive));
            Ok(0)
        }
        ExperimentCommand::Report { at, out } => {
            let grid = at.grid()?;
            let out = out.unwrap_or_else(|| default_out(&at.name));
            let archive = crate::report::read_archives(&at.archive)?;
            for f in crate::report::write(&grid, &at.runs(&grid), &archive, &out, &at.report_command(&out))? {
                println!("{}", f.display());
            }
            // the claims table reads the archive just written: keep it in step
            let (claims, page) = (at.archive.join("claims.toml"), at.archive.join("README.md"));
            if claims.is_file() && page.is_file() {
                println!("{}", crate::claims::write(&claims, &at.archive, &page)?.display());
            }
            Ok(0)
        }
        ExperimentCommand::Claims { file, archive, out } => {
            let file = file.unwrap_or_else(|| archive.join("claims.toml"));
            let out = out.unwrap_or_else(|| archive.join("README.md"));
            println!("{}", crate::claims::write(&file, &archive, &out)?.display());
            Ok(0)
        }
        ExperimentCommand::Heldout { dir, episodes, checkpoint } => {
            let cfg = crate::runner::run_config(&dir)?;
            let checkpoint = match checkpoint {
                Some(c) => c,
                None => equiarm_train::rundir::find_checkpoint(&dir)?,
            };
            let r = crate::runner::heldout(&cfg, &checkpoint, episodes as usize)?;
            equiarm_sac::learner::write_json(&dir.join("heldout.json"), &r)?;
            println!(
                "{}: held-out success {:.2} (discounted return {:.3}) over {} episodes, checkpoint {}",
                dir.display(),
                r.success_rate,
                r.discounted_return,
                r.episodes,
                checkpoint.display()
            );
            Ok(0)
        }
        ExperimentCommand::RunOne { dir, heldout_episodes, checkpoint_minutes } => {
            // Stop with a checkpoint on Ctrl-C / SIGTERM, and when the runner that started us is gone.
            let parent = std::os::unix::process::parent_id();
            let stop_or_orphan = || stop() || std::os::unix::process::parent_id() != parent;
            match crate::runner::run_one(&dir, heldout_episodes, checkpoint_minutes * 60.0, &stop_or_orphan)? {
                Some(r) => {
                    println!("{}: {}", dir.display(), crate::runner::result_line(&r));
                    Ok(0)
                }
                None => Ok(STOPPED_EXIT),
            }
        }
    }
}
