//! The report over many runs: every `run.json` under a directory, grouped by corruption setting,
//! variant (Equi, CNN, CNN + image transformations; "no crop" when random crops were off) and
//! training-set size, as mean ± standard error over seeds; a Markdown table and one PNG per setting
//! (accuracy against the number of training pairs, one line per variant, the invariant-classifier
//! bound as a dashed line where it is below 1).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_train::plot::{Chart, Legend, Scale, Series, mean_se, write_panels_png, write_png};

use equiarm_sim::rotest::PairCorruption;

use crate::error::{Result, RotestError};
use crate::train::{ClassifierKind, RotestConfig, RotestRecord};
use equiarm_types::files::at;

/// The variant name of the C8 network.
pub const EQUI: &str = "Equi";
/// The variant name of the CNN.
pub const CNN: &str = "CNN";
/// The variant name of the CNN trained on the eight rotations of its pairs (`--img-trans`).
pub const CNN_TRANS: &str = "CNN + trans";

/// Name of a run's variant: [`EQUI`], [`CNN`] or [`CNN_TRANS`] (or `Equi + trans`), with
/// ` (no crop)` when crops were off.
pub fn variant(r: &RotestRecord) -> String {
    variant_of(&r.config)
}

/// [`variant`] of a run's configuration.
pub fn variant_of(cfg: &RotestConfig) -> String {
    let base = match (cfg.model, cfg.img_trans > 0) {
        (ClassifierKind::Equi, false) => EQUI,
        (ClassifierKind::Equi, true) => "Equi + trans",
        (ClassifierKind::Cnn, false) => CNN,
        (ClassifierKind::Cnn, true) => CNN_TRANS,
    };
    if cfg.crop { base.to_string() } else { format!("{base} (no crop)") }
}

/// Every `run.json` below `dir` (recursively), sorted by path. A file that does not parse is an
/// error naming it.
pub fn collect_runs(dir: &Path) -> Result<Vec<(PathBuf, RotestRecord)>> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).map_err(at(&d))? {
            let p = e.map_err(at(&d))?.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n == "run.json") {
                files.push(p);
            }
        }
    }
    files.sort();
    files.into_iter().map(|p| Ok((p.clone(), read_record(&p)?))).collect()
}

/// One run's record (its `run.json`).
pub fn read_record(path: &Path) -> Result<RotestRecord> {
    let text = std::fs::read(path).map_err(at(path))?;
    serde_json::from_slice(&text)
        .map_err(|e| RotestError::Format { path: path.to_path_buf(), message: format!("not a run file: {e}") })
}

/// Test accuracies by setting → variant → training pairs.
pub type Table = BTreeMap<String, BTreeMap<String, BTreeMap<usize, Vec<f64>>>>;

/// Groups runs into a [`Table`], each cell's accuracies in increasing order: a mean is then summed
/// in one order whatever order the runs came in (from the runs directory, or from the archive on
/// another machine), so a mean that falls on a rounding boundary (2.01 / 4 = 0.5025) is printed
/// the same by both.
pub fn table(runs: &[(PathBuf, RotestRecord)]) -> Table {
    let mut t = Table::new();
    for (_, r) in runs {
        t.entry(r.corrupt.clone())
            .or_default()
            .entry(variant(r))
            .or_default()
            .entry(r.config.train_pairs)
            .or_default()
            .push(r.test_acc);
    }
    for cells in t.values_mut().flat_map(|by_var| by_var.values_mut()).flat_map(|by_n| by_n.values_mut()) {
        cells.sort_by(f64::total_cmp);
    }
    t
}

/// A cell of accuracies in percent: `mean ± s.e. (seeds)`, or `mean (1)` for a single seed (whose
/// standard error is unknown, not zero).
fn cell(acc: &[f64]) -> String {
    let (m, se) = mean_se(acc);
    if acc.len() < 2 {
        format!("{:.1} (1)", 100.0 * m)
    } else {
        format!("{:.1} ± {:.1} ({})", 100.0 * m, 100.0 * se, acc.len())
    }
}

