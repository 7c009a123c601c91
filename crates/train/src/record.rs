//! What a run writes into its directory as it goes, the same for the in-process loop and the trainer
//! node: the config, CleanRL-named metrics ([`crate::metrics`]), the evaluations with the learning
//! curve, and checkpoints in the layout of [`crate::rundir`].

use std::path::{Path, PathBuf};

use equiarm_sac::agent::Metrics;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, write_json};
use serde::Serialize;

use crate::TrainError;
use crate::evaluation::EvalResult;
use crate::metrics::MetricsWriter;
use crate::rundir::{RunDirLock, step_dir_name, write_latest};

/// What a finished (or stopped) run reports.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Run directory.
    pub run_dir: PathBuf,
    /// Every evaluation.
    pub evals: Vec<EvalResult>,
    /// Training env steps.
    pub global_step: u64,
    /// Updates made.
    pub updates: u64,
    /// Wall time of this process's part of the run, seconds.
    pub wall_s: f64,
    /// The last checkpoint written.
    pub last_checkpoint: Option<PathBuf>,
    /// Demo episodes tried / kept.
    pub demos: (usize, usize),
}

/// The evaluation table of a run (one row per evaluation) and where its outputs are.
impl std::fmt::Display for RunSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "\n  updates   episodes   success rate   discounted return   mean length")?;
        for e in &self.evals {
            writeln!(
                f,
                "  {:>7}   {:>8}   {:>12.2}   {:>17.3}   {:>11.1}",
                e.updates, e.episodes, e.success_rate, e.discounted_return, e.mean_length
            )?;
        }
        writeln!(f, "\nrun directory   {}", self.run_dir.display())?;
        writeln!(f, "metrics         {}", self.run_dir.join(crate::metrics::CSV_FILE).display())?;
        writeln!(f, "learning curve  {}", self.run_dir.join("learning_curve.png").display())?;
        if let Some(c) = &self.last_checkpoint {
            writeln!(f, "checkpoint      {}", c.display())?;
        }
        write!(f, "updates {}, env steps {}, wall {:.0} s", self.updates, self.global_step, self.wall_s)
    }
}

/// A run's directory while the run lives: claimed ([`RunDirLock`]) and written to.
#[derive(Debug)]
pub struct RunRecord {
    dir: PathBuf,
    cfg: TrainConfig,
    metrics: MetricsWriter,
    evals: Vec<EvalResult>,
    last_checkpoint: Option<PathBuf>,
    _claim: RunDirLock,
}

