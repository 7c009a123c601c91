//! The report of a grid, from its run directories alone: `OUT/README.md` with one table row per
//! task × view × corruption × variant (mean ± standard error over the seeds of the held-out
//! evaluation and of the last evaluation during training, discounted return first as the paper plots
//! it, success rate beside it, the paper's figure where the grid gives it) and, per task × view × corruption, two figures of the
//! greedy evaluations against updates (success rate, discounted return), one curve per variant:
//! the mean over seeds with a band of ± one standard error. Where a task × corruption has finished
//! runs at two or more camera views, a table and two figures of the held-out results against the
//! camera's elevation ([`by_view`]).
//!
//! The report also writes `OUT/runs.json`, the archive of its finished runs (config, evaluations,
//! result: a few kB a run). Committed with the report, it lets a later checkout, on a machine without
//! the run directories, count those runs as done (`run` skips them) and draw them again.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{read_json, write_json};
use equiarm_train::evaluation::EvalResult;
use equiarm_train::plot::{Chart, Series, mean_se, palette, write_png};
use equiarm_types::files::{at, replace};
use serde::{Deserialize, Serialize};

use crate::error::{ExperimentError, Result};
use crate::grid::{Cell, Grid, VARIANTS, Variant};
use crate::runner::{RESULT_FILE, RunResult, check_config, read_result};

/// One run as the report sees it.
#[derive(Clone, Debug)]
pub struct RunView {
    /// The cell.
    pub cell: Cell,
    /// Evaluations so far (`evals.json`, or the latest checkpoint's for a run in progress).
    pub evals: Vec<EvalResult>,
    /// The result, once finished.
    pub result: Option<RunResult>,
    /// Updates the run is to make.
    pub total_updates: u64,
}

/// A finished run as a report keeps it (`OUT/runs.json`): enough to count it as done and to draw
/// it again on a machine that does not have its directory.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Archived {
    /// The run's directory below the runs directory ([`Cell::rel_dir`]).
    pub run: PathBuf,
    /// Its config.
    pub config: TrainConfig,
    /// Its evaluations during training.
    pub evals: Vec<EvalResult>,
    /// Its result.
    pub result: RunResult,
}

/// The archive file a report writes beside its README.md.
pub const ARCHIVE_FILE: &str = "runs.json";

/// Every archived run, by run directory: several where grids with their own runs directories
/// (`runs` in the grid file) have runs of the same name and different configs.
pub type Archive = BTreeMap<PathBuf, Vec<Archived>>;

/// Finished runs archived by earlier reports: every `DIR/*/runs.json`, by run directory (a missing
/// `DIR` is an empty archive).
pub fn read_archives(dir: &Path) -> Result<Archive> {
    let mut out = BTreeMap::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(at(dir))?
        .filter_map(|e| e.ok().map(|e| e.path().join(ARCHIVE_FILE)))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    for f in files {
        let runs: Vec<Archived> = read_json(&f)?;
        for a in runs {
            out.entry(a.run.clone()).or_insert_with(Vec::new).push(a);
        }
    }
    Ok(out)
}

/// The archived run of `cell`, if the archive has it with the config the grid gives now.
pub fn archived<'a>(archive: &'a Archive, cell: &Cell, cfg: &TrainConfig) -> Option<&'a Archived> {
    archive.get(&cell.rel_dir())?.iter().find(|a| &a.config == cfg)
}