/// The Markdown table: one row per setting and training size, one column per variant, cells
/// `mean ± s.e. (seeds)` in percent (`mean (1)` for one seed).
pub fn markdown(t: &Table) -> String {
    let mut variants: Vec<String> = t.values().flat_map(|v| v.keys().cloned()).collect();
    variants.sort();
    variants.dedup();
    let mut s = format!("| setting | N | {} |\n|---|---|{}\n", variants.join(" | "), "---|".repeat(variants.len()));
    for (setting, by_var) in t {
        let mut ns: Vec<usize> = by_var.values().flat_map(|m| m.keys().copied()).collect();
        ns.sort();
        ns.dedup();
        for n in ns {
            let cells: Vec<String> = variants
                .iter()
                .map(|v| match by_var.get(v).and_then(|m| m.get(&n)) {
                    Some(acc) => cell(acc),
                    None => "–".into(),
                })
                .collect();
            s += &format!("| {setting} | {n} | {} |\n", cells.join(" | "));
        }
    }
    s
}

/// The difference of two cells' mean accuracies in points, with the standard error of the
/// difference (`√(se_a² + se_b²)`) when both cells have two seeds or more.
#[derive(Clone, Copy, Debug)]
struct Diff {
    points: f64,
    se: Option<f64>,
}

/// A difference of accuracies (fractions) in points, with rounding noise of the means (below
/// 1e-6 points) set to zero: accuracies are counts over the same test set, so equal means tie.
fn points(fraction: f64) -> f64 {
    let p = 100.0 * fraction;
    if p.abs() < 1e-6 { 0.0 } else { p }
}

impl Diff {
    fn of(a: &[f64], b: &[f64]) -> Self {
        let ((ma, sa), (mb, sb)) = (mean_se(a), mean_se(b));
        let se = (a.len() >= 2 && b.len() >= 2).then(|| 100.0 * sa.hypot(sb));
        Diff { points: points(ma - mb), se }
    }

    /// A cell's distance to a fixed accuracy (the invariant bound), with the cell's own standard
    /// error when it has two seeds or more.
    fn to_value(acc: &[f64], value: f64) -> Self {
        let (m, se) = mean_se(acc);
        Diff { points: points(m - value), se: (acc.len() >= 2).then_some(100.0 * se) }
    }

    /// Whether the difference is within two of its standard errors of zero (`None` without one).
    fn within_two_se(self) -> Option<bool> {
        self.se.map(|se| self.points.abs() <= 2.0 * se)
    }
}

impl std::fmt::Display for Diff {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:+.1}", self.points)?;
        if let Some(se) = self.se { write!(f, " ± {se:.1}") } else { Ok(()) }
    }
}

/// Whether a setting's labels are inverted by the objects' arrangement (invert-label), the one
/// setting where the paper expects the CNN ahead.
fn inverts_labels(setting: &str) -> bool {
    setting.split(',').any(|w| PairCorruption::from_name(w.trim()) == Some(PairCorruption::InvertLabel))
}

/// `a − b` for every setting of `settings` and training size both variants have: a Markdown table
/// (one row per setting, one column per size) and the differences themselves.
fn diff_table(t: &Table, settings: &[&String], a: &str, b: &str) -> (String, Vec<(String, usize, Diff)>) {
    let mut cells = Vec::new();
    for &setting in settings {
        let (Some(ra), Some(rb)) = (t[setting].get(a), t[setting].get(b)) else { continue };
        for (n, acc_a) in ra {
            if let Some(acc_b) = rb.get(n) {
                cells.push((setting.clone(), *n, Diff::of(acc_a, acc_b)));
            }
        }
    }
    let ns: std::collections::BTreeSet<usize> = cells.iter().map(|c| c.1).collect();
    let by_cell: BTreeMap<(&str, usize), Diff> = cells.iter().map(|(s, n, d)| ((s.as_str(), *n), *d)).collect();
    let mut s = format!(
        "| setting | {} |\n|---|{}\n",
        ns.iter().map(|n| format!("N = {n}")).collect::<Vec<_>>().join(" | "),
        "---|".repeat(ns.len())
    );
    for &setting in settings {
        let row: Vec<String> =
            ns.iter().map(|&n| by_cell.get(&(setting.as_str(), n)).map_or("–".to_string(), Diff::to_string)).collect();
        if row.iter().all(|c| c == "–") {
            continue;
        }
        s += &format!("| {setting} | {} |\n", row.join(" | "));
    }
    (s, cells)
}