impl RunRecord {
    /// Claim `run_dir` and start a new run there (refused where a run is already, unless `force`
    /// moves it aside: [`RunDirLock::acquire_new`]), or continue the run of the checkpoint `resume`
    /// = (checkpoint directory, env steps and evaluations at that checkpoint): metrics logged after
    /// it are dropped.
    pub fn open(
        cfg: &TrainConfig,
        run_dir: &Path,
        resume: Option<(&Path, u64, Vec<EvalResult>)>,
        force: bool,
    ) -> Result<Self, TrainError> {
        let claim = RunDirLock::acquire_for(run_dir, resume.as_ref().map(|r| r.0), force)?;
        write_json(&run_dir.join("config.json"), cfg)?;
        let (metrics, evals) = match resume {
            Some((_, step, evals)) => (MetricsWriter::resume(run_dir, step), evals),
            None => (MetricsWriter::create(run_dir), Vec::new()),
        };
        Ok(RunRecord {
            dir: run_dir.to_path_buf(),
            cfg: cfg.clone(),
            metrics: metrics?,
            evals,
            last_checkpoint: None,
            _claim: claim,
        })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The evaluations so far.
    pub fn evals(&self) -> &[EvalResult] {
        &self.evals
    }

    /// The last checkpoint written by this process.
    pub fn last_checkpoint(&self) -> Option<&Path> {
        self.last_checkpoint.as_deref()
    }

    fn log(&mut self, step: u64, wall_s: f64, named: &[(&str, f64)]) -> Result<(), TrainError> {
        Ok(self.metrics.log(step, wall_s, named)?)
    }

    /// A training episode ended at env step `step`: its return, discounted return, length and success.
    pub fn episode(
        &mut self,
        step: u64,
        wall_s: f64,
        ret: f64,
        discounted: f64,
        length: u32,
        success: bool,
    ) -> Result<(), TrainError> {
        let named = [
            ("charts/episodic_return", ret),
            ("charts/discounted_return", discounted),
            ("charts/episodic_length", length as f64),
            ("charts/success", success as u8 as f64),
        ];
        self.log(step, wall_s, &named)
    }

    /// Update `updates` was made with metrics `m` at `sps` env steps per second (logged for the
    /// first update and every tenth).
    pub fn update(&mut self, step: u64, wall_s: f64, updates: u64, m: &Metrics, sps: f64) -> Result<(), TrainError> {
        if updates.is_multiple_of(10) || updates == 1 {
            let mut named = m.named();
            named.push(("charts/SPS", sps));
            named.push(("charts/updates", updates as f64));
            self.log(step, wall_s, &named)?;
        }
        Ok(())
    }

    /// An evaluation: logged, kept, and the learning curve redrawn.
    pub fn evaluation(&mut self, step: u64, wall_s: f64, e: EvalResult) -> Result<(), TrainError> {
        self.log(step, wall_s, &e.named())?;
        self.evals.push(e);
        self.write_curve()
    }

    /// Write a checkpoint of `learner` with the transport's state beside it (`state_file`, JSON) and
    /// point `checkpoints/latest` at it once it is complete.
    pub fn checkpoint<S: Serialize>(
        &mut self,
        learner: &Learner,
        state_file: &str,
        state: &S,
    ) -> Result<PathBuf, TrainError> {
        let dir = self.dir.join("checkpoints").join(step_dir_name(learner.updates()));
        learner.save(&dir)?;
        write_json(&dir.join(state_file), state)?;
        write_latest(&self.dir, learner.updates())?;
        log::info!("checkpoint {}", dir.display());
        self.last_checkpoint = Some(dir.clone());
        Ok(dir)
    }

    /// The end of the run (or of this process's part of it): a checkpoint at the current update
    /// count unless there is one already, `evals.json` and the learning curve.
    pub fn finish<S: Serialize>(&mut self, learner: &Learner, state_file: &str, state: &S) -> Result<(), TrainError> {
        if self.last_checkpoint.as_ref().is_none_or(|p| !p.ends_with(step_dir_name(learner.updates()))) {
            self.checkpoint(learner, state_file, state)?;
        }
        write_json(&self.dir.join("evals.json"), &self.evals)?;
        // The curve is redrawn at every evaluation; draw it at the end too (a run may end before one).
        self.write_curve()
    }

    /// Write `learning_curve.png`: evaluation success rate and discounted return against updates.
    fn write_curve(&self) -> Result<(), TrainError> {
        use crate::plot::{Chart, Series, palette, write_png};
        let series = vec![
            Series {
                label: "success rate".into(),
                color: palette(0),
                points: self.evals.iter().map(|e| (e.updates as f64, e.success_rate)).collect(),
                band: None,
                bars: false,
            },
            Series {
                label: "discounted return".into(),
                color: palette(1),
                points: self.evals.iter().map(|e| (e.updates as f64, e.discounted_return)).collect(),
                band: None,
                bars: false,
            },
        ];
        let cfg = &self.cfg;
        let chart = Chart {
            title: format!("{} SAC, {} ({} eval episodes)", cfg.agent.model.name(), cfg.task, cfg.eval_episodes),
            x_label: "gradient updates".into(),
            y_label: "greedy evaluation".into(),
            y_range: Some((0.0, 1.0)),
            ..Chart::default()
        };
        Ok(write_png(&self.dir.join("learning_curve.png"), &chart, &series)?)
    }
}
