//! The claims table: each claim of the paper that a grid tests, checked on the archived runs of the
//! grid pages (`docs/results/GRID/runs.json`), worded by its statistic. The claims are written in a
//! TOML file (`docs/results/claims.toml`):
//!
//! ```toml
//! [[claim]]
//! claim = "Equi SAC beats CNN SAC on block pulling"
//! paper = "0.87 against 0.53"
//! test = "ahead"                                   # a above b; or "level"
//! a = "tasks:block_pulling/equi/side/none"         # GRID:the run path without its seed
//! b = "tasks:block_pulling/cnn/side/none"
//! a_label = "Equi SAC"                             # (default: the variant's label)
//! ```
//!
//! The statistic is the paper's: the discounted return of the final weights over the held-out
//! episodes, mean ± standard error over seeds, success rate beside it. `a` is clearly ahead of `b`
//! when the difference of the means exceeds two standard errors of the difference
//! (√(se_a² + se_b²)); level when it is within them. Below three seeds on either side no standard
//! error is printed and the verdict stays open.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_train::plot::mean_se;
use equiarm_types::files::{at, replace};
use serde::Deserialize;

use crate::error::{ExperimentError, Result};
use crate::grid::Variant;
use crate::report::{self, ARCHIVE_FILE, Archived, MIN_SEEDS_FOR_SE};

/// Where the claims table starts and ends in the page it is written into.
pub const BEGIN: &str = "<!-- claims table: begin (written by `equiarm experiment claims`) -->";
/// See [`BEGIN`].
pub const END: &str = "<!-- claims table: end -->";

/// The claims file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ClaimsFile {
    claim: Vec<Claim>,
}

/// What the data must show for a claim to hold.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum Test {
    /// `a` above `b` by more than two standard errors of the difference.
    Ahead,
    /// `a` and `b` within two standard errors of the difference.
    Level,
}

/// One claim of the paper and the two groups of runs that test it.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Claim {
    /// The claim, in the paper's words or close to them.
    pub claim: String,
    /// The paper's figures for it.
    pub paper: String,
    /// What the data must show.
    pub test: Test,
    /// `GRID:task/variant/view/corruption`: the runs of that cell in the grid's archive.
    pub a: CellRef,
    /// As `a`.
    pub b: CellRef,
    /// The name `a` goes by in the table (default: its variant's label).
    #[serde(default)]
    pub a_label: Option<String>,
    /// As `a_label`.
    #[serde(default)]
    pub b_label: Option<String>,
}

/// The held-out results of one cell's finished runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Side {
    /// Discounted return per seed.
    pub discounted_return: Vec<f64>,
    /// Success rate per seed.
    pub success: Vec<f64>,
}

/// A claim's cell reference, `GRID:task/variant/view/corruption`: a grid and a run path without its
/// seed (read once, from the claims file).
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub struct CellRef {
    /// The grid whose archive holds the runs.
    pub grid: String,
    /// `task/variant/view/corruption`.
    pub cell: String,
}

impl CellRef {
    /// The cell's model variant (its second part).
    pub fn variant(&self) -> &str {
        self.cell.split('/').nth(1).unwrap_or_default()
    }
}

impl TryFrom<String> for CellRef {
    type Error = String;
    fn try_from(r: String) -> std::result::Result<Self, String> {
        let bad = || format!("`{r}`: expected GRID:task/variant/view/corruption");
        let (grid, cell) = r.split_once(':').ok_or_else(bad)?;
        if grid.is_empty() || cell.split('/').count() != 4 || cell.split('/').any(str::is_empty) {
            return Err(bad());
        }
        Ok(CellRef { grid: grid.to_string(), cell: cell.to_string() })
    }
}

/// The finished runs of `cell` in `runs` (one grid's archive).
pub fn side(runs: &[Archived], cell: &str) -> Side {
    let mut out = Side::default();
    let mut of_cell: Vec<&Archived> = runs.iter().filter(|a| a.run.parent() == Some(Path::new(cell))).collect();
    of_cell.sort_by_key(|a| a.config.seed);
    for a in of_cell {
        out.discounted_return.push(a.result.heldout.discounted_return);
        out.success.push(a.result.heldout.success_rate);
    }
    out
}

/// A mean over seeds as the table prints it (as the grid pages do), with the seed count.
fn stat(v: &[f64]) -> String {
    match v.len() {
        0 => "no finished run".to_string(),
        1 => format!("{} (1 seed)", report::stat(v)),
        n => format!("{} ({n} seeds)", report::stat(v)),
    }
}