/// Every cell of `grid` with a directory below `runs` or a finished run in `archive`.
pub fn collect(grid: &Grid, runs: &Path, archive: &Archive) -> Result<Vec<RunView>> {
    let mut out = Vec::new();
    for cell in grid.cells() {
        let dir = runs.join(cell.rel_dir());
        let cfg = grid.config(cell)?;
        let local_done = dir.join(RESULT_FILE).is_file();
        if let (false, Some(a)) = (local_done, archived(archive, cell, &cfg)) {
            out.push(RunView {
                cell: cell.clone(),
                evals: a.evals.clone(),
                result: Some(a.result.clone()),
                total_updates: cfg.total_updates,
            });
            continue;
        }
        if !dir.is_dir() {
            continue;
        }
        check_config(&dir, &cfg)?;
        let result = read_result(&dir)?;
        // A finished run's evals.json; a run in progress has its evaluations up to its latest
        // checkpoint in that checkpoint's loop state.
        let bad = |e: String| ExperimentError::Run { dir: dir.clone(), message: e };
        let evals_file = dir.join("evals.json");
        let latest = dir.join("checkpoints").join("latest");
        let evals: Vec<EvalResult> = if result.is_none() && latest.is_file() {
            let ckpt = equiarm_train::rundir::find_checkpoint(&dir)?;
            equiarm_train::inprocess::LoopState::read(&ckpt).map_err(|e| bad(e.to_string()))?.evals
        } else if evals_file.is_file() {
            equiarm_sac::learner::read_json(&evals_file).map_err(|e| bad(format!("evals.json: {e}")))?
        } else {
            Vec::new()
        };
        out.push(RunView { cell: cell.clone(), evals, result, total_updates: cfg.total_updates });
    }
    Ok(out)
}

type GroupKey = (String, String, String);

