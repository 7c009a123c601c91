#!/usr/bin/env bash
# Rewrites launch_scripts/configs/{reduced,reduced16,paper}_<task>.json from the program's presets
# (`equiarm train --print-config`), so the committed configs follow the code.
#
# Usage: bash launch_scripts/configs/regenerate.sh
#   EQUIARM_BIN=path/to/equiarm  use that binary (default: `equiarm` on PATH)
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
bin=${EQUIARM_BIN:-equiarm}
for preset in reduced reduced16 paper; do
  for task in block_pulling block_pushing block_picking drawer_opening block_in_bowl; do
    "$bin" train --print-config --preset "$preset" --task "$task" > "$here/${preset}_${task}.json.tmp"
    mv "$here/${preset}_${task}.json.tmp" "$here/${preset}_${task}.json"
  done
done
echo "configs written to $here"