/// The verdict on `test` for `a` against `b` (discounted returns per seed).
pub fn verdict(test: Test, a: &[f64], b: &[f64]) -> String {
    if a.is_empty() || b.is_empty() {
        return "not run yet".to_string();
    }
    let ((ma, sa), (mb, sb)) = (mean_se(a), mean_se(b));
    let d = ma - mb;
    if a.len() < MIN_SEEDS_FOR_SE || b.len() < MIN_SEEDS_FOR_SE {
        let dir = if d >= 0.0 { "ahead" } else { "behind" };
        return format!("open: fewer than three seeds ({dir} by {:.2})", d.abs());
    }
    let se = (sa * sa + sb * sb).sqrt();
    // how many standard errors of the difference apart (a tie of identical seeds is 0)
    let z = if se > 0.0 {
        d / se
    } else if d == 0.0 {
        0.0
    } else {
        d.signum() * f64::INFINITY
    };
    let apart = if z.is_finite() { format!("{:.1} s.e. of the difference", z.abs()) } else { "no spread".to_string() };
    match test {
        Test::Ahead if z > 2.0 => format!("**reproduced**: ahead by {d:.2}, {apart}"),
        Test::Ahead if z >= -2.0 => {
            format!("not clear: {} by {:.2}, {apart}", if d >= 0.0 { "ahead" } else { "behind" }, d.abs())
        }
        Test::Ahead => format!("**contradicted**: behind by {:.2}, {apart}", d.abs()),
        Test::Level if z.abs() <= 2.0 => format!("**reproduced**: {:.2} apart, {apart}", d.abs()),
        Test::Level => format!("**not reproduced**: {:.2} apart, {apart}", d.abs()),
    }
}

/// The claims of a claims file, each cell reference checked for its form.
pub fn read(claims_file: &Path) -> Result<Vec<Claim>> {
    let text = std::fs::read_to_string(claims_file).map_err(at(claims_file))?;
    let file: ClaimsFile = toml::from_str(&text)
        .map_err(|e| ExperimentError::Claims { path: claims_file.to_path_buf(), message: e.to_string() })?;
    Ok(file.claim)
}

/// The claims of `claims_file` checked on the archives below `archive_dir`, as a Markdown table.
pub fn table(claims_file: &Path, archive_dir: &Path) -> Result<String> {
    let claims = read(claims_file)?;
    let mut archives: BTreeMap<String, Vec<Archived>> = BTreeMap::new();
    let mut md = String::from(
        "| claim | the paper | ours: held-out discounted return, mean ± s.e. (success rate) | verdict |\n|---|---|---|---|\n",
    );
    for c in &claims {
        let mut cells = Vec::new();
        for (r, label) in [(&c.a, &c.a_label), (&c.b, &c.b_label)] {
            if !archives.contains_key(&r.grid) {
                let f = archive_dir.join(&r.grid).join(ARCHIVE_FILE);
                let runs: Vec<Archived> = if f.is_file() { equiarm_sac::learner::read_json(&f)? } else { Vec::new() };
                archives.insert(r.grid.clone(), runs);
            }
            let s = side(&archives[&r.grid], &r.cell);
            let variant = r.variant();
            let label = label.clone().unwrap_or_else(|| Variant::by_name(variant).map_or(variant, |v| v.label).into());
            cells.push((label, s));
        }
        let (la, a) = &cells[0];
        let (lb, b) = &cells[1];
        let succ =
            |s: &Side| if s.success.is_empty() { "–".to_string() } else { format!("{:.2}", mean_se(&s.success).0) };
        md += &format!(
            "| {} | {} | {la} {} against {lb} {} (success {} against {}) | {} |\n",
            c.claim,
            c.paper,
            stat(&a.discounted_return),
            stat(&b.discounted_return),
            succ(a),
            succ(b),
            verdict(c.test, &a.discounted_return, &b.discounted_return)
        );
    }
    Ok(md)
}

