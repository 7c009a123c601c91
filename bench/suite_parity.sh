#!/usr/bin/env bash
# Does the suite over DDS learn like the in-process loop? (issue 59, item 1.) For each seed: the main
# job (`launch_scripts/train.sh`) at the given update count, then `equiarm train --in-process` with
# that run's own config.json (the same config, seed and update count), then the held-out evaluation
# of both final checkpoints (`equiarm experiment heldout`: the same 100 held-out episodes for every
# run); at the end a table (per seed and mean ± standard error) and the learning curves of both
# (mean ± standard error over seeds) as PNGs.
#
#   bash bench/suite_parity.sh [--seeds "0 1 2 3"] [--updates 5000] [--task block_pulling]
#                              [--out bench/out/suite_parity] [--episodes 100] [-- train.sh flags]
#
# Each run uses both cores, one after the other (a seed's two runs about 35 + 30 min at reduced16 on
# 2 cores). A seed whose run directories hold a finished run (its heldout.json) is not run again, so
# an interrupted benchmark continues where it stopped. ROS_DOMAIN_ID defaults to 31 here. While each
# run trains, bench/proc_usage.py samples every equiarm process (CPU seconds, peak RSS) into
# RUN.usage.csv; a second table gives the CPU seconds per update of each role and its peak RSS.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds="0 1 2 3" updates=5000 task=block_pulling out=bench/out/suite_parity episodes=100
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --seeds) seeds=$2; shift 2 ;;
    --updates) updates=$2; shift 2 ;;
    --task) task=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --episodes) episodes=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "suite_parity.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-31}"
source launch_scripts/lib.sh
eqa_bin
bin=$EQUIARM_BIN
# (the features of the launch scripts' build, so nothing is built twice)
cargo build --locked --quiet --example compare_runs -p equiarm -p equiarm_train --features equiarm/vulkan
mkdir -p "$out"
for s in $seeds; do
  suite="$out/suite-s$s" inproc="$out/inprocess-s$s"
  if [ ! -f "$suite/heldout.json" ]; then
    rm -rf "$suite"
    t0=$(date +%s)
    python3 bench/proc_usage.py --until-gone --exe "$bin" "$out/suite-s$s.usage.csv" & sampler=$!
    bash launch_scripts/train.sh --task "$task" --seed "$s" --total-updates "$updates" --run-dir "$suite" \
      "${extra[@]}" > "$out/suite-s$s.log" 2>&1
    kill -TERM $sampler 2>/dev/null || true; wait $sampler
    echo "suite seed $s: $(( $(date +%s) - t0 )) s wall" | tee "$out/suite-s$s.time"
    RAYON_NUM_THREADS=1 "$bin" experiment heldout "$suite" --episodes "$episodes"
  fi
  if [ ! -f "$inproc/heldout.json" ]; then
    rm -rf "$inproc"
    t0=$(date +%s)
    python3 bench/proc_usage.py --until-gone --exe "$bin" "$out/inprocess-s$s.usage.csv" & sampler=$!
    RAYON_NUM_THREADS=2 "$bin" train --in-process --config "$suite/config.json" --run-dir "$inproc" -q \
      > "$out/inprocess-s$s.log" 2>&1
    kill -TERM $sampler 2>/dev/null || true; wait $sampler
    echo "in-process seed $s: $(( $(date +%s) - t0 )) s wall" | tee "$out/inprocess-s$s.time"
    RAYON_NUM_THREADS=1 "$bin" experiment heldout "$inproc" --episodes "$episodes"
  fi
done
join() { local d="" s; for s in $seeds; do d="$d${d:+,}$out/$1-s$s"; done; echo "$d"; }
cmp="$CARGO_TARGET_DIR/debug/examples/compare_runs"
"$cmp" "$out/$task-success.png" "suite=$(join suite)" "in-process=$(join inprocess)"
"$cmp" "$out/$task-return.png" --metric discounted_return "suite=$(join suite)" "in-process=$(join inprocess)"
python3 - "$out" $seeds <<'EOF'
import csv, json, math, sys
out, seeds = sys.argv[1], sys.argv[2:]
def run(kind, s):
    d = f"{out}/{kind}-s{s}"
    h = json.load(open(f"{d}/heldout.json"))
    # long format: global_step, wall_time, name, value; the training time is the last update's
    ups = [(float(r["value"]), float(r["wall_time"])) for r in csv.DictReader(open(f"{d}/metrics.csv"))
           if r["name"] == "charts/updates"]
    updates, wall = max(ups)
    return h["success_rate"], h["discounted_return"], wall, updates
def ms(v):
    m = sum(v) / len(v)
    if len(v) < 2:
        return f"{m:.3f}"
    se = math.sqrt(sum((x - m) ** 2 for x in v) / (len(v) - 1) / len(v))
    return f"{m:.3f} ± {se:.3f}"
print("| seed | suite: held-out success | disc. return | training s | s/update | in-process: held-out success | disc. return | training s | s/update |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
cols = {k: [[], [], []] for k in ("suite", "inprocess")}
for s in seeds:
    line = [s]
    for k in ("suite", "inprocess"):
        succ, ret, wall, u = run(k, s)
        cols[k][0].append(succ); cols[k][1].append(ret); cols[k][2].append(wall / max(u, 1))
        line += [f"{succ:.2f}", f"{ret:.3f}", f"{wall:.0f}", f"{wall / max(u, 1):.3f}"]
    print("| " + " | ".join(line) + " |")
print("| mean ± s.e. | " + " | ".join(
    f"{ms(cols[k][0])} | {ms(cols[k][1])} | | {ms(cols[k][2])}" for k in ("suite", "inprocess")) + " |")
# CPU seconds per update and peak RSS of each role (bench/proc_usage.py), summed over the training
# envs' sims and policies; mean over the seeds whose usage was sampled
def group(r):
    sub, _, ns = r.partition(" ")
    return f"{sub} (eval)" if ns == "/eval" else (f"{sub} (training envs)" if ns else sub)
usage = {}
for k in ("suite", "inprocess"):
    for s in seeds:
        f = f"{out}/{k}-s{s}.usage.csv"
        try:
            rows = list(csv.DictReader(open(f)))
        except FileNotFoundError:
            continue
        _, _, _, u = run(k, s)
        per = {}
        for r in rows:
            g = per.setdefault(group(r["role"]), [0.0, 0.0])
            g[0] += float(r["cpu_s"]) / max(u, 1)
            g[1] = max(g[1], float(r["peak_rss_mib"]))
        for g, (c, m) in per.items():
            usage.setdefault((k, g), []).append((c, m))
if usage:
    print()
    print("| run | role | CPU s per update | peak RSS MiB (largest process) | seeds |")
    print("| --- | --- | --- | --- | --- |")
    for (k, g), v in sorted(usage.items()):
        print(f"| {k} | {g} | {ms([c for c, _ in v])} | {max(m for _, m in v):.0f} | {len(v)} |")
EOF