/// A list of cells for a sentence: `` `setting` N = n (diff)``, comma-separated, or "none".
fn cell_list<'a>(cells: impl Iterator<Item = &'a (String, usize, Diff)>) -> String {
    let v: Vec<String> = cells.map(|(s, n, d)| format!("`{s}` N = {n} ({d})")).collect();
    if v.is_empty() { "none".into() } else { v.join(", ") }
}

/// The paper's three claims about this experiment (docs/paper.md §4), each checked on `t` in
/// Markdown: Equi ahead of the CNN on every setting but invert-label; on invert-label Equi at most
/// the invariant bound (from `bounds`) while the CNN exceeds it; CNN + trans close to Equi.
/// Differences are in points, with the standard error of the difference where both cells have two
/// seeds or more; "clearly" means by more than two such standard errors.
pub fn claims(t: &Table, bounds: &BTreeMap<String, f64>) -> String {
    let settings: Vec<&String> = t.keys().filter(|s| !inverts_labels(s)).collect();
    let mut s = String::from("## The paper's claims, checked on this table\n\n");

    let (table, cells) = diff_table(t, &settings, EQUI, CNN);
    let ahead = cells.iter().filter(|c| c.2.points > 0.0).count();
    let with_se: Vec<_> = cells.iter().filter(|c| c.2.se.is_some()).collect();
    let clearly = with_se.iter().filter(|c| c.2.points > 0.0 && c.2.within_two_se() == Some(false)).count();
    s += &format!(
        "**1. Equi ahead of the CNN on every setting but invert-label.** Equi − CNN, points:\n\n{table}\n\
         Equi's mean is above the CNN's in {ahead} of {} cells (clearly in {clearly} of the {} with two \
         seeds or more of both); not above: {}.\n\n",
        cells.len(),
        with_se.len(),
        cell_list(cells.iter().filter(|c| c.2.points <= 0.0)),
    );

    for setting in t.keys().filter(|s| inverts_labels(s)) {
        let by_var = &t[setting];
        s += &format!("**2. Invert-label (`{setting}`): Equi at most the invariant bound, the CNN above it.** ");
        let Some(&bound) = bounds.get(setting) else {
            s += "The bound is unknown here: pass the datasets' directory (`--data`) to compute it.\n\n";
            continue;
        };
        let vars: Vec<&str> = [EQUI, CNN, CNN_TRANS].into_iter().filter(|v| by_var.contains_key(*v)).collect();
        let ns: std::collections::BTreeSet<usize> = vars.iter().flat_map(|v| by_var[*v].keys().copied()).collect();
        s += &format!(
            "Bound {:.1} %. Accuracy, and its distance to the bound in points:\n\n| N | {} |\n|---|{}\n",
            100.0 * bound,
            vars.join(" | "),
            "---|".repeat(vars.len())
        );
        for n in &ns {
            let row: Vec<String> = vars
                .iter()
                .map(|v| match by_var[*v].get(n) {
                    Some(acc) => format!("{}: {:+.1}", cell(acc), Diff::to_value(acc, bound).points),
                    None => "–".into(),
                })
                .collect();
            s += &format!("| {n} | {} |\n", row.join(" | "));
        }
        s += "\n";
        for v in [EQUI, CNN] {
            let Some(by_n) = by_var.get(v) else { continue };
            let (above, under): (Vec<_>, Vec<_>) =
                by_n.iter().map(|(n, acc)| (*n, Diff::to_value(acc, bound))).partition(|(_, d)| d.points > 0.0);
            let list = |cells: &[(usize, Diff)]| {
                let v: Vec<String> = cells
                    .iter()
                    .map(|(n, d)| match d.se.filter(|&se| se > 0.0) {
                        Some(se) => format!("{n} ({:+.1} points, {:.1} s.e.)", d.points, d.points.abs() / se),
                        None => format!("{n} ({:+.1} points)", d.points),
                    })
                    .collect();
                if v.is_empty() { "no N".to_string() } else { format!("N = {}", v.join(", ")) }
            };
            s += &format!("{v}: above the bound at {}; at or under it at {}. ", list(&above), list(&under));
        }
        s.truncate(s.trim_end().len());
        s += "\n\n";
    }

    let (table, cells) = diff_table(t, &settings, CNN_TRANS, EQUI);
    let with_se: Vec<_> = cells.iter().filter(|c| c.2.se.is_some()).collect();
    let close = with_se.iter().filter(|c| c.2.within_two_se() == Some(true)).count();
    let mean = cells.iter().map(|c| c.2.points).sum::<f64>() / cells.len().max(1) as f64;
    s += &format!(
        "**3. CNN + trans close to Equi.** CNN + trans − Equi, points:\n\n{table}\n\
         Within two standard errors of the difference in {close} of the {} cells with two seeds or more \
         of both; further apart: {}. Mean difference over all {} cells: {mean:+.1} points.\n",
        with_se.len(),
        cell_list(with_se.iter().copied().filter(|c| c.2.within_two_se() == Some(false))),
        cells.len(),
    );
    s
}

