#!/usr/bin/env bash
# What the suite's other processes cost the learner (issue 59, item 2): the main job's seconds per
# update against the update alone at the same thread count. For each niceness N given: the main job
# (`launch_scripts/train.sh`, its config at --updates updates) with EQA_ENV_NICE=N (the sims and
# policies run at niceness N), every process sampled by bench/proc_usage.py; its seconds per update
# over updates --from … --updates (from metrics.csv's wall times: the first updates, whose episodes
# mostly run to the step limit, are left out). Then the update benchmark alone at 2 threads
# (`cargo bench --bench update`, the config's model, no peer). Prints a table: niceness, the suite's
# seconds per update, the update alone, their ratio, and each role's CPU seconds per update.
#
#   bash bench/suite_overhead.sh [--updates 1500] [--from 500] [--nice "0 10"] [--seed 0]
#                                [--out bench/out/suite_overhead] [-- train.sh flags]
#
# Each run uses both cores, one after the other; nothing else should run meanwhile. ROS_DOMAIN_ID
# defaults to 32 here.
set -euo pipefail
cd "$(dirname "$0")/.."
updates=1500 from=500 nices="0 10" seed=0 out=bench/out/suite_overhead
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --updates) updates=$2; shift 2 ;;
    --from) from=$2; shift 2 ;;
    --nice) nices=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "suite_overhead.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
[ "$from" -lt "$updates" ] || { echo "suite_overhead.sh: --from $from must be below --updates $updates" >&2; exit 2; }
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-32}"
source launch_scripts/lib.sh
eqa_bin
mkdir -p "$out"
for n in $nices; do
  run="$out/nice$n"
  rm -rf "$run"
  python3 bench/proc_usage.py --until-gone --exe "$EQUIARM_BIN" "$out/nice$n.usage.csv" & sampler=$!
  EQA_ENV_NICE=$n bash launch_scripts/train.sh --seed "$seed" --total-updates "$updates" --run-dir "$run" \
    "${extra[@]}" > "$out/nice$n.log" 2>&1
  kill -TERM $sampler 2>/dev/null || true; wait $sampler
  echo "niceness $n: done ($(grep -c '' "$run/metrics.csv") metric rows)"
done
model=$(eqa_config_get "$out/nice${nices%% *}/config.json" model)
preset=reduced16
[ "$(eqa_config_get "$out/nice${nices%% *}/config.json" hidden)" = 64 ] && preset=paper
# the update alone, built as the suite's binary is (the dev profile, the launch scripts' features)
cargo bench --locked --profile dev -p equiarm -p equiarm_sac --features equiarm/vulkan --bench update -- \
  --config "$preset" --model "$model" --threads 2 --reps 7 --no-peer > "$out/update.log" 2>&1
python3 - "$out" "$from" "$updates" $nices <<'EOF'
import csv, sys
out, lo, hi, nices = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
alone = None
for line in open(f"{out}/update.log"):
    if line.startswith("csv,") and not line.startswith("csv,model"):
        alone = float(line.split(",")[7])
def group(role):
    sub, _, ns = role.partition(" ")
    return f"{sub} (eval)" if ns == "/eval" else (f"{sub} (training)" if ns else sub)
print(f"updates {lo}..{hi}; the update alone at 2 threads: {alone:.3f} s (median of 7)")
print("| niceness of sims and policies | suite s/update | ratio to the update alone | CPU s/update: " +
      " | ".join(["train", "record", "sim (training)", "policy (training)", "sim (eval)", "policy (eval)", "idle"]) + " |")
print("| --- " * 10 + "|")
for n in nices:
    wall = {}
    for r in csv.DictReader(open(f"{out}/nice{n}/metrics.csv")):
        if r["name"] == "charts/updates":
            wall[int(float(r["value"]))] = float(r["wall_time"])
    per = (wall[hi] - wall[lo]) / (hi - lo)
    # CPU over the whole run, per update (the sampler's totals); idle: what of 2 cores nobody used
    total_wall = max(wall.values())
    cpu = {}
    for r in csv.DictReader(open(f"{out}/nice{n}.usage.csv")):
        cpu[group(r["role"])] = cpu.get(group(r["role"]), 0.0) + float(r["cpu_s"])
    used = sum(cpu.values())
    cols = [cpu.get(k, 0.0) / hi for k in ["train", "record", "sim (training)", "policy (training)", "sim (eval)", "policy (eval)"]]
    idle = max(0.0, 2 * total_wall - used) / hi
    print(f"| {n} | {per:.3f} | {per / alone:.2f} | " + " | ".join(f"{c:.3f}" for c in cols + [idle]) + " |")
EOF