/// Writes `OUT/README.md`, the figures and the archive of the finished runs (`OUT/runs.json`);
/// returns the files written. Runs are taken from `runs`, and from `archive` where `runs` does not
/// have them finished.
pub fn write(grid: &Grid, runs: &Path, archive: &Archive, out: &Path, command: &str) -> Result<Vec<PathBuf>> {
    let views = collect(grid, runs, archive)?;
    std::fs::create_dir_all(out).map_err(at(out))?;
    let mut files = Vec::new();
    let mut keep = Vec::new();
    for v in &views {
        if let Some(r) = &v.result {
            keep.push(Archived {
                run: v.cell.rel_dir(),
                config: grid.config(&v.cell)?,
                evals: v.evals.clone(),
                result: r.clone(),
            });
        }
    }
    let archive_file = out.join(ARCHIVE_FILE);
    write_json(&archive_file, &keep)?;
    // task × view × corruption → variant → runs
    let mut groups: BTreeMap<GroupKey, BTreeMap<usize, Vec<&RunView>>> = BTreeMap::new();
    for v in &views {
        let vi = VARIANTS.iter().position(|x| x.name == v.cell.variant).unwrap_or(usize::MAX);
        groups
            .entry((v.cell.task.to_string(), v.cell.view.to_string(), v.cell.corruption.to_string()))
            .or_default()
            .entry(vi)
            .or_default()
            .push(v);
    }
    let mut md = format!("# Experiment `{}`\n\n{}\n\n", grid.name, grid.description.trim());
    md += &format!("Scene: {}.\n\n", scene_of(grid, out));
    md += &format!(
        "Regenerate this page from the run directories with `{command}`. Grid: [`{}`]({}). Base preset `{}`; \
         every run is one `equiarm train --in-process` run at one thread. The headline is what the paper \
         plots: the discounted return (γ = 0.99) of the greedy policy at the end of training, here over {} \
         held-out episodes of the final weights (episodes no evaluation saw), success rate beside it; mean ± \
         standard error over the finished seeds (the mean alone below three seeds). The last evaluation \
         during training (its episodes are the same at every evaluation) follows. The paper's figure is its \
         discounted return at the last training step (docs/paper.md §6, read off its plots, 4 seeds).\n\n",
        grid.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        relative_link(out, &grid.path),
        grid.preset.name(),
        grid.heldout_episodes
    );
    md += "| task | view | corruption | variant | finished | updates | **held-out: disc. return** | success | held-out disc. return per seed | paper (disc. return) | last evaluation: disc. return | success | training time per run |\n";
    md += "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for ((task, view, corruption), by_variant) in &groups {
        for (vi, runs_of) in by_variant {
            let variant: Option<Variant> = VARIANTS.get(*vi).copied();
            let done: Vec<&RunResult> = runs_of.iter().filter_map(|r| r.result.as_ref()).collect();
            let pick =
                |f: &dyn Fn(&RunResult) -> Option<f64>| -> Vec<f64> { done.iter().filter_map(|r| f(r)).collect() };
            let cell = |v: Vec<f64>| stat(&v);
            let mut per_seed: Vec<(u64, f64)> = runs_of
                .iter()
                .filter_map(|r| r.result.as_ref().map(|x| (r.cell.seed, x.heldout.discounted_return)))
                .collect();
            per_seed.sort_by_key(|p| p.0);
            let per_seed = per_seed.iter().map(|(s, x)| format!("s{s} {x:.2}")).collect::<Vec<_>>().join(", ");
            let updates = runs_of.iter().map(|r| r.total_updates).max().unwrap_or(0);
            let name = variant.map_or("?", |v| v.name);
            let paper = grid.paper.get(&format!("{task}/{name}")).map_or("–".to_string(), |p| format!("{p:.2}"));
            let time = cell(pick(&|r| Some(r.train_seconds / 60.0))) + " min";
            md += &format!(
                "| {task} | {view} | {corruption} | {} | {} of {} | {updates} | **{}** | {} | {} | {paper} | {} | {} | {} |\n",
                variant.map_or("?", |v| v.label),
                done.len(),
                runs_of.len(),
                cell(pick(&|r| Some(r.heldout.discounted_return))),
                cell(pick(&|r| Some(r.heldout.success_rate))),
                if per_seed.is_empty() { "–".into() } else { per_seed },
                cell(pick(&|r| r.last_eval.as_ref().map(|e| e.discounted_return))),
                cell(pick(&|r| r.last_eval.as_ref().map(|e| e.success_rate))),
                if done.is_empty() { "–".into() } else { time },
            );
        }
    }
    md += &params_table(grid)?;
    let unfinished: Vec<String> = views
        .iter()
        .filter(|v| v.result.is_none())
        .map(|v| {
            let at = v.evals.last().map_or(0, |e| e.updates);
            format!("- `{}` (last evaluation at {at} of {} updates)", v.cell.rel_dir().display(), v.total_updates)
        })
        .collect();
    let missing = grid.cells().len() - views.len();
    if !unfinished.is_empty() || missing > 0 {
        md += "\nNot finished:\n\n";
        md += &unfinished.join("\n");
        if missing > 0 {
            md += &format!("{}- {missing} runs not started", if unfinished.is_empty() { "" } else { "\n" });
        }
        md += "\n";
    }
    let swept = by_view(&views);
    if !swept.is_empty() {
        md += "\n## By camera view\n\nHeld-out evaluation of the final weights at each camera elevation, for each task and \
               corruption with finished runs at two or more views: discounted return (success rate), mean ± standard \
               error over the finished seeds (n; the mean alone below three seeds).\n\n";
    }
    for ((task, corruption), by_variant) in &swept {
        let mut cols: Vec<(equiarm_types::ViewPreset, f64)> =
            by_variant.values().flatten().map(|p| (p.view, p.elevation_deg)).collect();
        cols.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        cols.dedup();
        md += &format!("{task}, corruption {corruption}:\n\n| variant |");
        for (view, deg) in &cols {
            md += &format!(" {view} ({deg:.1}°) |");
        }
        md += &format!("\n|---|{}\n", "---|".repeat(cols.len()));
        for (vi, points) in by_variant {
            md += &format!("| {} |", VARIANTS.get(*vi).map_or("?", |v| v.label));
            for (view, _) in &cols {
                match points.iter().find(|p| &p.view == view) {
                    Some(p) => {
                        md +=
                            &format!(" {} ({}; n={}) |", stat(&p.discounted_return), stat(&p.success), p.success.len());
                    }
                    None => md += " – |",
                }
            }
            md += "\n";
        }
        let stem = format!("{task}-{}-by_view", corruption.replace(',', "+"));
        for (metric, label) in [("success", "success rate"), ("return", "discounted return")] {
            let series: Vec<Series> = by_variant
                .iter()
                .map(|(vi, points)| {
                    let mut stats: Vec<(f64, (f64, f64))> = points
                        .iter()
                        .map(|p| {
                            let v = if metric == "success" { &p.success } else { &p.discounted_return };
                            (p.elevation_deg, mean_se(v))
                        })
                        .collect();
                    stats.sort_by(|a, b| a.0.total_cmp(&b.0));
                    mean_band(VARIANTS.get(*vi).map_or("?".to_string(), |v| v.label.to_string()), *vi, &stats)
                })
                .collect();
            let chart = Chart::new(
                format!("{task}, corruption {corruption}: held-out {label} by camera elevation"),
                "camera elevation (degrees; 90 = top-down)",
                format!("held-out {label}"),
            );
            files.push(draw(out, &format!("{stem}-{metric}.png"), chart, metric, &series)?);
        }
        md += &format!(
            "\n![{task}, {corruption}, by view: discounted return]({stem}-return.png)\n![{task}, {corruption}, by view: success rate]({stem}-success.png)\n\n"
        );
    }
    md += "\n## Learning curves\n\nGreedy evaluations during training, mean ± one standard error over seeds (a seed counts at an update count once it has evaluated there).\n\n";
    for ((task, view, corruption), by_variant) in &groups {
        let stem = format!("{task}-{view}-{}", corruption.replace(',', "+"));
        for (metric, label) in [("success", "success rate"), ("return", "discounted return")] {
            let series: Vec<Series> = by_variant
                .iter()
                .map(|(vi, runs_of)| {
                    let seeds = runs_of.iter().filter(|r| !r.evals.is_empty()).count();
                    let label = VARIANTS.get(*vi).map_or("?".to_string(), |v| format!("{} ({seeds} seeds)", v.label));
                    let mut at: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
                    for r in runs_of {
                        for e in &r.evals {
                            let y = if metric == "success" { e.success_rate } else { e.discounted_return };
                            at.entry(e.updates).or_default().push(y);
                        }
                    }
                    let stats: Vec<(f64, (f64, f64))> = at.iter().map(|(u, v)| (*u as f64, mean_se(v))).collect();
                    mean_band(label, *vi, &stats)
                })
                .collect();
            let chart = Chart::new(
                format!("{task}, view {view}, corruption {corruption}"),
                "updates",
                format!("evaluation {label}"),
            );
            files.push(draw(out, &format!("{stem}-{metric}.png"), chart, metric, &series)?);
        }
        md += &format!(
            "![{task}, {view}, {corruption}: discounted return]({stem}-return.png)\n![{task}, {view}, {corruption}: success rate]({stem}-success.png)\n\n"
        );
    }
    let readme = out.join("README.md");
    replace(&readme, md)?;
    files.insert(0, readme);
    files.push(archive_file);
    Ok(files)
}

