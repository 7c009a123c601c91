# Sourced by tests/run_all.sh (and usable alone): makes sure this machine has a Vulkan driver that
# runs on the CPU, Mesa's lavapipe, so that the GPU build's tests (crates/train/tests/vulkan_device.rs)
# run without a GPU, and exports EQUIARM_LAVAPIPE_ICD, the path of its driver manifest.
#
# Installs Debian's `libvulkan1` (the Vulkan loader) and `mesa-vulkan-drivers` (lavapipe) when the
# manifest is missing (tests/apt_install.sh).
source "$(dirname "${BASH_SOURCE[0]}")/apt_install.sh"
_icd=""
for _f in /usr/share/vulkan/icd.d/lvp_icd.x86_64.json /usr/share/vulkan/icd.d/lvp_icd.*.json; do
  if [ -f "$_f" ]; then _icd="$_f"; break; fi
done
# (grep reads all of ldconfig's output: with `-q` it could stop early, ldconfig would die of SIGPIPE,
# and under `set -o pipefail` a present loader would look missing.)
if [ -z "$_icd" ] || ! ldconfig -p 2>/dev/null | grep 'libvulkan\.so\.1 ' >/dev/null; then
  eqa_apt_install "the Vulkan loader and Mesa's lavapipe for the GPU build's tests" libvulkan1 mesa-vulkan-drivers \
    || { return 1 2>/dev/null || exit 1; }
  for _f in /usr/share/vulkan/icd.d/lvp_icd.*.json; do
    if [ -f "$_f" ]; then _icd="$_f"; break; fi
  done
  if [ -z "$_icd" ]; then
    echo "equiarm: mesa-vulkan-drivers is installed but no lavapipe manifest (lvp_icd.*.json) is in /usr/share/vulkan/icd.d" >&2
    return 1 2>/dev/null || exit 1
  fi
fi
export EQUIARM_LAVAPIPE_ICD="$_icd"
# Mesa wants a runtime directory for its shader cache; a batch job may have none.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
unset _icd _f
