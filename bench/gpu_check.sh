#!/usr/bin/env bash
# The GPU check (docs/backends.md, "GPU check"): the GPU build's learner on a GPU machine that has
# no network, beside PyTorch + e2cnn on the same GPU.
#
# Here (a machine with the package registries), build and pack everything it needs into DIR:
#   bash bench/gpu_check.sh --pack DIR
# DIR then holds: `equiarm` (the release GPU build, stripped), lib/libvulkan.so.1 (the Vulkan loader,
# for a machine without one), the PyTorch peer's scripts, and wheels/ with e2cnn (pure Python); and
# DIR.tar.gz beside it, the same packed as one file (about 24 MB against the folder's 82 MB: what
# travels to a lent GPU machine is limited to 64 MiB; there `tar -xzf DIR.tar.gz` first).
#
# There (the GPU machine: an NVIDIA driver with its Vulkan ICD, python3 with torch, numpy, scipy):
#   bash DIR/gpu_check.sh [--minutes 5] [--device vulkan] [--size paper] [--no-peer] [--out DIR]
# prints the device, the Equi and CNN SAC update medians beside the CPU's, the batch-1 action time,
# the peak device memory, `--minutes` of in-process Equi SAC on block pulling with its evaluations,
# then the peer's update medians on `cuda` and the ratio. Results: OUT/device_check.json,
# OUT/peer_*.json (OUT defaults to ./gpu_check_out).
set -euo pipefail

if [ "${1:-}" = "--pack" ]; then
  dir="${2:?usage: bash bench/gpu_check.sh --pack DIR}"
  cd "$(dirname "$0")/.."
  export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
  cargo build --locked --release --features vulkan --bin equiarm
  mkdir -p "$dir/lib" "$dir/wheels"
  cp "$CARGO_TARGET_DIR/release/equiarm" "$dir/equiarm"
  strip "$dir/equiarm"
  loader=$(ldconfig -p | awk '/libvulkan\.so\.1 .*x86-64/ {print $NF; exit}')
  if [ -z "$loader" ]; then
    source tests/vulkan_env.sh
    loader=$(ldconfig -p | awk '/libvulkan\.so\.1 .*x86-64/ {print $NF; exit}')
  fi
  cp -L "$loader" "$dir/lib/libvulkan.so.1"
  cp bench/gpu_check.sh bench/sac_update_peer.py bench/e2cnn_peer.py "$dir/"
  python3 -m pip download --quiet --no-deps --only-binary=:all: -d "$dir/wheels" e2cnn==0.2.3
  echo "packed into $dir:"
  ls -l "$dir" "$dir/lib" "$dir/wheels"
  tar -C "$(dirname "$dir")" -czf "$dir.tar.gz" "$(basename "$dir")"
  echo "equiarm (stripped): $(stat -c %s "$dir/equiarm") bytes; the whole pack: $(du -sh "$dir" | cut -f1);" \
    "as one file: $dir.tar.gz, $(stat -c %s "$dir.tar.gz") bytes"
  exit 0
fi

here="$(cd "$(dirname "$0")" && pwd)"
minutes=5 device=vulkan size=paper peer=1 out="$PWD/gpu_check_out"
while [ $# -gt 0 ]; do
  case "$1" in
    --minutes) minutes="$2"; shift 2 ;;
    --device) device="$2"; shift 2 ;;
    --size) size="$2"; shift 2 ;;
    --no-peer) peer=0; shift ;;
    --out) out="$2"; shift 2 ;;
    *) echo "gpu_check.sh: unknown option '$1' (--minutes M, --device D, --size paper|reduced16, --no-peer, --out DIR; or --pack DIR)" >&2; exit 2 ;;
  esac
done
[ -x "$here/equiarm" ] || { echo "gpu_check.sh: no $here/equiarm: run 'bash bench/gpu_check.sh --pack DIR' first and call DIR/gpu_check.sh" >&2; exit 2; }
mkdir -p "$out"

# The Vulkan loader: the machine's, else the one carried along.
if ! ldconfig -p 2>/dev/null | grep 'libvulkan\.so\.1 ' >/dev/null; then  # not -q: see tests/vulkan_env.sh
  export LD_LIBRARY_PATH="$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
# The NVIDIA Vulkan driver's manifest, where containers mount it when the loader does not look.
if [ -z "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}" ]; then
  for f in /usr/share/vulkan/icd.d/nvidia_icd.json /etc/vulkan/icd.d/nvidia_icd.json /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; do
    if [ -f "$f" ]; then export VK_DRIVER_FILES="$f"; break; fi
  done
fi
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true

echo "== equiarm device-check --device $device --size $size --run-minutes $minutes"
"$here/equiarm" device-check --device "$device" --size "$size" --run-minutes "$minutes" --reps 10 --warmup 2 \
  --run-dir "$out/device_check" 2>&1 | tee "$out/device_check.log"

if [ "$peer" = 1 ]; then
  echo "== PyTorch + e2cnn on cuda (bench/sac_update_peer.py), same sizes"
  site="$out/site"
  python3 -m pip install --quiet --no-index --no-deps --no-compile --target "$site" "$here"/wheels/*.whl
  for model in equi cnn; do
    PYTHONPATH="$site" python3 "$here/sac_update_peer.py" --device cuda --model "$model" --config "$size" --reps 10 \
      | tail -n 1 | tee "$out/peer_$model.json"
  done
  python3 - "$out" <<'EOF'
import json, sys, os
out = sys.argv[1]
ours = json.load(open(os.path.join(out, "device_check", "device_check.json")))
print(f"\nSAC update at {ours['size']} (batch {ours['batch']}), median seconds: ours on {ours['device_name']} vs PyTorch + e2cnn on cuda")
for m in ours["models"]:
    peer = json.load(open(os.path.join(out, f"peer_{m['model']}.json")))
    u = m["device"]["update_median_s"]
    print(f"  {m['model']:<5} ours {u:.4f}  peer {peer['update_s']:.4f}  ratio (ours / peer) {u / peer['update_s']:.2f}")
EOF
fi