/// A variant's colour, the same in every figure: CNN red, CNN + trans blue, Equi green; others
/// (`(no crop)`, `Equi + trans`) purple, orange or grey by their name.
fn color(variant: &str) -> [u8; 3] {
    const OTHERS: [[u8; 3]; 3] = [[140, 80, 160], [230, 140, 20], [110, 110, 110]];
    match variant {
        CNN => [200, 60, 40],
        CNN_TRANS => [40, 90, 200],
        EQUI => [40, 150, 70],
        _ => OTHERS[variant.bytes().map(usize::from).sum::<usize>() % OTHERS.len()],
    }
}

/// One setting's chart: accuracy (%) against training pairs (log scale, a tick at each N run) for
/// each variant, error bars of one s.e.; `bound` (if below 1) as a dashed line.
fn panel(
    caption: &str,
    by_var: &BTreeMap<String, BTreeMap<usize, Vec<f64>>>,
    bound: Option<f64>,
) -> (Chart, Vec<Series>) {
    let ns: std::collections::BTreeSet<usize> = by_var.values().flat_map(|m| m.keys().copied()).collect();
    let lo = ns.first().copied().unwrap_or(1).max(1) as f64;
    let hi = ns.last().copied().unwrap_or(1).max(1) as f64;
    let chart = Chart {
        x_scale: Scale::Log,
        // a margin of 20 % on both sides (N = 100, 400, 1600 evenly spaced)
        x_range: Some((lo / 1.25, hi * 1.25)),
        x_ticks: Some(ns.iter().map(|&n| n as f64).collect()),
        y_range: Some((0.0, 100.0)),
        reference: bound.filter(|b| *b < 1.0).map(|b| (format!("invariant bound {:.1} %", 100.0 * b), 100.0 * b)),
        legend: Legend::LowerRight,
        ..Chart::new(caption, "training pairs N (log scale)", "test accuracy (%)")
    };
    let series = by_var
        .iter()
        .map(|(v, by_n)| {
            let stats: Vec<(f64, (f64, f64))> = by_n.iter().map(|(n, a)| (*n as f64, mean_se(a))).collect();
            Series {
                band: Some(stats.iter().map(|(_, (_, se))| 100.0 * se).collect()),
                bars: true,
                ..Series::new(v.clone(), color(v), stats.iter().map(|(n, (m, _))| (*n, 100.0 * m)).collect())
            }
        })
        .collect();
    (chart, series)
}

/// One PNG: accuracy (%) against training pairs (log scale) for each variant of `setting`, error bars of one
/// s.e.; `bound` (if below 1) as a dashed line.
pub fn figure(
    path: &Path,
    setting: &str,
    by_var: &BTreeMap<String, BTreeMap<usize, Vec<f64>>>,
    bound: Option<f64>,
) -> Result<()> {
    let (chart, series) = panel(&format!("rotation estimation: {setting}"), by_var, bound);
    Ok(write_png(path, &Chart { width: 640, height: 420, ..chart }, &series)?)
}