/// Variant `vi`'s curve: the mean at each x, with a band of ± one standard error.
fn mean_band(label: String, vi: usize, stats: &[(f64, (f64, f64))]) -> Series {
    Series {
        label,
        color: palette(vi),
        points: stats.iter().map(|(x, (m, _))| (*x, *m)).collect(),
        band: Some(stats.iter().map(|(_, (_, se))| *se).collect()),
        bars: false,
    }
}

/// Draws `series` into `OUT/NAME` (a success-rate chart on a fixed 0–1 axis); returns the file.
fn draw(out: &Path, name: &str, mut chart: Chart, metric: &str, series: &[Series]) -> Result<PathBuf> {
    if metric == "success" {
        chart.y_range = Some((0.0, 1.0));
    }
    let file = out.join(name);
    write_png(&file, &chart, series)?;
    Ok(file)
}

/// One variant's finished runs at one camera view, for the by-view summary.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewPoint {
    /// The camera preset.
    pub view: equiarm_types::ViewPreset,
    /// Its camera elevation, degrees (90 = top-down).
    pub elevation_deg: f64,
    /// Held-out success rate of each finished seed.
    pub success: Vec<f64>,
    /// Held-out discounted return of each finished seed.
    pub discounted_return: Vec<f64>,
}

/// The finished runs' held-out results by camera elevation (the paper's view-angle figure, docs/paper.md
/// §5.1): task × corruption → variant (index into [`VARIANTS`]) → one point per view, highest elevation
/// first. Only task × corruption pairs with finished runs at two or more views are kept.
pub fn by_view(views: &[RunView]) -> BTreeMap<(String, String), BTreeMap<usize, Vec<ViewPoint>>> {
    let mut out: BTreeMap<(String, String), BTreeMap<usize, Vec<ViewPoint>>> = BTreeMap::new();
    for v in views {
        let Some(r) = &v.result else {
            continue;
        };
        let vi = VARIANTS.iter().position(|x| x.name == v.cell.variant).unwrap_or(usize::MAX);
        let points =
            out.entry((v.cell.task.to_string(), v.cell.corruption.to_string())).or_default().entry(vi).or_default();
        let i = match points.iter().position(|p| p.view == v.cell.view) {
            Some(i) => i,
            None => {
                points.push(ViewPoint {
                    view: v.cell.view,
                    elevation_deg: equiarm_sim::CameraConfig::from(v.cell.view).elevation_deg,
                    success: Vec::new(),
                    discounted_return: Vec::new(),
                });
                points.len() - 1
            }
        };
        points[i].success.push(r.heldout.success_rate);
        points[i].discounted_return.push(r.heldout.discounted_return);
    }
    out.retain(|_, by_variant| {
        by_variant.values().flatten().map(|p| p.view).collect::<std::collections::BTreeSet<_>>().len() >= 2
    });
    for by_variant in out.values_mut() {
        for points in by_variant.values_mut() {
            points.sort_by(|a, b| b.elevation_deg.total_cmp(&a.elevation_deg));
        }
    }
    out
}

