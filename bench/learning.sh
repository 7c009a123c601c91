#!/usr/bin/env bash
# Learning benchmark (issue: learning): Equi SAC and CNN SAC on block pulling with the reduced CPU
# config, 2 seeds each, in-process, then one PNG with both curves (mean ± standard error over seeds)
# and a table of the final evaluation. Prints the wall time of each run.
#
#   bash bench/learning.sh [--task block_pulling] [--preset reduced] [--seeds "0 1"] [--models "equi cnn"]
#                          [--out bench/out/learning] [--parallel 2] [--features F]
#                          [-- extra `equiarm train` flags]
# Runs `--parallel` trainings at once, each with RAYON_NUM_THREADS = 2 / parallel.
set -euo pipefail
cd "$(dirname "$0")/.."
task=block_pulling preset=reduced seeds="0 1" models="equi cnn" out=bench/out/learning parallel=1 features=""
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --task) task=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --seeds) seeds=$2; shift 2 ;;
    --models) models=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --parallel) parallel=$2; shift 2 ;;
    --features) features=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "learning.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
cargo build --locked --quiet --bin equiarm --example compare_runs -p equiarm -p equiarm_train ${features:+--features "equiarm/$features"}
bin=$CARGO_TARGET_DIR/debug/equiarm
mkdir -p "$out"
threads=$(( 2 / parallel )); [ "$threads" -lt 1 ] && threads=1
jobs=()
for m in $models; do for s in $seeds; do jobs+=("$m:$s"); done; done
running=0
for j in "${jobs[@]}"; do
  m=${j%%:*} s=${j##*:}
  dir="$out/$task-$m-seed$s"
  rm -rf "$dir"
  (
    t0=$(date +%s)
    RAYON_NUM_THREADS=$threads "$bin" train --in-process --preset "$preset" --task "$task" --model "$m" --seed "$s" \
      --run-dir "$dir" -q "${extra[@]}" > "$dir.log" 2>&1
    echo "$m seed $s: $(( $(date +%s) - t0 )) s wall" | tee "$dir.time"
  ) &
  running=$((running + 1))
  if [ "$running" -ge "$parallel" ]; then wait -n; running=$((running - 1)); fi
done
wait
args=()
for m in $models; do
  dirs=""
  for s in $seeds; do dirs="$dirs${dirs:+,}$out/$task-$m-seed$s"; done
  args+=("$m=$dirs")
done
"$CARGO_TARGET_DIR/debug/examples/compare_runs" "$out/$task-success.png" "${args[@]}"
"$CARGO_TARGET_DIR/debug/examples/compare_runs" "$out/$task-return.png" --metric discounted_return "${args[@]}"
cat "$out"/*.time
