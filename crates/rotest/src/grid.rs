//! The experiment's grid (`equiarm rotest grid` and `status`): every setting × training size ×
//! seed × variant, which of those runs are finished (here, or in a committed report's archive) and
//! which are still to train, and training the rest with the one grid runner
//! ([`equiarm_train::grid`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use equiarm_nn::burn::tensor::Device;
use equiarm_sim::rotest::{Corruptions, PAPER_SETTINGS, PairConfig};
use equiarm_train::STOPPED_EXIT;
use equiarm_train::grid::{Grid as GridSpec, Job, JobEnd, Planned, RunState, RunnerOptions, ThreadJob};

use crate::cli::{ClassifierVariant, TrainOpts};
use crate::dataset::Dataset;
use crate::error::{Result, RotestError};
use crate::generate::{generate, setting_file_stem};
use crate::train::{Checkpointing, Outcome, RotestConfig, RotestRecord};

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
    /// Runs at a time (each on a thread of this process).
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=64))]
    pub parallel: usize,
}

/// One run of the grid: its setting and what it trains.
pub type PlannedRun = Planned<(Corruptions, RotestConfig)>;

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
            .map(|r| (crate::report::run_key(&r), r))
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
                        let archived = archived.get(&crate::report::key(&c.name(), &cfg)).filter(|r| r.config == cfg);
                        let mut p = Planned { dir, group: c.name(), state: RunState::New, run: (c.clone(), cfg) };
                        p.state = state_of(&p, archived)?;
                        plan.push(p);
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

/// Where a run stands: its `run.json`, else the report's archive (`archived`, with the same
/// configuration), else its directory (and checkpoint), else new.
fn state_of(p: &PlannedRun, archived: Option<&RotestRecord>) -> Result<RunState> {
    let record = p.dir.join("run.json");
    if record.is_file() {
        return Ok(RunState::Finished(crate::cli::summary(&crate::report::read_record(&record)?)));
    }
    if let Some(r) = archived {
        return Ok(RunState::Archived(crate::cli::summary(r)));
    }
    if !p.dir.exists() {
        return Ok(RunState::New);
    }
    Ok(RunState::Unfinished(match crate::resume::find(&p.dir) {
        _ if equiarm_train::rundir::RunDirLock::is_held(&p.dir) => "in training now".to_string(),
        Some(dir) => match crate::resume::read_state(&dir) {
            Ok(state) => format!("unfinished, checkpoint after epoch {}", state.epoch),
            Err(e) => format!("unfinished, unreadable checkpoint ({e})"),
        },
        None => "unfinished, no checkpoint".to_string(),
    }))
}

/// `rotest status`: where every run stands (finished here, archived in the report, unfinished,
/// not started), then the counts of each setting and of the grid.
pub fn status(args: &GridArgs) -> Result<String> {
    Ok(equiarm_train::grid::status(&args.plan()?, &args.report))
}

/// The grid as the one grid runner drives it ([`equiarm_train::grid`]): each run trains on a thread
/// of this process, from its checkpoint if it has one.
struct RotestGrid<'a> {
    args: &'a GridArgs,
    device: Device,
    every: Duration,
    /// The dataset of the setting whose runs start now (the plan goes setting by setting).
    dataset: Option<(Corruptions, Arc<Dataset>)>,
}

impl GridSpec for RotestGrid<'_> {
    type Run = (Corruptions, RotestConfig);
    type Error = RotestError;

    fn title(&self) -> String {
        "rotest grid".into()
    }

    fn archive(&self) -> &Path {
        &self.args.report
    }

    fn state(&self, p: &PlannedRun) -> Result<RunState> {
        // a run archived when planned stays so (the grid trains only the others)
        match &p.state {
            RunState::Archived(_) if !p.dir.join("run.json").is_file() => Ok(p.state.clone()),
            _ => state_of(p, None),
        }
    }

    fn start(&mut self, p: &PlannedRun, _: &RunState) -> Result<Box<dyn Job>> {
        let (setting, cfg) = p.run.clone();
        let ds = match &self.dataset {
            Some((s, ds)) if *s == setting => Arc::clone(ds),
            _ => {
                let ds = Arc::new(Dataset::read(&self.args.data_dir(&setting), None)?);
                self.dataset = Some((setting, Arc::clone(&ds)));
                ds
            }
        };
        let (device, every, dir) = (self.device.clone(), self.every, p.dir.clone());
        Ok(Box::new(ThreadJob::spawn(move |stop| {
            let ckpt = Checkpointing { every, stop };
            match crate::train::run_with(&ds, &cfg, &device, &dir, Some(&ckpt), &mut |_| {}) {
                Ok(Outcome::Finished(_)) => JobEnd::Done,
                Ok(Outcome::Stopped { .. }) => JobEnd::Stopped,
                Err(e) => JobEnd::Failed(e.to_string()),
            }
        })))
    }

    fn report(&mut self) -> Result<Vec<PathBuf>> {
        crate::report::write(&self.args.runs, &self.args.report, &crate::cli::bounds_of(&self.args.data)?)
    }
}

/// `rotest grid`: each setting's dataset (generated if `DATA/<setting>` has none; the report's
/// bound line comes from it), then every run still to train, `--parallel` at a time (an unfinished
/// one from its checkpoint; one another process is training is left to it), then the report. Before
/// each dataset, and by the runner while runs train, it asks `stop()`: when true it returns
/// [`STOPPED_EXIT`] (finished runs kept, the runs in training checkpointed at the end of their
/// epoch, no report); else 0, or 1 when a run failed.
pub fn run(args: &GridArgs, stop: &dyn Fn() -> bool) -> Result<i32> {
    let plan = args.plan()?;
    let device = equiarm_nn::device::open(&args.opts.device)?;
    let every = args.opts.checkpoint_every()?;
    let mut settings: Vec<&Corruptions> = plan.iter().map(|p| &p.run.0).collect();
    settings.dedup();
    for setting in settings {
        let dir = args.data_dir(setting);
        if stop() {
            println!("stopped before the dataset {}: no run trained; the same command continues", dir.display());
            return Ok(STOPPED_EXIT);
        }
        if !dir.join(crate::dataset::FILE_NAME).is_file() {
            let ds = generate(&PairConfig { size: 152, supersample: 2, corruptions: setting.clone() }, args.pairs, 0)?;
            println!("{}", ds.write(&dir)?.display());
        }
    }
    let mut grid = RotestGrid { args, device, every, dataset: None };
    // a run trained on a thread ends with this process: a run held is another process's
    let opts = RunnerOptions { parallel: args.parallel, wait_for_locked: Duration::ZERO };
    let summary = equiarm_train::grid::run(&mut grid, plan, &opts, stop)?;
    for line in summary.lines(&grid.title()) {
        println!("{line}");
    }
    Ok(summary.exit_code())
}
