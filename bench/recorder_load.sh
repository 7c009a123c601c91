#!/usr/bin/env bash
# The recorder under load: N envs x R Hz of 152 px RGBD Observations for S seconds, on loopback in a
# private network namespace (default 10 50 10). Prints published vs recorded counts, CPU time and peak
# RSS; with `--foxglove-rounds K`, K rounds each without and with a Foxglove WebSocket client attached
# to `equiarm record --foxglove`, and the medians' ratios.
# Built in the dev profile, as the launch scripts run the recorder (dependencies optimised, see
# Cargo.toml), with the test command's features, so it reuses the test command's build.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
build=(cargo bench --locked --workspace --features vulkan --profile dev --bench record_load)
"${build[@]}" --no-run
ns=(); if unshare -n true 2>/dev/null; then ns=(unshare -n); elif unshare -rn true 2>/dev/null; then ns=(unshare -rn); fi
"${ns[@]}" bash -c 'ip link set lo up 2>/dev/null; ip link set lo multicast on 2>/dev/null; ip route add 224.0.0.0/4 dev lo 2>/dev/null; exec "$@"' _ "${build[@]}" --offline -- "$@"