/// One PNG with a small panel per setting of `t` (five to a row, in the table's order), the legend
/// in the first: the whole experiment at a glance. Axes as in [`figure`]: training pairs N (log
/// scale) across, test accuracy (%) up.
pub fn overview(path: &Path, t: &Table, bounds: &BTreeMap<String, f64>) -> Result<()> {
    let panels: Vec<(Chart, Vec<Series>)> = t
        .iter()
        .enumerate()
        .map(|(k, (setting, by_var))| {
            let (chart, series) = panel(setting, by_var, bounds.get(setting).copied());
            let legend = if k == 0 { Legend::LowerRight } else { Legend::Hidden };
            let small = Chart {
                width: 330,
                height: 250,
                x_label: String::new(),
                y_label: String::new(),
                text_scale: 0.75,
                legend,
                ..chart
            };
            (small, series)
        })
        .collect();
    let title = "rotation estimation: test accuracy (%) against training pairs N (log scale), mean ± s.e. over seeds";
    Ok(write_panels_png(path, title, &panels, 5)?)
}

/// The archive a report writes beside its table: every run's record without its epoch history
/// (a few hundred bytes a run). Committed with the report, it lets a checkout on another machine
/// skip those runs (`rotest grid`) and draw them again (`rotest report`).
pub const ARCHIVE_FILE: &str = "rotest_runs.json";

/// The key that names a run in the grid: setting, variant, training pairs, seed.
pub fn run_key(r: &RotestRecord) -> (String, String, usize, u64) {
    key(&r.corrupt, &r.config)
}

/// [`run_key`] of a run of setting `corrupt` with configuration `cfg`, before it has run.
pub fn key(corrupt: &str, cfg: &RotestConfig) -> (String, String, usize, u64) {
    (corrupt.to_string(), variant_of(cfg), cfg.train_pairs, cfg.seed)
}

/// The archived runs in `path` (none if the file does not exist).
pub fn read_archive(path: &Path) -> Result<Vec<RotestRecord>> {
    if !path.is_file() {
        return Ok(Vec::new());
    }
    let text = std::fs::read(path).map_err(at(path))?;
    serde_json::from_slice(&text)
        .map_err(|e| RotestError::Format { path: path.to_path_buf(), message: format!("not a run archive: {e}") })
}

