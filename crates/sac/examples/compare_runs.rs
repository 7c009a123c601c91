//! Plot the evaluation curves of several runs in one PNG, grouped by label with mean ± standard
//! error over the runs of a group (the paper's plots), and print a table of the final values.
//!
//! `cargo run -p equiarm_sac --example compare_runs -- OUT.png [--metric success_rate|discounted_return]
//!   LABEL=RUN_DIR[,RUN_DIR...] ...`
//!
//! Each RUN_DIR is a training run directory with `evals.json` (written by `equiarm train`).

use std::collections::BTreeMap;
use std::path::Path;

use equiarm_sac::plot::{Chart, Series, palette, write_png};
use equiarm_sac::train::EvalResult;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() {
        eprintln!("usage: compare_runs OUT.png [--metric success_rate|discounted_return] LABEL=RUN[,RUN...] ...");
        std::process::exit(2);
    }
    let out = Path::new(&args[0]);
    let mut metric = "success_rate".to_string();
    let mut groups: Vec<(String, Vec<String>)> = Vec::new();
    let mut i = 1;
    while i < args.len() {
        if args[i] == "--metric" {
            metric = args.get(i + 1).cloned().unwrap_or_default();
            i += 2;
            continue;
        }
        let Some((label, dirs)) = args[i].split_once('=') else {
            eprintln!("expected LABEL=RUN_DIR[,RUN_DIR...], got `{}`", args[i]);
            std::process::exit(2);
        };
        groups.push((label.to_string(), dirs.split(',').map(String::from).collect()));
        i += 1;
    }
    let pick = |e: &EvalResult| if metric == "discounted_return" { e.discounted_return } else { e.success_rate };
    let mut series = Vec::new();
    println!("{:<12} {:>5} {:>9} {:>14} {:>10}", "label", "runs", "updates", &metric, "stderr");
    for (gi, (label, dirs)) in groups.iter().enumerate() {
        let mut by_step: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
        for d in dirs {
            let path = Path::new(d).join("evals.json");
            let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let evals: Vec<EvalResult> =
                serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            for e in &evals {
                by_step.entry(e.updates).or_default().push(pick(e));
            }
        }
        let full: Vec<(u64, Vec<f64>)> = by_step.into_iter().filter(|(_, v)| v.len() == dirs.len()).collect();
        let stats: Vec<(f64, f64, f64)> = full
            .iter()
            .map(|(u, v)| {
                let n = v.len() as f64;
                let m = v.iter().sum::<f64>() / n;
                let sd =
                    if v.len() > 1 { (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() } else { 0.0 };
                (*u as f64, m, sd / n.sqrt())
            })
            .collect();
        if let Some(&(u, m, se)) = stats.last() {
            println!("{label:<12} {:>5} {:>9} {:>14.3} {:>10.3}", dirs.len(), u, m, se);
        }
        series.push(Series {
            label: format!("{label} ({} seeds)", dirs.len()),
            color: palette(gi),
            points: stats.iter().map(|s| (s.0, s.1)).collect(),
            band: Some(stats.iter().map(|s| s.2).collect()),
        });
    }
    let chart = Chart {
        title: format!("greedy evaluation {metric} (mean +/- standard error over seeds)"),
        x_label: "gradient updates".into(),
        y_label: metric.clone(),
        y_range: Some((0.0, 1.0)),
        ..Chart::default()
    };
    write_png(out, &chart, &series).unwrap_or_else(|e| panic!("{e}"));
    println!("wrote {}", out.display());
}