/// A relative link from a file in `from_dir` to `to` (both relative to the working directory), or
/// `to` as given when it cannot be made relative.
fn relative_link(from_dir: &Path, to: &Path) -> String {
    let abs = |p: &Path| std::path::absolute(p).ok();
    let (Some(from), Some(to_abs)) = (abs(from_dir), abs(to)) else { return to.display().to_string() };
    let f: Vec<_> = from.components().collect();
    let t: Vec<_> = to_abs.components().collect();
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    let mut p = PathBuf::new();
    for _ in common..f.len() {
        p.push("..");
    }
    for c in &t[common..] {
        p.push(c);
    }
    p.display().to_string()
}

/// Whether every run of `grid` is finished, below `runs` or in `archive`.
pub fn all_finished(grid: &Grid, runs: &Path, archive: &Archive) -> Result<bool> {
    for c in grid.cells() {
        let cfg = grid.config(c)?;
        if !runs.join(c.rel_dir()).join(RESULT_FILE).is_file() && archived(archive, c, &cfg).is_none() {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Fewest seeds whose standard error a page prints: from two it says too little (two seeds that
/// happen to agree print "± 0.00").
pub const MIN_SEEDS_FOR_SE: usize = 3;

/// A mean over seeds as the pages print it: `m ± se` from [`MIN_SEEDS_FOR_SE`] seeds on, the mean
/// alone below that (the tables give the seed count beside it), `–` for none.
pub(crate) fn stat(v: &[f64]) -> String {
    let (m, se) = mean_se(v);
    match v.len() {
        0 => "–".to_string(),
        n if n < MIN_SEEDS_FOR_SE => format!("{m:.2}"),
        _ => format!("{m:.2} ± {se:.2}"),
    }
}

/// The networks' sizes of each variant of `grid` (its first task's config; the sizes do not depend
/// on the task): the paper matched them across models, so a comparison is only fair as far as they match.
fn params_table(grid: &Grid) -> Result<String> {
    let mut md = "\nTrainable parameters of each variant's networks (actor; critic, both Q heads), as the grid builds \
                  them:\n\n| variant | actor | critic | actor / Equi SAC's |\n|---|---|---|---|\n"
        .to_string();
    let mut seen = Vec::new();
    let mut rows = Vec::new();
    for c in grid.cells() {
        if seen.contains(&c.variant) {
            continue;
        }
        seen.push(c.variant.clone());
        let cfg = grid.config(c)?;
        let agent = equiarm_sac::agent::Agent::new(cfg.agent.clone(), 0)
            .map_err(|e| ExperimentError::Grid { path: grid.path.clone(), message: format!("{}: {e}", c.variant) })?;
        let label = VARIANTS.iter().find(|v| v.name == c.variant).map_or(c.variant.as_str(), |v| v.label);
        rows.push((label.to_string(), cfg.agent.model, agent.param_counts()));
    }
    let equi = rows.iter().find(|r| r.1 == equiarm_types::ModelKind::Equi).map(|r| r.2.0);
    for (label, _, (actor, critic)) in &rows {
        let ratio = equi.map_or("–".to_string(), |e| format!("{:.2}", *actor as f64 / e as f64));
        md += &format!("| {label} | {actor} | {critic} | {ratio} |\n");
    }
    Ok(md)
}

/// Which scene a grid's runs used: the arm in view or not, and the floor (docs/arm.md).
fn scene_of(grid: &Grid, out: &Path) -> String {
    use equiarm_types::ArmView;
    let arms: std::collections::BTreeSet<ArmView> = grid.cells().iter().map(|c| c.arm).collect();
    let gripper_only = grid.cells().iter().all(|c| c.corruption.gripper_only);
    let arm = match arms.iter().collect::<Vec<_>>()[..] {
        [ArmView::Visible] if gripper_only => "the arm hidden by the gripper-only scene",
        [ArmView::Visible] => "the arm that carries the gripper in view (the paper's scene)",
        [ArmView::Hidden] => {
            "the arm hidden (a floating gripper: the scene before the arm was drawn, kept so that new seeds stay comparable with the archived ones)"
        }
        _ => "runs with and without the arm (the VIEW part of a run's path ends in `-arm` where it is in view)",
    };
    let floor = if gripper_only { "a plain floor" } else { "the tiled floor" };
    let root = grid.path.parent().and_then(Path::parent).unwrap_or(Path::new(""));
    format!("{arm}; {floor} ([docs/arm.md]({}))", relative_link(out, &root.join("docs/arm.md")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use equiarm_types::{Corruption, TaskKind, ViewPreset};

    /// Issue 58: two seeds that happened to agree printed "± 0.00", read as a precise figure.
    #[test]
    fn a_mean_of_fewer_than_three_seeds_prints_no_standard_error() {
        assert_eq!(stat(&[]), "–");
        assert_eq!(stat(&[0.8, 0.8]), "0.80");
        assert_eq!(stat(&[0.7, 0.8, 0.9]), "0.80 ± 0.06");
    }

    #[test]
    fn archives_keep_runs_of_one_name_with_different_configs_apart() {
        let cell = Cell {
            task: TaskKind::BlockPulling,
            variant: "equi".into(),
            view: ViewPreset::Side,
            corruption: Corruption::NONE,
            arm: equiarm_types::ArmView::Hidden,
            seed: 0,
        };
        let f32_cfg = TrainConfig::reduced16(TaskKind::BlockPulling);
        let mut bf16_cfg = f32_cfg.clone();
        bf16_cfg.agent.matmul = serde_json::from_str("\"bf16\"").unwrap();
        let run = |config: &TrainConfig, success_rate: f64| Archived {
            run: cell.rel_dir(),
            config: config.clone(),
            evals: Vec::new(),
            result: RunResult {
                updates: 5000,
                env_steps: 25_000,
                train_seconds: 1.0,
                last_eval: None,
                heldout: EvalResult { updates: 5000, episodes: 100, success_rate, ..EvalResult::default() },
                heldout_seconds: 1.0,
            },
        };
        let dir = std::env::temp_dir().join(format!("equiarm_archives_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for (grid, a) in [("tasks", run(&f32_cfg, 0.8)), ("bf16_check", run(&bf16_cfg, 0.7))] {
            std::fs::create_dir_all(dir.join(grid)).unwrap();
            std::fs::write(dir.join(grid).join(ARCHIVE_FILE), serde_json::to_vec(&[a]).unwrap()).unwrap();
        }
        let archive = read_archives(&dir).unwrap();
        assert_eq!(archive[&cell.rel_dir()].len(), 2);
        assert_eq!(archived(&archive, &cell, &f32_cfg).unwrap().result.heldout.success_rate, 0.8);
        assert_eq!(archived(&archive, &cell, &bf16_cfg).unwrap().result.heldout.success_rate, 0.7);
        let mut other = f32_cfg.clone();
        other.seed = 9;
        assert!(archived(&archive, &cell, &other).is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn by_view_groups_finished_runs_by_elevation_and_drops_single_view_groups() {
        let run = |task: &str, variant: &str, view: &str, seed: u64, success: Option<f64>| RunView {
            cell: Cell {
                task: task.parse().unwrap(),
                variant: variant.into(),
                view: view.parse().unwrap(),
                corruption: "gripper_only".parse().unwrap(),
                arm: equiarm_types::ArmView::Hidden,
                seed,
            },
            evals: Vec::new(),
            result: success.map(|s| crate::runner::test_result(s, s / 2.0)),
            total_updates: 10,
        };
        let views = [
            run("block_pulling", "equi", "angle15", 0, Some(0.2)),
            run("block_pulling", "equi", "angle90", 0, Some(0.9)),
            run("block_pulling", "equi", "angle90", 1, Some(0.7)),
            run("block_pulling", "equi", "angle30", 0, None),
            run("block_pulling", "cnn", "side", 0, Some(0.5)),
            // one view only: no sweep to draw
            run("block_pushing", "equi", "angle90", 0, Some(0.4)),
            run("block_pushing", "cnn", "angle90", 0, Some(0.3)),
        ];
        let swept = by_view(&views);
        assert_eq!(swept.len(), 1);
        let pulling = &swept[&("block_pulling".to_string(), "gripper_only".to_string())];
        let equi = &pulling[&0];
        assert_eq!(equi.iter().map(|p| p.view.name()).collect::<Vec<_>>(), ["angle90", "angle15"]);
        assert_eq!(equi[0].elevation_deg, 90.0);
        assert_eq!(equi[0].success, [0.9, 0.7]);
        assert_eq!(equi[0].discounted_return, [0.45, 0.35]);
        assert_eq!(equi[1].success, [0.2]);
        let cnn = &pulling[&VARIANTS.iter().position(|v| v.name == "cnn").unwrap()];
        assert_eq!(cnn.len(), 1);
        assert!((cnn[0].elevation_deg - 47.49).abs() < 0.01, "side is BulletArm's 47.5° view");
    }

    #[test]
    fn links_are_relative_to_the_report() {
        assert_eq!(
            relative_link(Path::new("docs/results/tasks"), Path::new("experiments/tasks.toml")),
            "../../../experiments/tasks.toml"
        );
    }
}