/// Writes `out/rotest.md` (the table), `out/rotest_<setting>.png` (one figure per setting) and the
/// archive `out/rotest_runs.json` from the runs below `runs_dir` and the runs of the archive already
/// in `out` that `runs_dir` does not have; `bounds` gives the invariant-classifier bound per setting
/// (drawn where below 1). Returns the files written.
pub fn write(runs_dir: &Path, out: &Path, bounds: &BTreeMap<String, f64>) -> Result<Vec<PathBuf>> {
    let mut runs = if runs_dir.is_dir() { collect_runs(runs_dir)? } else { Vec::new() };
    let archive = out.join(ARCHIVE_FILE);
    let have: std::collections::BTreeSet<_> = runs.iter().map(|(_, r)| run_key(r)).collect();
    for r in read_archive(&archive)? {
        if !have.contains(&run_key(&r)) {
            runs.push((archive.clone(), r));
        }
    }
    if runs.is_empty() {
        return Err(RotestError::Format {
            path: runs_dir.to_path_buf(),
            message: "no run.json below this directory".into(),
        });
    }
    let t = table(&runs);
    std::fs::create_dir_all(out).map_err(at(out))?;
    let md = out.join("rotest.md");
    let text = format!(
        "# Rotation estimation: test accuracy at the best validation epoch\n\n\
         Generated by `equiarm rotest report` from {} run files; mean ± standard error over seeds in %, \
         the number of seeds in parentheses.\n\n{}\n{}",
        runs.len(),
        markdown(&t),
        claims(&t, bounds)
    );
    std::fs::write(&md, text).map_err(at(&md))?;
    let mut kept: Vec<RotestRecord> =
        runs.iter().map(|(_, r)| RotestRecord { history: Vec::new(), ..r.clone() }).collect();
    kept.sort_by_key(run_key);
    let json = serde_json::to_vec_pretty(&kept)
        .map_err(|e| RotestError::Format { path: archive.clone(), message: e.to_string() })?;
    std::fs::write(&archive, json).map_err(at(&archive))?;
    let all = out.join("rotest_overview.png");
    overview(&all, &t, bounds)?;
    let mut files = vec![md, archive, all];
    for (setting, by_var) in &t {
        let p = out.join(format!("rotest_{}.png", setting.replace(',', "+")));
        figure(&p, setting, by_var, bounds.get(setting).copied())?;
        files.push(p);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{EpochRecord, RotestConfig};

    fn record(model: ClassifierKind, n: usize, img_trans: usize, seed: u64, acc: f64) -> RotestRecord {
        let mut config = RotestConfig::paper(model, n, seed);
        config.img_trans = img_trans;
        let e = EpochRecord { epoch: 1, loss: 1.0, train_acc: acc, val_acc: acc, test_acc: Some(acc), seconds: 1.0 };
        RotestRecord {
            config,
            corrupt: "condition_reverse".into(),
            data_seed: 0,
            history: vec![e],
            best_epoch: 1,
            best_val_acc: acc,
            test_acc: acc,
            train_samples: n,
        }
    }

    /// Run files in nested directories are found, grouped by variant and N, and averaged; the
    /// table, the figure and the archive are written, and the archive alone gives the same table;
    /// an empty directory (and no archive) is an error naming it.
    #[test]
    fn report_groups_runs_and_writes_table_and_figure() {
        let root = std::env::temp_dir().join(format!("equiarm_rotest_report_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let runs = [
            ("equi/100/s0", record(ClassifierKind::Equi, 100, 0, 0, 0.5)),
            ("equi/100/s1", record(ClassifierKind::Equi, 100, 0, 1, 0.6)),
            ("cnn/100/s0", record(ClassifierKind::Cnn, 100, 0, 0, 0.7)),
            ("cnn+trans/400/s0", record(ClassifierKind::Cnn, 400, 400, 0, 0.8)),
        ];
        for (dir, r) in &runs {
            let d = root.join("runs").join(dir);
            std::fs::create_dir_all(&d).unwrap();
            std::fs::write(d.join("run.json"), serde_json::to_vec(r).unwrap()).unwrap();
        }
        let out = root.join("out");
        let bounds = BTreeMap::from([("condition_reverse".to_string(), 0.625)]);
        let files = write(&root.join("runs"), &out, &bounds).unwrap();
        assert_eq!(files.len(), 4);
        let md = std::fs::read_to_string(out.join("rotest.md")).unwrap();
        assert!(md.contains("| condition_reverse | 100 | 70.0 (1) | – | 55.0 ± 5.0 (2) |"), "{md}");
        assert!(md.contains("| condition_reverse | 400 | – | 80.0 (1) | – |"), "{md}");
        assert!(md.contains("| 100 | 55.0 ± 5.0 (2): -7.5 | 70.0 (1): +7.5 | – |"), "{md}");
        assert!(
            md.contains("Equi: above the bound at no N; at or under it at N = 100 (-7.5 points, 1.5 s.e.)."),
            "{md}"
        );
        assert!(image::open(out.join("rotest_condition_reverse.png")).is_ok());
        // the overview: one row of five panels under the title
        let all = image::open(out.join("rotest_overview.png")).unwrap();
        assert_eq!((all.width(), all.height()), (5 * 330, 40 + 250));
        // the archive alone (no run directories) gives the same table
        let archived = read_archive(&out.join(ARCHIVE_FILE)).unwrap();
        assert_eq!(archived.len(), 4);
        assert!(archived.iter().all(|r| r.history.is_empty()));
        std::fs::remove_dir_all(root.join("runs")).unwrap();
        write(&root.join("runs"), &out, &bounds).unwrap();
        assert_eq!(std::fs::read_to_string(out.join("rotest.md")).unwrap(), md);
        std::fs::create_dir_all(root.join("empty")).unwrap();
        let e = write(&root.join("empty"), &root.join("out2"), &bounds).unwrap_err().to_string();
        assert!(e.contains("no run.json") && e.contains("empty"), "{e}");
        let _ = std::fs::remove_dir_all(&root);
    }

    /// The claims: differences per setting and N with their standard errors, the cells where Equi
    /// is not ahead, invert-label against its bound (and a missing bound said so), CNN + trans
    /// against Equi.
    #[test]
    fn claims_compare_the_variants_cell_by_cell() {
        let mut runs = Vec::new();
        let mut add = |setting: &str, model, n, img_trans, accs: &[f64]| {
            for (seed, &a) in accs.iter().enumerate() {
                let mut r = record(model, n, img_trans, seed as u64, a);
                r.corrupt = setting.into();
                runs.push((PathBuf::from("x"), r));
            }
        };
        // `none`: Equi clearly ahead at 100, behind at 400; CNN + trans close at 100, far at 400
        add("none", ClassifierKind::Equi, 100, 0, &[0.80, 0.82]);
        add("none", ClassifierKind::Cnn, 100, 0, &[0.40, 0.42]);
        add("none", ClassifierKind::Cnn, 100, 100, &[0.79, 0.83]);
        add("none", ClassifierKind::Equi, 400, 0, &[0.90]);
        add("none", ClassifierKind::Cnn, 400, 0, &[0.95]);
        // `grid`: equal means from different seeds (a tie, whatever the rounding of the sums)
        add("grid", ClassifierKind::Equi, 100, 0, &[0.1, 0.2, 0.3]);
        add("grid", ClassifierKind::Cnn, 100, 0, &[0.3, 0.2, 0.1]);
        add("side,grid", ClassifierKind::Equi, 100, 0, &[0.70, 0.72]);
        add("side,grid", ClassifierKind::Cnn, 100, 0, &[0.50, 0.52]);
        add("side,grid", ClassifierKind::Cnn, 100, 100, &[0.50, 0.52]);
        add("condition_reverse", ClassifierKind::Equi, 1600, 0, &[0.56, 0.62]);
        add("condition_reverse", ClassifierKind::Cnn, 1600, 0, &[0.84, 0.90]);
        let t = table(&runs);
        let bounds = BTreeMap::from([("condition_reverse".to_string(), 0.625)]);
        let c = claims(&t, &bounds);
        assert!(c.contains("| none | +40.0 ± 1.4 | -5.0 |"), "{c}");
        assert!(c.contains("| side,grid | +20.0 ± 1.4 | – |"), "{c}");
        assert!(!c.contains("| condition_reverse |"), "{c}");
        assert!(c.contains("| grid | +0.0 ± 8.2 | – |"), "{c}");
        assert!(c.contains("above the CNN's in 2 of 4 cells (clearly in 2 of the 3"), "{c}");
        assert!(c.contains("not above: `grid` N = 100 (+0.0 ± 8.2), `none` N = 400 (-5.0)."), "{c}");
        assert!(c.contains("Bound 62.5 %. Accuracy, and its distance to the bound in points:\n\n| N | Equi | CNN |\n|---|---|---|\n| 1600 | 59.0 ± 3.0 (2): -3.5 | 87.0 ± 3.0 (2): +24.5 |\n"), "{c}");
        assert!(c.contains("Equi: above the bound at no N; at or under it at N = 1600 (-3.5 points, 1.2 s.e.). CNN: above the bound at N = 1600 (+24.5 points, 8.2 s.e.); at or under it at no N."), "{c}");
        assert!(
            c.contains("| setting | N = 100 |\n|---|---|\n| none | +0.0 ± 2.2 |\n| side,grid | -20.0 ± 1.4 |\n"),
            "{c}"
        );
        assert!(
            c.contains(
                "in 1 of the 2 cells with two seeds or more of both; further apart: `side,grid` N = 100 (-20.0 ± 1.4)."
            ),
            "{c}"
        );
        assert!(c.contains("Mean difference over all 2 cells: -10.0 points."), "{c}");
        let c = claims(&t, &BTreeMap::new());
        assert!(c.contains("The bound is unknown here"), "{c}");
    }
}
