#!/usr/bin/env bash
# The short form of every benchmark and example (issue 62): each program built in the test build and
# run for a few steps, without its Python peer, so one that no longer builds or dies at run time fails
# the test command instead of rotting. Figures printed here mean nothing (debug build, few reps);
# the benchmarks proper are `bash bench/*.sh` and `cargo bench` (docs/benchmarks.md).
#
# Run by tests/run_all.sh after the build; also on its own: `bash tests/bench_smoke.sh`.
# The DDS programs (the recorder-load benchmark, the sim-node example) run inside a private network
# namespace, as the DDS tests do (tests/netns.sh).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
source launch_scripts/lib.sh
features=("${EQA_FEATURES[@]}")
source tests/netns.sh
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cargo_test=(cargo test --locked --offline --workspace "${features[@]}" --quiet)
smoke() { # NAME cmd...: runs cmd, prints one line with its time, fails the script if it fails
  local name=$1 t0=$SECONDS
  shift
  if ! "$@" >"$tmp/out" 2>&1; then
    cat "$tmp/out" >&2
    echo "bench smoke: $name FAILED" >&2
    return 1
  fi
  echo "  $name: ok ($((SECONDS - t0)) s)"
}

# Benchmarks (harness = false: cargo test runs each main with the arguments after --).
smoke "bench step_render" "${cargo_test[@]}" --bench step_render -- --steps 3 --rounds 1 --envs 2 --vec-steps 60
smoke "bench cdr" "${cargo_test[@]}" --bench cdr -- --rounds 1 --iters 2
smoke "bench write" "${cargo_test[@]}" --bench write -- 10 1
smoke "bench actors" "${cargo_test[@]}" --bench actors -- --reps 1 --config reduced --mode fwd_b1 --no-peer
smoke "bench update" "${cargo_test[@]}" --bench update -- --reps 1 --config reduced16 --threads 1 --no-peer
smoke "bench record_load" "${ns[@]}" bash -c "$netup; exec ${cargo_test[*]} --bench record_load -- 2 10 1"

# Examples: the ones that need no run directory run briefly; the rest are built by the test build.
ex="$CARGO_TARGET_DIR/debug/examples"
smoke "example snapshot" "$ex/snapshot" "$tmp/snap" block_pulling 0 2 angle45
smoke "example expert_success" "$ex/expert_success" 2 block_pushing
smoke "example init_scale" "$ex/init_scale"
smoke "example bc_check" "$ex/bc_check" 1 2
smoke "example sim_node_bench" "${ns[@]}" bash -c "$netup; ROS_DOMAIN_ID=77 exec $ex/sim_node_bench 20 block_picking"

# Scripts under bench/: their syntax (they build and run the programs above in their long form).
for f in bench/*.sh; do smoke "syntax $f" bash -n "$f"; done
# (parsed, not compiled: nothing is written into the clone)
for f in bench/*.py; do smoke "syntax $f" python3 -c 'import ast, sys; ast.parse(open(sys.argv[1]).read(), sys.argv[1])' "$f"; done