/// Writes the claims table into `page` between [`BEGIN`] and [`END`]; returns the page's path.
pub fn write(claims_file: &Path, archive_dir: &Path, page: &Path) -> Result<PathBuf> {
    let md = table(claims_file, archive_dir)?;
    let text = std::fs::read_to_string(page).map_err(at(page))?;
    let missing = || ExperimentError::Claims {
        path: page.to_path_buf(),
        message: format!("no claims table markers: put the lines `{BEGIN}` and `{END}` where the table goes"),
    };
    let start = text.find(BEGIN).ok_or_else(missing)? + BEGIN.len();
    let end = start + text[start..].find(END).ok_or_else(missing)?;
    let new = format!("{}\n\n{md}\n{}", &text[..start], &text[end..]);
    replace(page, new)?;
    Ok(page.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_follow_two_standard_errors_of_the_difference() {
        let a = [0.80, 0.82, 0.84, 0.86];
        let b = [0.50, 0.55, 0.60, 0.52];
        assert!(verdict(Test::Ahead, &a, &b).starts_with("**reproduced**: ahead by 0.29"));
        assert!(verdict(Test::Ahead, &b, &a).starts_with("**contradicted**"));
        assert!(verdict(Test::Level, &a, &b).starts_with("**not reproduced**"));
        let c = [0.78, 0.86, 0.80, 0.90];
        assert!(verdict(Test::Ahead, &a, &c).starts_with("not clear: behind by 0.01"));
        assert!(verdict(Test::Level, &a, &c).starts_with("**reproduced**: 0.01 apart"));
        // two seeds decide nothing, however far apart
        assert!(verdict(Test::Ahead, &a[..2], &b).starts_with("open: fewer than three seeds (ahead by"));
        assert_eq!(verdict(Test::Ahead, &[], &b), "not run yet");
        // identical seeds: no spread, yet a difference is a difference
        assert!(verdict(Test::Ahead, &[0.5; 3], &[0.4; 3]).starts_with("**reproduced**"));
        assert!(verdict(Test::Level, &[0.5; 3], &[0.5; 3]).starts_with("**reproduced**: 0.00 apart"));
    }

    #[test]
    fn a_side_is_the_finished_seeds_of_its_cell_in_seed_order() {
        use equiarm_sac::config::TrainConfig;
        let run = |path: &str, seed: u64, r: f64| {
            let mut config = TrainConfig::reduced16(equiarm_types::TaskKind::BlockPulling);
            config.seed = seed;
            Archived {
                run: PathBuf::from(path),
                config,
                evals: Vec::new(),
                result: crate::runner::test_result(r / 2.0, r),
            }
        };
        let runs = [
            run("block_pulling/equi/side/none/s1", 1, 0.7),
            run("block_pulling/cnn/side/none/s0", 0, 0.3),
            run("block_pulling/equi/side/none/s0", 0, 0.8),
            run("block_pulling/equi/side-arm/none/s2", 2, 0.1),
        ];
        let s = side(&runs, "block_pulling/equi/side/none");
        assert_eq!(s.discounted_return, [0.8, 0.7]);
        assert_eq!(s.success, [0.4, 0.35]);
        assert_eq!(side(&runs, "block_pulling/equi/side").discounted_return, Vec::<f64>::new());
    }

    #[test]
    fn cell_references_name_a_grid_and_four_path_parts() {
        let r = CellRef::try_from("tasks:block_pulling/equi/side/none".to_string()).unwrap();
        assert_eq!((r.grid.as_str(), r.cell.as_str(), r.variant()), ("tasks", "block_pulling/equi/side/none", "equi"));
        for bad in ["block_pulling/equi/side/none", "tasks:block_pulling/equi/side", ":a/b/c/d", "t:a//c/d"] {
            let e = CellRef::try_from(bad.to_string()).unwrap_err();
            assert!(e.contains("expected GRID:task/variant/view/corruption"), "{bad}");
        }
    }

    #[test]
    fn the_table_goes_between_the_markers_and_nothing_else_changes() {
        let dir = std::env::temp_dir().join(format!("equiarm_claims_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("g")).unwrap();
        let claims = dir.join("claims.toml");
        std::fs::write(
            &claims,
            "[[claim]]\nclaim = \"A beats B\"\npaper = \"0.9 against 0.5\"\ntest = \"ahead\"\n\
             a = \"g:block_pulling/equi/side/none\"\nb = \"g:block_pulling/cnn/side/none\"\n",
        )
        .unwrap();
        std::fs::write(dir.join("g").join(ARCHIVE_FILE), "[]").unwrap();
        let page = dir.join("README.md");
        std::fs::write(&page, format!("# R\n\nbefore\n{BEGIN}\nold table\n{END}\nafter\n")).unwrap();
        write(&claims, &dir, &page).unwrap();
        let text = std::fs::read_to_string(&page).unwrap();
        assert!(text.starts_with(&format!("# R\n\nbefore\n{BEGIN}\n\n| claim |")), "{text}");
        assert!(text.ends_with(&format!("{END}\nafter\n")), "{text}");
        assert!(!text.contains("old table"));
        assert!(text.contains(
            "| A beats B | 0.9 against 0.5 | Equi SAC + RAD no finished run against CNN SAC + RAD no finished run"
        ));
        assert!(text.contains("| not run yet |"));
        // a page without the markers is refused, and left as it was
        std::fs::write(&page, "# R\n").unwrap();
        let e = write(&claims, &dir, &page).unwrap_err().to_string();
        assert!(e.contains("README.md") && e.contains("no claims table markers"), "{e}");
        assert_eq!(std::fs::read_to_string(&page).unwrap(), "# R\n");
        // a claim with a bad reference is named
        std::fs::write(
            &claims,
            "[[claim]]\nclaim = \"X\"\npaper = \"p\"\ntest = \"ahead\"\na = \"g:x\"\nb = \"g:x\"\n",
        )
        .unwrap();
        let e = table(&claims, &dir).unwrap_err().to_string();
        assert!(e.contains("claims.toml") && e.contains("line 5") && e.contains("`g:x`: expected GRID:"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
