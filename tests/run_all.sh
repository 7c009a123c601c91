#!/usr/bin/env bash
# The test command (README, .ci/run): installs what the tests need, builds, and runs every Rust and
# Python test. DDS tests run inside a private network namespace (only the loopback interface, with
# multicast on), so no DDS traffic leaves the machine and parallel runs never cross-talk.
#
# Environment: CARGO_TARGET_DIR (default: a folder outside the clone, so later clones reuse the
# build), EQUIARM_VENV_DIR (where the Python environment is kept).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
export CARGO_TERM_COLOR=never

source tests/python_env.sh

echo "== style gates"
# formatting (rustfmt.toml), lints with every warning an error (missing_docs included: the workspace
# warns on it), and the API docs of every crate without a broken link; each names the file and line.
cargo fmt --all --check
cargo clippy --locked --workspace --all-targets --quiet -- -D warnings
RUSTDOCFLAGS="-D warnings" cargo doc --locked --workspace --no-deps --quiet
echo "== build (target dir: $CARGO_TARGET_DIR)"
cargo build --locked --workspace --all-targets
cargo test --locked --workspace --no-run

# A private network namespace: as root (CI) or through an unprivileged user namespace.
ns=()
if unshare -n true 2>/dev/null; then
  ns=(unshare -n)
elif unshare -rn true 2>/dev/null; then
  ns=(unshare -rn)
else
  echo "WARNING: cannot create a network namespace; DDS tests use the host's interfaces" >&2
fi
netup='if command -v ip >/dev/null; then ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo 2>/dev/null || true; fi'

echo "== Rust tests"
"${ns[@]}" bash -c "$netup; exec cargo test --locked --offline --workspace"
echo "== fuzz: 10^4 inputs per target (docs/fuzzing.md)" && "$CARGO_TARGET_DIR/debug/equiarm_fuzz" all --execs 10000
echo "== Python tests"
# The launch-script examples drive real nodes over DDS: same private namespace, our binary.
export EQUIARM_BIN="$CARGO_TARGET_DIR/debug/equiarm"
"${ns[@]}" bash -c "$netup; cd tests/python && exec \"\$EQUIARM_PYTHON\" -m pytest -q"
echo "== GPU build: its device tests on Mesa's lavapipe, a Vulkan driver on the CPU (docs/backends.md)"
# A build of its own in the `gpu-test` profile (why and what it costs: docs/backends.md).
source tests/vulkan_env.sh
VK_ICD_FILENAMES="$EQUIARM_LAVAPIPE_ICD" cargo test --locked --workspace --profile gpu-test --features equiarm_train/vulkan --test vulkan_device
echo "== all tests passed in $(( $(date +%s) - start )) s"
