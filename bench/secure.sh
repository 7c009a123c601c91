#!/usr/bin/env bash
# DDS Security's cost to the main job (issue 60; a benchmark, not a test): `train.sh` (block pulling,
# the default preset and envs) for UPDATES updates plain, then the same with `--secure`, one after
# the other on this machine. Prints for each: the trainer's updates per second (from its first to
# its last logged update, metrics.csv), the recorder's messages per second (the bag's messages over
# its duration) and the secured/plain ratios (goal: within 20 %). One run of each: quote it as such.
#
#   bash bench/secure.sh [--updates 300] [--out DIR]
#
# Runs in a private network namespace (as root or with unprivileged user namespaces), so its DDS
# traffic stays on this machine's loopback. EQUIARM_BIN: use this binary instead of building.
set -euo pipefail
args=("$@")
updates=300 out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --updates) updates=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "secure.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
[[ $updates =~ ^[1-9][0-9]*$ ]] || { echo "secure.sh: --updates $updates: expected a whole number above 0" >&2; exit 2; }
source "$(dirname "$0")/../launch_scripts/lib.sh"
eqa_private_netns "$0" "${args[@]}"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-63}
cd "$(dirname "$0")/.."
eqa_bin
out=${out:-runs/secure-bench-$(date +%Y%m%d-%H%M%S)}
[ -e "$out" ] && { echo "secure.sh: $out exists: choose another --out" >&2; exit 2; }
mkdir -p "$out"

# updates_rate FILE: updates per second of wall time from the first to the last `charts/updates` row
# of metrics.csv (global_step,wall_time,name,value; value is the update count)
updates_rate() {
  awk -F, '$3 == "charts/updates" { if (!seen) { seen = 1; s = $4; t = $2 } ; e = $4; u = $2 }
    END { if (u > t) printf "%.3f", (e - s) / (u - t); else printf "nan" }' "$1"
}
# bag_rate BAG: messages per second of the bag's duration
bag_rate() {
  "$EQUIARM_BIN" bag info "$1" | awk '/^Messages:/ { m = $2 } /^Duration:/ { d = $2 }
    END { if (d > 0) printf "%.1f", m / d; else printf "nan" }'
}
declare -A ups msgs
for mode in plain secure; do
  flags=()
  [ $mode = secure ] && flags=(--secure)
  echo "== $mode: train.sh ${flags[*]} --total-updates $updates" >&2
  bash launch_scripts/train.sh "${flags[@]}" --total-updates "$updates" --run-dir "$out/$mode" > "$out/$mode.log" 2>&1 \
    || { echo "secure.sh: the $mode run failed: see $out/$mode.log" >&2; exit 1; }
  ups[$mode]=$(updates_rate "$out/$mode/metrics.csv")
  msgs[$mode]=$(bag_rate "$out/$mode/bag")
  printf '%-7s updates/s %s   recorder messages/s %s\n' "$mode" "${ups[$mode]}" "${msgs[$mode]}"
done
awk -v a="${ups[secure]}" -v b="${ups[plain]}" -v c="${msgs[secure]}" -v d="${msgs[plain]}" \
  'BEGIN { printf "secured/plain: updates/s %.2f, recorder messages/s %.2f (goal: 0.80 or more)\n", a / b, c / d }'
