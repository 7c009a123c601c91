//! The fuzz program end to end: a target that fails on purpose has each failure caught, reported
//! in one line and its input saved; a clean run exits 0 with its figures.

use std::process::Command;

fn fuzz(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_equiarm_fuzz")).args(args).output().expect("running equiarm_fuzz");
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned())
}

#[test]
fn panics_aborts_allocation_failures_and_hangs_are_caught_and_their_inputs_saved() {
    let dir = tempfile::tempdir().unwrap();
    let crashes = dir.path().to_str().unwrap();
    let (ok, out) = fuzz(&["selftest", "--execs", "5", "--time-limit-s", "1", "--crash-dir", crashes]);
    assert!(!ok, "a run with failures must exit non-zero:\n{out}");
    for (index, what) in [(1, "panic: "), (2, "abort: "), (3, "abort: "), (4, "hang")] {
        let line = out
            .lines()
            .find(|l| l.starts_with(&format!("CRASH selftest input {index}: ")))
            .unwrap_or_else(|| panic!("no line for input {index}:\n{out}"));
        assert!(line.contains(what), "{line}");
    }
    assert!(out.contains("selftest panics"), "the panic message is reported:\n{out}");
    assert!(out.contains("memory allocation of"), "the allocation failure is reported:\n{out}");
    for (index, input) in [(1, "panic"), (2, "abort"), (3, "alloc"), (4, "hang")] {
        let saved = std::fs::read(dir.path().join(format!("selftest-{index}.bin"))).unwrap();
        assert_eq!(saved, input.as_bytes());
    }
    assert!(!dir.path().join("selftest-0.bin").exists());
    let row: Vec<&str> =
        out.lines().find(|l| l.starts_with("selftest ")).expect("a table row").split_whitespace().collect();
    assert_eq!((row[1], row[2], row[5]), ("5", "1", "4"), "execs, accepted, crashes: {row:?}");
}

#[test]
fn a_clean_run_exits_zero_with_its_figures() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, out) = fuzz(&["cli_values", "--execs", "3000", "--crash-dir", dir.path().to_str().unwrap()]);
    assert!(ok, "{out}");
    let row: Vec<&str> =
        out.lines().find(|l| l.starts_with("cli_values ")).expect("a table row").split_whitespace().collect();
    assert_eq!((row[1], row[5]), ("3000", "0"), "{row:?}");
    let accepted: u64 = row[2].parse().unwrap();
    assert!((8..3000).contains(&accepted), "the seeds pass and most mutants are refused: {accepted}");
}

#[test]
fn targets_run_in_parallel_give_the_same_table_in_the_same_order() {
    let dir = tempfile::tempdir().unwrap();
    let crashes = dir.path().to_str().unwrap();
    let rows = |jobs: &str| {
        let (ok, out) = fuzz(&["all", "--execs", "20", "--jobs", jobs, "--crash-dir", crashes]);
        assert!(ok, "--jobs {jobs}:\n{out}");
        // name, execs, accepted, crashes: everything but the times
        out.lines()
            .skip(1)
            .map(|l| {
                let f: Vec<&str> = l.split_whitespace().collect();
                assert_eq!(f.len(), 6, "a table row: {l}");
                format!("{} {} {} {}", f[0], f[1], f[2], f[5])
            })
            .collect::<Vec<_>>()
    };
    let (one, three) = (rows("1"), rows("3"));
    let names: Vec<&str> = one.iter().map(|r| r.split(' ').next().unwrap()).collect();
    assert!(names.len() > 3 && names.contains(&"bag_recover") && names.contains(&"cli_values"), "{names:?}");
    assert_eq!(one, three, "the inputs and the table's order do not depend on --jobs");
    let (ok, _) = fuzz(&["all", "--execs", "1", "--jobs", "0"]);
    assert!(!ok, "--jobs 0 is refused");
}
