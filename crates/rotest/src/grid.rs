//! The experiment's grid (`equiarm rotest grid` and `status`): every setting × training size ×
//! seed × variant, which of those runs are finished (here, or in a committed report's archive) and
//! which are still to train, and training the rest.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_sim::rotest::{Corruptions, PAPER_SETTINGS, PairConfig};
use equiarm_train::STOPPED_EXIT;

use crate::cli::{ClassifierVariant, TrainOpts};
use crate::dataset::Dataset;
use crate::error::{Result, RotestError};
use crate::generate::{generate, setting_file_stem};
use crate::train::{Checkpointing, Outcome, RotestConfig};

/// What names a grid: where its datasets, runs and report are, and which runs it holds.
#[derive(Clone, Debug, clap::Args)]
pub struct GridArgs {
    /// Directory of the datasets (one subdirectory per setting, commas written as +).
    #[arg(long)]
    pub data: PathBuf,
    /// Directory of the runs.
    #[arg(long)]
    pub runs: PathBuf,
    /// Settings, separated by `;` (each a comma-separated list of flags), or `all` for the 15.
    #[arg(long, default_value = "all")]
    pub settings: String,
    /// Training-set sizes N.
    #[arg(long, value_delimiter = ',', default_value = "100,400,1600")]
    pub sizes: Vec<usize>,
    /// Seeds.
    #[arg(long, value_delimiter = ',', default_value = "0,1,2,3")]
    pub seeds: Vec<u64>,
    /// The networks to train (e.g. `cnn` alone for a size only the CNN is run at).
    #[arg(long, value_delimiter = ',', default_value = "equi,cnn,cnn+trans")]
    pub variants: Vec<ClassifierVariant>,
    /// Pairs per generated dataset.
    #[arg(long, default_value_t = 2000)]
    pub pairs: usize,
    /// The schedule, the network size and the device.
    #[command(flatten)]
    pub opts: TrainOpts,
    /// Where the report goes.
    #[arg(long, default_value = "docs/results")]
    pub report: PathBuf,
}

/// Where one run of the grid stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunState {
    /// Its `run.json` is in the runs directory.
    Finished,
    /// The report's archive holds it, with the same configuration.
    Archived,
    /// Its directory exists without a `run.json`: stopped or cut short (it continues from its
    /// checkpoint, if it wrote one), or in training now.
    Unfinished,
    /// Not started.
    New,
}

impl RunState {
    /// Whether the grid still has to train it.
    pub fn to_train(self) -> bool {
        matches!(self, RunState::Unfinished | RunState::New)
    }
}

/// One run of the grid.
#[derive(Clone, Debug)]
pub struct PlannedRun {
    /// Its setting.
    pub setting: Corruptions,
    /// `RUNS/<setting>/<variant>/<N>/s<seed>`.
    pub dir: PathBuf,
    /// What it trains.
    pub cfg: RotestConfig,
    /// Where it stands.
    pub state: RunState,
}

impl GridArgs {
    /// The settings named, checked, each once (in the order first named).
    pub fn settings(&self) -> Result<Vec<Corruptions>> {
        let named: Vec<&str> =
            if self.settings.trim() == "all" { PAPER_SETTINGS.to_vec() } else { self.settings.split(';').collect() };
        let mut list: Vec<Corruptions> = Vec::new();
        for s in named {
            let c = Corruptions::parse(s)?;
            if !list.contains(&c) {
                list.push(c);
            }
        }
        Ok(list)
    }

    /// Every run of the grid, setting by setting, then by size, seed and variant, with its state
    /// (every option checked first).
    pub fn plan(&self) -> Result<Vec<PlannedRun>> {
        let settings = self.settings()?;
        if self.sizes.is_empty() || self.seeds.is_empty() || self.variants.is_empty() {
            return Err(RotestError::Config {
                field: "--sizes/--seeds/--variants",
                message: "need at least one of each".into(),
            });
        }
        for &n in &self.sizes {
            let cfg = self.opts.config(crate::train::ClassifierKind::Cnn, n, n, 0)?;
            crate::train::split(self.pairs, &cfg)?;
        }
        // The runs a committed report holds (read once: the grid writes the report only at the end).
        let archived: BTreeMap<_, _> = crate::report::read_archive(&self.report.join(crate::report::ARCHIVE_FILE))?
            .into_iter()
            .map(|r| (crate::report::run_key(&r), r.config))
            .collect();
        let mut plan = Vec::new();
        for c in settings {
            let stem = setting_file_stem(&c);
            for &n in &self.sizes {
                for &seed in &self.seeds {
                    for &variant in &self.variants {
                        let (model, img_trans) = variant.model(n);
                        let dir =
                            self.runs.join(&stem).join(variant.name()).join(n.to_string()).join(format!("s{seed}"));
                        let cfg = self.opts.config(model, n, img_trans, seed)?;
                        let key = crate::report::key(&c.name(), &cfg);
                        let state = if dir.join("run.json").is_file() {
                            RunState::Finished
                        } else if archived.get(&key) == Some(&cfg) {
                            RunState::Archived
                        } else if dir.exists() {
                            RunState::Unfinished
                        } else {
                            RunState::New
                        };
                        plan.push(PlannedRun { setting: c.clone(), dir, cfg, state });
                    }
                }
            }
        }
        Ok(plan)
    }

