//! The report over many runs: every `run.json` under a directory, grouped by corruption setting,
//! variant (Equi, CNN, CNN + image transformations; "no crop" when random crops were off) and
//! training-set size, as mean ± standard error over seeds; a Markdown table and one PNG per setting
//! (accuracy against the number of training pairs, one line per variant, the invariant-classifier
//! bound as a dashed line where it is below 1).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_train::plot::{ensure_font, mean_se};
use plotters::prelude::*;

use crate::error::{Result, RotestError, io};
use crate::train::{ModelKind, RunRecord};

/// Name of a run's variant: `Equi`, `CNN` or `CNN + trans`, with ` (no crop)` when crops were off.
pub fn variant(r: &RunRecord) -> String {
    let base = match (r.config.model, r.config.img_trans > 0) {
        (ModelKind::Equi, false) => "Equi",
        (ModelKind::Equi, true) => "Equi + trans",
        (ModelKind::Cnn, false) => "CNN",
        (ModelKind::Cnn, true) => "CNN + trans",
    };
    if r.config.crop { base.to_string() } else { format!("{base} (no crop)") }
}

/// Every `run.json` below `dir` (recursively), sorted by path. A file that does not parse is an
/// error naming it.
pub fn collect_runs(dir: &Path) -> Result<Vec<(PathBuf, RunRecord)>> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).map_err(io(&d))? {
            let p = e.map_err(io(&d))?.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n == "run.json") {
                files.push(p);
            }
        }
    }
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let text = std::fs::read(&p).map_err(io(&p))?;
            let r = serde_json::from_slice(&text)
                .map_err(|e| RotestError::Format { path: p.clone(), message: format!("not a run file: {e}") })?;
            Ok((p, r))
        })
        .collect()
}

/// Test accuracies by setting → variant → training pairs.
pub type Table = BTreeMap<String, BTreeMap<String, BTreeMap<usize, Vec<f64>>>>;

/// Groups runs into a [`Table`].
pub fn table(runs: &[(PathBuf, RunRecord)]) -> Table {
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
    t
}

/// The Markdown table: one row per setting and training size, one column per variant, cells
/// `mean ± s.e. (seeds)` in percent.
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
                    Some(acc) => {
                        let (m, se) = mean_se(acc);
                        format!("{:.1} ± {:.1} ({})", 100.0 * m, 100.0 * se, acc.len())
                    }
                    None => "–".into(),
                })
                .collect();
            s += &format!("| {setting} | {n} | {} |\n", cells.join(" | "));
        }
    }
    s
}

/// One PNG: accuracy (%) against training pairs (log scale) for each variant of `setting`, error bars of one
/// s.e.; `bound` (if below 1) as a dashed line.
pub fn figure(
    path: &Path,
    setting: &str,
    by_var: &BTreeMap<String, BTreeMap<usize, Vec<f64>>>,
    bound: Option<f64>,
) -> Result<()> {
    let err = |m: String| RotestError::Image { path: path.to_path_buf(), message: m };
    ensure_font().map_err(|e| err(e.to_string()))?;
    let (w, h) = (640u32, 420u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        // The sizes that were run, sorted and once each: the axis's ticks (the log scale's own ticks
        // crowd into each other once N spans more than a decade).
        let ns: Vec<usize> = by_var
            .values()
            .flat_map(|m| m.keys().copied())
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let (lo, hi) = (ns.first().copied().unwrap_or(1) as f64, ns.last().copied().unwrap_or(1) as f64);
        // Logarithmic N axis with a margin of 20 % on both sides (N = 100, 400, 1600 evenly spaced).
        let (x0, x1) = (lo.max(1.0) / 1.25, hi.max(1.0) * 1.25);
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("rotation estimation: {setting}"), ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(
                (x0..x1).log_scale().with_key_points(ns.iter().map(|&n| n as f64).collect()),
                0f64..100f64,
            )
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.0}"))
            .x_desc("training pairs N (log scale)")
            .y_desc("test accuracy (%)")
            .draw()
            .map_err(|e| err(e.to_string()))?;
        let colors = [RGBColor(200, 60, 40), RGBColor(40, 90, 200), RGBColor(40, 150, 70), RGBColor(140, 80, 160)];
        for (k, (v, by_n)) in by_var.iter().enumerate() {
            let c = colors[k % colors.len()];
            let pts: Vec<(f64, f64, f64)> = by_n
                .iter()
                .map(|(n, a)| {
                    let (m, se) = mean_se(a);
                    (*n as f64, 100.0 * m, 100.0 * se)
                })
                .collect();
            chart
                .draw_series(std::iter::once(PathElement::new(
                    pts.iter().map(|p| (p.0, p.1)).collect::<Vec<_>>(),
                    c.stroke_width(2),
                )))
                .map_err(|e| err(e.to_string()))?
                .label(v.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
            // error bars of one s.e. and a dot at each mean
            chart
                .draw_series(pts.iter().map(|p| PathElement::new(vec![(p.0, p.1 - p.2), (p.0, p.1 + p.2)], c)))
                .map_err(|e| err(e.to_string()))?;
            chart
                .draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 3, c.filled())))
                .map_err(|e| err(e.to_string()))?;
        }
        if let Some(b) = bound.filter(|b| *b < 1.0) {
            let y = 100.0 * b;
            // dashed: 40 dashes, evenly spaced on the log axis
            let at = |t: f64| x0 * (x1 / x0).powf(t / 80.0);
            chart
                .draw_series(
                    (0..40)
                        .map(|k| PathElement::new(vec![(at(2.0 * k as f64), y), (at(2.0 * k as f64 + 1.0), y)], BLACK)),
                )
                .map_err(|e| err(e.to_string()))?;
            chart
                .draw_series(std::iter::once(PathElement::new(vec![(x0, y), (x0, y)], BLACK)))
                .map_err(|e| err(e.to_string()))?
                .label(format!("invariant bound {y:.1} %"))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| err(e.to_string()))?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| err("buffer size".into()))?;
    img.save(path).map_err(|e| err(e.to_string()))
}

