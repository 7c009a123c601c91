//! The grids of `experiments/`: each reads and checks, and a run two grids have in common (same
//! directory) has the same config in both, so that it is made once.

use std::collections::BTreeMap;
use std::path::PathBuf;

use equiarm_experiment::grid::Grid;

#[test]
fn every_grid_reads_and_shared_runs_agree() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 4, "{files:?}");
    // Keyed by (runs directory, run directory): a grid with its own `runs` shares nothing.
    let mut seen: BTreeMap<(Option<PathBuf>, PathBuf), (String, String)> = BTreeMap::new();
    let mut shared = 0;
    for f in &files {
        let g = Grid::read(f).unwrap_or_else(|e| panic!("{e}"));
        for c in g.cells() {
            let cfg = serde_json::to_string(&g.config(c).unwrap()).unwrap();
            let key = (g.runs.clone(), c.rel_dir());
            if let Some((other, other_cfg)) = seen.get(&key) {
                assert_eq!(&cfg, other_cfg, "{} differs between {other} and {}", c.rel_dir().display(), g.name);
                shared += 1;
            } else {
                seen.insert(key, (g.name.clone(), cfg));
            }
        }
    }
    assert!(shared > 0, "the baselines and reflection grids share the tasks grid's runs");
}

/// Every cell a claim of docs/results/claims.toml compares is a cell of the grid it names, so that
/// a claim never reads "not run yet" for want of a typo.
#[test]
fn every_claim_names_cells_of_its_grids() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let claims = equiarm_experiment::claims::read(&root.join("docs/results/claims.toml")).unwrap();
    assert!(claims.len() >= 10, "{} claims", claims.len());
    for c in &claims {
        for r in [&c.a, &c.b] {
            let (grid, cell) = (&r.grid, &r.cell);
            let g = Grid::read(&root.join("experiments").join(format!("{grid}.toml")))
                .unwrap_or_else(|e| panic!("claim {}: {e}", c.claim));
            let cells: Vec<PathBuf> = g.cells().iter().map(|x| x.rel_dir()).collect();
            assert!(
                cells.iter().any(|d| d.parent() == Some(std::path::Path::new(cell.as_str()))),
                "claim {}: {cell} is not a cell of grid {grid}",
                c.claim
            );
        }
    }
}
