//! A named grid of runs: the TOML file `experiments/NAME.toml`, its cells (task × variant × view ×
//! corruption × seed) and the training config of each cell.
//!
//! ```toml
//! description = "Equi SAC against CNN SAC on the five tasks"
//! preset = "reduced16"                  # the base config of every run (equiarm train --preset)
//! tasks = ["block_pulling", "block_in_bowl"]
//! variants = ["equi", "cnn"]            # see VARIANTS
//! views = ["side"]                      # camera presets (default: side)
//! corruptions = ["none"]                # `none` or comma-separated corruption names (default: none)
//! seeds = [0, 1]
//! heldout_episodes = 100                # the final held-out evaluation of each run
//! checkpoint_minutes = 10               # a checkpoint at least this often (besides checkpoint_every)
//! runs = "runs/my_grid"                 # its own runs directory (default: runs/experiments, shared)
//!
//! [updates]                             # total_updates per task (default: the preset's)
//! block_in_bowl = 10000
//!
//! [config]                              # any TrainConfig field, as in a --config JSON file
//! eval_every = 100
//! agent = { lr_final = 3e-4 }
//!
//! [paper]                               # the paper's figure per task/variant, for the report
//! "block_pulling/equi" = 0.87
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_sac::config::{Preset, TrainConfig};
use equiarm_types::{ArmView, Augmentation, Corruption, ModelKind, TaskKind, ViewPreset};
use serde::Deserialize;

use crate::error::{ExperimentError, Result};

/// A model variant of the paper's comparisons: a network family with an augmentation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variant {
    /// Its name in grid files, run directories and reports.
    pub name: &'static str,
    /// Its label in tables and figures (the paper's).
    pub label: &'static str,
    /// The networks.
    pub model: ModelKind,
    /// The augmentation.
    pub augmentation: Augmentation,
    /// Hidden size of the networks as a fraction of the grid's (`hidden`): 1, or ½ for the paper's SEN,
    /// whose width is half Equi SAC's so that their parameter counts match (docs/paper.md §1.7, §1.9).
    pub hidden_divisor: usize,
}

/// Every variant a grid may name (docs/paper.md §1.8–1.11).
pub const VARIANTS: [Variant; 6] = [
    Variant {
        name: "equi",
        label: "Equi SAC + RAD",
        model: ModelKind::Equi,
        augmentation: Augmentation::Rad,
        hidden_divisor: 1,
    },
    Variant {
        name: "cnn",
        label: "CNN SAC + RAD",
        model: ModelKind::Cnn,
        augmentation: Augmentation::Rad,
        hidden_divisor: 1,
    },
    Variant {
        name: "cnn_drq",
        label: "CNN SAC + DrQ",
        model: ModelKind::Cnn,
        augmentation: Augmentation::PAPER_DRQ,
        hidden_divisor: 1,
    },
    Variant {
        name: "sen",
        label: "SEN + RAD (Equi's width)",
        model: ModelKind::Sen,
        augmentation: Augmentation::Rad,
        hidden_divisor: 1,
    },
    Variant {
        name: "ferm",
        label: "FERM",
        model: ModelKind::Ferm,
        augmentation: Augmentation::FERM,
        hidden_divisor: 1,
    },
    Variant {
        name: "sen_half",
        label: "SEN + RAD",
        model: ModelKind::Sen,
        augmentation: Augmentation::Rad,
        hidden_divisor: 2,
    },
];

impl Variant {
    /// A variant by name.
    pub fn by_name(name: &str) -> Option<Variant> {
        VARIANTS.iter().copied().find(|v| v.name == name)
    }
}

/// The grid file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GridFile {
    description: String,
    #[serde(default = "default_preset")]
    preset: String,
    tasks: Vec<TaskKind>,
    variants: Vec<String>,
    #[serde(default = "default_views")]
    views: Vec<ViewPreset>,
    #[serde(default = "default_corruptions")]
    corruptions: Vec<Corruption>,
    seeds: Vec<u64>,
    #[serde(default = "default_heldout")]
    heldout_episodes: usize,
    #[serde(default = "default_checkpoint_minutes")]
    checkpoint_minutes: f64,
    #[serde(default)]
    runs: Option<PathBuf>,
    #[serde(default)]
    updates: BTreeMap<TaskKind, u64>,
    #[serde(default)]
    config: toml::Table,
    #[serde(default)]
    paper: BTreeMap<String, f64>,
}