    /// The dataset directory of `setting`.
    pub fn data_dir(&self, setting: &Corruptions) -> PathBuf {
        self.data.join(setting_file_stem(setting))
    }
}

/// `rotest status`: a line per setting (runs finished here, archived, unfinished, not started),
/// one for the whole grid, then every run still to train with its directory.
pub fn status(args: &GridArgs) -> Result<String> {
    let plan = args.plan()?;
    let count = |runs: &[&PlannedRun], state: RunState| runs.iter().filter(|r| r.state == state).count();
    let line = |runs: &[&PlannedRun]| {
        format!(
            "{} finished here, {} archived in {}, {} unfinished (cut short, or in training now), {} not started",
            count(runs, RunState::Finished),
            count(runs, RunState::Archived),
            args.report.display(),
            count(runs, RunState::Unfinished),
            count(runs, RunState::New)
        )
    };
    let mut s = String::new();
    for group in plan.chunk_by(|a, b| a.setting == b.setting) {
        let runs: Vec<&PlannedRun> = group.iter().collect();
        s += &format!("{}: {}\n", group[0].setting.name(), line(&runs));
    }
    let all: Vec<&PlannedRun> = plan.iter().collect();
    s += &format!("all {} runs: {}\n", plan.len(), line(&all));
    for r in plan.iter().filter(|r| r.state.to_train()) {
        let what = match (r.state, crate::resume::find(&r.dir)) {
            (RunState::New, _) => "not started".to_string(),
            _ if equiarm_train::rundir::RunDirLock::is_held(&r.dir) => "in training now".to_string(),
            (_, Some(dir)) => match crate::resume::read_state(&dir) {
                Ok(state) => format!("unfinished, checkpoint after epoch {}", state.epoch),
                Err(e) => format!("unfinished, unreadable checkpoint ({e})"),
            },
            (_, None) => "unfinished, no checkpoint".to_string(),
        };
        s += &format!("{what}: {}\n", r.dir.display());
    }
    Ok(s)
}

/// `rotest grid`: for each setting, its dataset (generated if `DATA/<setting>` has none), then every
/// run still to train (an unfinished one from its checkpoint; one another process is training is
/// skipped); then the report. Before each dataset and run, and after each epoch, it asks `stop()`:
/// when true it returns [`STOPPED_EXIT`] (finished runs kept, the run in training checkpointed, no
/// report); else 0. Results are printed to stdout.
pub fn run(args: &GridArgs, stop: &dyn Fn() -> bool) -> Result<i32> {
    let plan = args.plan()?;
    let device = equiarm_nn::device::open(&args.opts.device)?;
    let ckpt = Checkpointing { every: args.opts.checkpoint_every()?, stop };
    let mut trained = 0usize;
    let stopped = |next: &Path, trained: usize| {
        println!(
            "stopped before {}: {trained} runs trained by this command, the rest not started and the report not \
             written; the same command continues",
            next.display()
        );
        STOPPED_EXIT
    };
    for group in plan.chunk_by(|a, b| a.setting == b.setting) {
        let setting = &group[0].setting;
        let dir = args.data_dir(setting);
        if stop() {
            return Ok(stopped(&dir, trained));
        }
        if !dir.join(crate::dataset::FILE_NAME).is_file() {
            let ds = generate(&PairConfig { size: 152, supersample: 2, corruptions: setting.clone() }, args.pairs, 0)?;
            println!("{}", ds.write(&dir)?.display());
        }
        let left: Vec<&PlannedRun> = group.iter().filter(|r| r.state.to_train()).collect();
        // the dataset is read only for a setting with runs left (it is generated regardless: the
        // report's bound line comes from it)
        let ds = if left.is_empty() { continue } else { Dataset::read(&dir, None)? };
        for r in left {
            if stop() {
                return Ok(stopped(&r.dir, trained));
            }
            // finished meanwhile by another grid on the same runs directory
            if r.dir.join("run.json").is_file() {
                continue;
            }
            // (an unreadable checkpoint is reported by run_with, naming its file)
            if let Some(Ok(state)) = crate::resume::find(&r.dir).map(|d| crate::resume::read_state(&d)) {
                println!("{}: continuing from its checkpoint after epoch {}", r.dir.display(), state.epoch);
            }
            match crate::train::run_with(&ds, &r.cfg, &device, &r.dir, Some(&ckpt), &mut |_| {}) {
                Ok(Outcome::Finished(rec)) => {
                    trained += 1;
                    println!("{}", crate::cli::summary(&rec));
                }
                Ok(Outcome::Stopped { epoch }) => {
                    println!(
                        "stopped in {} after epoch {epoch}, its checkpoint written: {trained} runs trained by this \
                         command, the report not written; the same command continues",
                        r.dir.display()
                    );
                    return Ok(STOPPED_EXIT);
                }
                // in training by another grid on the same runs directory
                Err(RotestError::Busy { path }) => {
                    println!("{}: in training by another process, skipped", path.display())
                }
                Err(e) => return Err(e),
            }
        }
    }
    for f in crate::report::write(&args.runs, &args.report, &crate::cli::bounds_of(&args.data)?)? {
        println!("{}", f.display());
    }
    Ok(0)
}
