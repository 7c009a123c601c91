#!/usr/bin/env bash
# The recorder under load: N envs x R Hz of 152 px RGBD Observations for S seconds, on loopback in a
# private network namespace (default 10 50 10). Prints published vs recorded counts and peak RSS.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
cargo bench --locked --bench record_load --no-run
ns=(); if unshare -n true 2>/dev/null; then ns=(unshare -n); elif unshare -rn true 2>/dev/null; then ns=(unshare -rn); fi
"${ns[@]}" bash -c 'ip link set lo up 2>/dev/null; ip link set lo multicast on 2>/dev/null; ip route add 224.0.0.0/4 dev lo 2>/dev/null; exec cargo bench --locked --offline --bench record_load -- "$@"' _ "$@"