/// The archive a report writes beside its table: every run's record without its epoch history
/// (a few hundred bytes a run). Committed with the report, it lets a checkout on another machine
/// skip those runs (`rotest grid`) and draw them again (`rotest report`).
pub const ARCHIVE_FILE: &str = "rotest_runs.json";

/// The key that names a run in the grid: setting, variant, training pairs, seed.
pub fn run_key(r: &RunRecord) -> (String, String, usize, u64) {
    (r.corrupt.clone(), variant(r), r.config.train_pairs, r.config.seed)
}

/// The archived runs in `path` (none if the file does not exist).
pub fn read_archive(path: &Path) -> Result<Vec<RunRecord>> {
    if !path.is_file() {
        return Ok(Vec::new());
    }
    let text = std::fs::read(path).map_err(io(path))?;
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
    std::fs::create_dir_all(out).map_err(io(out))?;
    let md = out.join("rotest.md");
    let text = format!(
        "# Rotation estimation: test accuracy at the best validation epoch\n\n\
         Generated by `equiarm rotest report` from {} run files; mean ± standard error over seeds in %, \
         the number of seeds in parentheses.\n\n{}",
        runs.len(),
        markdown(&t)
    );
    std::fs::write(&md, text).map_err(io(&md))?;
    let mut kept: Vec<RunRecord> = runs.iter().map(|(_, r)| RunRecord { history: Vec::new(), ..r.clone() }).collect();
    kept.sort_by_key(run_key);
    let json = serde_json::to_vec_pretty(&kept)
        .map_err(|e| RotestError::Format { path: archive.clone(), message: e.to_string() })?;
    std::fs::write(&archive, json).map_err(io(&archive))?;
    let mut files = vec![md, archive];
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
    use crate::train::{EpochRecord, TrainConfig};

    fn record(model: ModelKind, n: usize, img_trans: usize, seed: u64, acc: f64) -> RunRecord {
        let mut config = TrainConfig::paper(model, n, seed);
        config.img_trans = img_trans;
        let e = EpochRecord { epoch: 1, loss: 1.0, train_acc: acc, val_acc: acc, test_acc: Some(acc), seconds: 1.0 };
        RunRecord {
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
            ("equi/100/s0", record(ModelKind::Equi, 100, 0, 0, 0.5)),
            ("equi/100/s1", record(ModelKind::Equi, 100, 0, 1, 0.6)),
            ("cnn/100/s0", record(ModelKind::Cnn, 100, 0, 0, 0.7)),
            ("cnn+trans/400/s0", record(ModelKind::Cnn, 400, 400, 0, 0.8)),
        ];
        for (dir, r) in &runs {
            let d = root.join("runs").join(dir);
            std::fs::create_dir_all(&d).unwrap();
            std::fs::write(d.join("run.json"), serde_json::to_vec(r).unwrap()).unwrap();
        }
        let out = root.join("out");
        let bounds = BTreeMap::from([("condition_reverse".to_string(), 0.625)]);
        let files = write(&root.join("runs"), &out, &bounds).unwrap();
        assert_eq!(files.len(), 3);
        let md = std::fs::read_to_string(out.join("rotest.md")).unwrap();
        assert!(md.contains("| condition_reverse | 100 | 70.0 ± 0.0 (1) | – | 55.0 ± 5.0 (2) |"), "{md}");
        assert!(md.contains("| condition_reverse | 400 | – | 80.0 ± 0.0 (1) | – |"), "{md}");
        assert!(image::open(out.join("rotest_condition_reverse.png")).is_ok());
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
}
