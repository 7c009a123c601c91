//! Plot the evaluation curves of several runs in one PNG, grouped by label with mean ± standard
//! error over the runs of a group (the paper's plots), and print a table of the final values.
//!
//! `cargo run -p equiarm_train --example compare_runs -- OUT.png [--metric success_rate|discounted_return]
//!   LABEL=RUN_DIR[,RUN_DIR...] ...`
//!
//! Each RUN_DIR is a training run directory with `evals.json` (written by `equiarm train`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clap::{Parser, ValueEnum};
use equiarm_train::evaluation::EvalResult;
use equiarm_train::plot::{Chart, Series, palette, write_png};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
#[value(rename_all = "snake_case")]
enum Metric {
    SuccessRate,
    DiscountedReturn,
}

impl Metric {
    fn name(self) -> &'static str {
        match self {
            Metric::SuccessRate => "success_rate",
            Metric::DiscountedReturn => "discounted_return",
        }
    }

    fn pick(self, e: &EvalResult) -> f64 {
        match self {
            Metric::SuccessRate => e.success_rate,
            Metric::DiscountedReturn => e.discounted_return,
        }
    }
}

/// A `LABEL=RUN_DIR[,RUN_DIR...]` argument.
#[derive(Clone, Debug)]
struct Group {
    label: String,
    dirs: Vec<PathBuf>,
}

fn parse_group(s: &str) -> anyhow::Result<Group> {
    let bad = || anyhow::anyhow!("expected LABEL=RUN_DIR[,RUN_DIR...], got `{s}`");
    let (label, dirs) = s.split_once('=').ok_or_else(bad)?;
    if label.is_empty() || dirs.is_empty() {
        return Err(bad());
    }
    Ok(Group { label: label.to_string(), dirs: dirs.split(',').map(PathBuf::from).collect() })
}

/// Evaluation curves of several runs, mean ± standard error per group, in one PNG.
#[derive(Parser, Debug)]
#[command(name = "compare_runs")]
struct Args {
    /// The PNG to write.
    out: PathBuf,
    /// The evaluation value plotted and tabulated.
    #[arg(long, value_enum, default_value_t = Metric::SuccessRate)]
    metric: Metric,
    /// Run directories (with `evals.json`) grouped under a legend label.
    #[arg(value_name = "LABEL=RUN_DIR[,RUN_DIR...]", required = true, value_parser = parse_group)]
    groups: Vec<Group>,
}

fn main() {
    let args = Args::parse();
    let metric = args.metric.name();
    let mut series = Vec::new();
    let lw = args.groups.iter().map(|g| g.label.chars().count()).max().unwrap_or(0).max(12);
    println!("{:<lw$} {:>5} {:>9} {:>14} {:>10}", "label", "runs", "updates", metric, "stderr");
    for (gi, Group { label, dirs }) in args.groups.iter().enumerate() {
        let mut by_step: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
        for d in dirs {
            let path = Path::new(d).join("evals.json");
            let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let evals: Vec<EvalResult> =
                serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            for e in &evals {
                by_step.entry(e.updates).or_default().push(args.metric.pick(e));
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
            println!("{label:<lw$} {:>5} {:>9} {:>14.3} {:>10.3}", dirs.len(), u, m, se);
        }
        series.push(Series {
            label: format!("{label} ({} seed{})", dirs.len(), if dirs.len() == 1 { "" } else { "s" }),
            color: palette(gi),
            points: stats.iter().map(|s| (s.0, s.1)).collect(),
            band: Some(stats.iter().map(|s| s.2).collect()),
            bars: false,
        });
    }
    let chart = Chart {
        title: format!("greedy evaluation {metric} (mean ± standard error over seeds)"),
        x_label: "gradient updates".into(),
        y_label: metric.to_string(),
        y_range: Some((0.0, 1.0)),
        ..Chart::default()
    };
    write_png(&args.out, &chart, &series).unwrap_or_else(|e| panic!("{e}"));
    println!("wrote {}", args.out.display());
}