fn default_preset() -> String {
    Preset::DEFAULT.name().into()
}
fn default_views() -> Vec<ViewPreset> {
    vec![ViewPreset::Side]
}
fn default_corruptions() -> Vec<Corruption> {
    vec![Corruption::NONE]
}
fn default_heldout() -> usize {
    100
}
fn default_checkpoint_minutes() -> f64 {
    10.0
}

/// One run of a grid.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Cell {
    /// Task.
    pub task: TaskKind,
    /// Variant name ([`VARIANTS`]).
    pub variant: String,
    /// Camera preset.
    pub view: ViewPreset,
    /// Corruption setting.
    pub corruption: Corruption,
    /// Whether the arm is in view (the grid's `[config] arm`; one value per grid).
    pub arm: ArmView,
    /// Seed.
    pub seed: u64,
}

impl Cell {
    /// The run directory below the experiment's: `TASK/VARIANT/VIEW/CORRUPTION/sSEED` (commas of
    /// the corruption written as `+`; VIEW is the view's name, with `-arm` after it when the arm is in
    /// view, so that runs of the two scenes never share a directory).
    pub fn rel_dir(&self) -> PathBuf {
        let corruption = self.corruption.to_string().replace(',', "+");
        [self.task.name(), &self.variant, &self.scene_view(), &corruption, &format!("s{}", self.seed)].iter().collect()
    }

    /// The view's name, with `-arm` when the arm is in view (the run directory's VIEW part).
    pub fn scene_view(&self) -> String {
        match self.arm {
            ArmView::Hidden => self.view.name().to_string(),
            ArmView::Visible => format!("{}-arm", self.view.name()),
        }
    }

    /// The group a report draws as one curve of one figure: everything but the seed, by name (so
    /// groups sort as their names do).
    pub fn group(&self) -> (String, String, String, String) {
        (self.task.to_string(), self.scene_view(), self.corruption.to_string(), self.variant.clone())
    }
}

/// A checked grid.
#[derive(Clone, Debug)]
pub struct Grid {
    /// The file it was read from.
    pub path: PathBuf,
    /// Its name (the file stem).
    pub name: String,
    /// What it is for (one line, shown in the report).
    pub description: String,
    /// Base preset.
    pub preset: Preset,
    /// Held-out episodes per run.
    pub heldout_episodes: usize,
    /// Checkpoint interval in minutes of training.
    pub checkpoint_minutes: f64,
    /// Its own runs directory, for a grid whose cells share names but not configs with other
    /// grids' (default: `runs/experiments`, shared by the grids).
    pub runs: Option<PathBuf>,
    /// The paper's figure per `task/variant` (discounted return), for the report.
    pub paper: BTreeMap<String, f64>,
    cells: Vec<Cell>,
    updates: BTreeMap<TaskKind, u64>,
    overrides: serde_json::Value,
}

impl Grid {
    /// Reads and checks `path`: every name is known, every cell's config passes
    /// `equiarm_train::config::check`. Errors name the file and the key.
    pub fn read(path: &Path) -> Result<Grid> {
        let text = std::fs::read_to_string(path).map_err(equiarm_types::files::at(path))?;
        Grid::parse(path, &text)
    }

