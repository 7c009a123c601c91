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
# A step's header, with the seconds since the start (where a cold run spends its time).
step() { echo "== [$(( $(date +%s) - start )) s] $*"; }
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
export CARGO_TERM_COLOR=never

source tests/python_env.sh
# OpenSSL's headers for the build (DDS Security, docs/security.md).
source tests/openssl_env.sh
# The GPU build's device tests run on Mesa's lavapipe, a Vulkan driver on the CPU (docs/backends.md).
source tests/vulkan_env.sh

# Everything is built once, as the GPU build (why and what it costs: docs/backends.md), and the
# programs exactly as the launch scripts build them (EQA_BUILD), so neither rebuilds after the other.
source launch_scripts/lib.sh
features=("${EQA_FEATURES[@]}")

step "style gates"
# formatting (rustfmt.toml), lints with every warning an error (missing_docs included: the workspace
# warns on it), and the API docs of every crate without a broken link; each names the file and line.
cargo fmt --all --check
cargo clippy --locked --workspace --all-targets "${features[@]}" --quiet -- -D warnings
RUSTDOCFLAGS="-D warnings" cargo doc --locked --workspace "${features[@]}" --no-deps --quiet
step "build (target dir: $CARGO_TARGET_DIR)"
# Every test target (examples and benchmarks included) in one go, then the programs (mostly built by
# then). The benchmarks build in the test profile here; `cargo bench` builds them in release.
cargo test --locked --workspace "${features[@]}" --all-targets --no-run
"${EQA_BUILD[@]}"

source tests/netns.sh

step "Rust tests (the device tests, crates/train/tests/vulkan_device.rs, on lavapipe: \`vulkan:cpu\`)"
"${ns[@]}" env VK_ICD_FILENAMES="$EQUIARM_LAVAPIPE_ICD" bash -c "$netup; exec cargo test --locked --offline --workspace ${features[*]}"
step "benchmarks and examples, short form (tests/bench_smoke.sh)"
bash tests/bench_smoke.sh
step "fuzz: 10^4 inputs per target, one target per core (docs/fuzzing.md)"
"$CARGO_TARGET_DIR/debug/equiarm_fuzz" all --execs 10000
step "Python tests"
# The launch-script examples drive real nodes over DDS: same private namespace, our binary.
export EQUIARM_BIN="$CARGO_TARGET_DIR/debug/equiarm"
"${ns[@]}" bash -c "$netup; cd tests/python && exec \"\$EQUIARM_PYTHON\" -m pytest -q"
step "the Python package (python/): its wheel, built by maturin, and its tests"
# The test build's profile and features, so the wheel reuses the build above (python/Cargo.toml,
# "Build reuse"); `pip install ./python` builds the same package in release.
wheels=$(mktemp -d)
"$EQUIARM_PYTHON" -m maturin build --locked --profile dev "${features[@]}" -m python/Cargo.toml \
  --compatibility linux -i "$EQUIARM_PYTHON" -o "$wheels" --quiet
"$EQUIARM_PYTHON" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "$wheels"/equiarm-*.whl
rm -rf "$wheels"
"${ns[@]}" bash -c "$netup; cd python/tests && exec \"\$EQUIARM_PYTHON\" -m pytest -q"
# Its benchmark in short form, without the PyBullet peer (bash bench/python.sh runs it in full).
(cd python/tests && "$EQUIARM_PYTHON" ../../bench/python_env.py --steps 5 --rounds 1 --tasks block_pulling > /dev/null)
step "all tests passed"