    /// [`Grid::read`] of the text of `path`.
    pub fn parse(path: &Path, text: &str) -> Result<Grid> {
        let bad = |message: String| ExperimentError::Grid { path: path.to_path_buf(), message };
        let f: GridFile = toml::from_str(text).map_err(|e| bad(e.to_string().trim_end().to_string()))?;
        let preset = Preset::from_name(&f.preset).ok_or_else(|| {
            let names: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
            bad(format!("preset: unknown preset `{}`: use {}", f.preset, names.join(", ")))
        })?;
        let corruptions = &f.corruptions;
        for (key, list) in [
            ("tasks", f.tasks.len()),
            ("variants", f.variants.len()),
            ("views", f.views.len()),
            ("corruptions", f.corruptions.len()),
            ("seeds", f.seeds.len()),
        ] {
            if list == 0 {
                return Err(bad(format!("{key}: the list is empty")));
            }
        }
        for v in &f.variants {
            if Variant::by_name(v).is_none() {
                let names: Vec<&str> = VARIANTS.iter().map(|v| v.name).collect();
                return Err(bad(format!("variants: unknown variant `{v}`: use {}", names.join(", "))));
            }
        }
        for task in f.updates.keys() {
            if !f.tasks.contains(task) {
                return Err(bad(format!("updates: `{task}` is not one of this grid's tasks")));
            }
        }
        if !(1..=equiarm_sac::config::MAX_EPISODES).contains(&f.heldout_episodes) {
            return Err(bad(format!(
                "heldout_episodes: {} must be 1..={} (a success rate over no episodes means nothing)",
                f.heldout_episodes,
                equiarm_sac::config::MAX_EPISODES
            )));
        }
        if !(f.checkpoint_minutes.is_finite() && f.checkpoint_minutes > 0.0) {
            return Err(bad(format!("checkpoint_minutes: {} must be a positive number", f.checkpoint_minutes)));
        }
        let overrides = serde_json::to_value(&f.config).map_err(|e| bad(format!("config: {e}")))?;
        // the scene of every run: the preset's (the arm in view) unless `[config]` says otherwise
        let arm = match overrides.get("arm") {
            Some(v) => serde_json::from_value(v.clone()).map_err(|e| bad(format!("config: arm: {e}")))?,
            None => TrainConfig::preset(preset, TaskKind::BlockPulling).arm,
        };
        let mut cells = Vec::new();
        for &task in &f.tasks {
            for variant in &f.variants {
                for &view in &f.views {
                    for &corruption in corruptions {
                        for &seed in &f.seeds {
                            cells.push(Cell { task, variant: variant.clone(), view, corruption, arm, seed });
                        }
                    }
                }
            }
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(c) = cells.iter().find(|c| !seen.insert((*c).clone())) {
            return Err(bad(format!("the run {} appears twice (a repeated name in a list)", c.rel_dir().display())));
        }
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let grid = Grid {
            path: path.to_path_buf(),
            name,
            description: f.description,
            preset,
            heldout_episodes: f.heldout_episodes,
            checkpoint_minutes: f.checkpoint_minutes,
            runs: f.runs,
            paper: f.paper,
            cells,
            updates: f.updates,
            overrides,
        };
        for c in &grid.cells {
            grid.config(c)?;
        }
        Ok(grid)
    }

    /// Every cell, in file order (task, variant, view, corruption, seed).
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// The grid narrowed to the runs whose path (`task/variant/view/corruption/sN`, as under the
    /// runs directory) matches one of the glob `patterns` (`*` within a path part, `**` across parts),
    /// in file order; no patterns keep every run. A pattern that does not parse, or that matches no
    /// run of the grid, is an error naming it.
    pub fn only(&self, patterns: &[String]) -> Result<Grid> {
        if patterns.is_empty() {
            return Ok(self.clone());
        }
        let bad = |message: String| ExperimentError::Grid { path: self.path.clone(), message };
        let opts = glob::MatchOptions { require_literal_separator: true, ..Default::default() };
        let mut globs = Vec::new();
        for p in patterns {
            let g = glob::Pattern::new(p).map_err(|e| bad(format!("--only `{p}`: {e}")))?;
            if !self.cells.iter().any(|c| g.matches_path_with(&c.rel_dir(), opts)) {
                let example = self.cells.first().map(|c| c.rel_dir().display().to_string()).unwrap_or_default();
                return Err(bad(format!(
                    "--only `{p}` matches none of its {} runs (a run's path reads like `{example}`)",
                    self.cells.len()
                )));
            }
            globs.push(g);
        }
        let mut g = self.clone();
        g.cells.retain(|c| globs.iter().any(|p| p.matches_path_with(&c.rel_dir(), opts)));
        Ok(g)
    }

    /// The training config of `cell`: the preset for its task, the `[config]` overrides, then the
    /// cell's variant, view, corruption, seed and the task's `[updates]`; checked.
    pub fn config(&self, cell: &Cell) -> Result<TrainConfig> {
        let bad = |message: String| ExperimentError::Grid { path: self.path.clone(), message };
        let base = TrainConfig::preset(self.preset, cell.task);
        let mut value = serde_json::to_value(&base).map_err(|e| bad(e.to_string()))?;
        merge(&mut value, &self.overrides);
        let mut cfg: TrainConfig = serde_json::from_value(value).map_err(|e| bad(format!("config: {e}")))?;
        let variant =
            Variant::by_name(&cell.variant).ok_or_else(|| bad(format!("unknown variant `{}`", cell.variant)))?;
        cfg.task = cell.task;
        cfg.agent.model = variant.model;
        cfg.agent.hidden /= variant.hidden_divisor;
        cfg.augmentation = variant.augmentation;
        cfg.view = cell.view;
        cfg.corruption = cell.corruption;
        cfg.arm = cell.arm;
        cfg.seed = cell.seed;
        if let Some(&u) = self.updates.get(&cell.task) {
            cfg.total_updates = u;
        }
        equiarm_train::config::check(&cfg)
            .map_err(|e| bad(format!("run {}: config field `{}`: {}", cell.rel_dir().display(), e.field, e.message)))?;
        Ok(cfg)
    }
}

/// Writes `patch` into `base`: objects key by key (recursively), anything else replaced.
fn merge(base: &mut serde_json::Value, patch: &serde_json::Value) {
    match (base, patch) {
        (serde_json::Value::Object(b), serde_json::Value::Object(p)) => {
            for (k, v) in p {
                match b.get_mut(k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k.clone(), v.clone());
                    }
                }
            }
        }
        (b, p) => *b = p.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Grid> {
        Grid::parse(Path::new("experiments/t.toml"), text)
    }

    const BASE: &str = "description = \"t\"\ntasks = [\"block_pulling\", \"block_in_bowl\"]\nvariants = [\"equi\", \"cnn_drq\"]\nseeds = [0, 1]\n";

    /// Issue 58: the paper's SEN is half Equi SAC's width (hidden 32 against 64), which matches their
    /// parameter counts; `sen_half` keeps that ratio at any grid's width, `sen` is Equi's width.
    #[test]
    fn sen_half_is_half_the_grids_width() {
        let g = parse("description = \"t\"\ntasks = [\"block_pulling\"]\nvariants = [\"equi\", \"sen\", \"sen_half\"]\nseeds = [0]\n")
            .unwrap();
        let hidden: Vec<(ModelKind, usize)> =
            g.cells().iter().map(|c| g.config(c).map(|x| (x.agent.model, x.agent.hidden)).unwrap()).collect();
        assert_eq!(hidden, [(ModelKind::Equi, 16), (ModelKind::Sen, 16), (ModelKind::Sen, 8)]);
        // a width whose half is not a multiple of 8 is refused, naming the run and the field
        let e = parse("description = \"t\"\ntasks = [\"block_pulling\"]\nvariants = [\"sen_half\"]\nseeds = [0]\n[config]\nagent = { hidden = 8 }\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sen_half") && e.contains("agent.hidden") && e.contains("multiple of 8"), "{e}");
    }

    #[test]
    fn cells_and_configs_follow_the_file() {
        let g = parse(&format!(
            "{BASE}corruptions = [\"gripper_only,random_reflection\"]\n[updates]\nblock_in_bowl = 10000\n[config]\neval_every = 50\nagent = {{ hidden = 8 }}\n"
        ))
        .unwrap();
        assert_eq!(g.cells().len(), 8);
        let c = &g.cells()[2];
        assert_eq!((c.task, c.variant.as_str(), c.seed), (TaskKind::BlockPulling, "cnn_drq", 0));
        assert_eq!(c.corruption.to_string(), "random_reflection,gripper_only");
        // the preset's scene has the arm in view: the VIEW part says so
        assert_eq!(c.rel_dir(), PathBuf::from("block_pulling/cnn_drq/side-arm/random_reflection+gripper_only/s0"));
        let cfg = g.config(c).unwrap();
        assert_eq!((cfg.eval_every, cfg.agent.hidden, cfg.seed), (50, 8, 0));
        assert_eq!(cfg.augmentation, Augmentation::Drq { k: 2, m: 2 });
        assert_eq!(cfg.agent.model, ModelKind::Cnn);
        assert_eq!(cfg.total_updates, TrainConfig::reduced16(TaskKind::BlockPulling).total_updates);
        assert_eq!(g.config(&g.cells()[4]).unwrap().total_updates, 10_000);
        // the rest is the preset's
        assert_eq!(cfg.batch_size, TrainConfig::reduced16(TaskKind::BlockPulling).batch_size);
        assert_eq!(g.runs, None, "shared runs directory by default");
        assert_eq!(cfg.arm, ArmView::Visible);
        let hidden = parse(&format!("{BASE}[config]\narm = \"hidden\"\n")).unwrap();
        assert_eq!(hidden.cells()[0].rel_dir(), PathBuf::from("block_pulling/equi/side/none/s0"));
        assert_eq!(hidden.config(&hidden.cells()[0]).unwrap().arm, ArmView::Hidden);
        assert!(parse(&format!("{BASE}[config]\narm = \"glass\"\n")).unwrap_err().to_string().contains("arm"));
        assert!(cfg.agent.matmul.is_f32());
        let own = parse(&format!("{BASE}runs = \"runs/own\"\n[config]\nagent = {{ matmul = \"bf16\" }}\n")).unwrap();
        assert_eq!(own.runs, Some(PathBuf::from("runs/own")));
        assert_eq!(own.config(&own.cells()[0]).unwrap().agent.matmul.name(), "bf16");
    }

    #[test]
    fn only_keeps_the_runs_a_glob_matches_and_refuses_one_that_matches_none() {
        let g = parse(BASE).unwrap();
        let names = |g: &Grid| g.cells().iter().map(|c| c.rel_dir().display().to_string()).collect::<Vec<_>>();
        assert_eq!(names(&g.only(&[]).unwrap()), names(&g));
        let cnn = g.only(&["*/cnn_drq/**".into()]).unwrap();
        assert_eq!(
            names(&cnn),
            [
                "block_pulling/cnn_drq/side-arm/none/s0",
                "block_pulling/cnn_drq/side-arm/none/s1",
                "block_in_bowl/cnn_drq/side-arm/none/s0",
                "block_in_bowl/cnn_drq/side-arm/none/s1"
            ]
        );
        // several patterns: the union, in file order; `*` stays within one part of the path
        let two = g.only(&["block_in_bowl/equi/*/*/s1".into(), "block_pulling/*/*/*/s0".into()]).unwrap();
        assert_eq!(
            names(&two),
            [
                "block_pulling/equi/side-arm/none/s0",
                "block_pulling/cnn_drq/side-arm/none/s0",
                "block_in_bowl/equi/side-arm/none/s1"
            ]
        );
        for (pattern, says) in
            [("*/cnn/**", "matches none of its 8 runs"), ("block_pulling/*", "matches none"), ("[", "--only `[`")]
        {
            let e = g.only(&[pattern.into()]).unwrap_err().to_string();
            assert!(e.contains("experiments/t.toml") && e.contains(says), "{pattern}: {e}");
        }
    }

    #[test]
    fn bad_grids_are_refused_naming_the_key() {
        for (text, key) in [
            (format!("{BASE}preset = \"huge\""), "preset"),
            (BASE.replace("\"cnn_drq\"", "\"ferm2\""), "variants"),
            (format!("{BASE}views = [\"top\"]"), "view"),
            (format!("{BASE}corruptions = [\"mirror\"]"), "corruptions"),
            (format!("{BASE}[updates]\nblock_picking = 10"), "updates"),
            (format!("{BASE}[config]\nbatch_sise = 10"), "batch_sise"),
            (format!("{BASE}[config]\nbatch_size = 0"), "batch_size"),
            (format!("{BASE}checkpoint_minutes = 0"), "checkpoint_minutes"),
            // regression (issue 61): "held-out success -0.00 over 0 episodes" went into result.json
            (format!("{BASE}heldout_episodes = 0"), "heldout_episodes"),
            (format!("{BASE}[config]\nagent = {{ expert_weight = -1.0 }}"), "expert_weight"),
            (format!("{BASE}colour = 1"), "colour"),
            (BASE.replace("seeds = [0, 1]", "seeds = []"), "seeds"),
            (BASE.replace("seeds = [0, 1]", "seeds = [1, 1]"), "twice"),
            (BASE.replace("description", "desc"), "description"),
        ] {
            let e = parse(&text).unwrap_err().to_string();
            assert!(e.contains("experiments/t.toml") && e.contains(key), "{key}: {e}");
        }
    }
}
