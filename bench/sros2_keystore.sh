#!/usr/bin/env bash
# Does a keystore made by ROS 2's own tooling work with equiarm's nodes? (issue 60.) `ros2 security
# create_keystore` and `create_enclave` are sros2's Python functions (`sros2.keystore`); this runs
# them from a checkout of https://github.com/ros2/sros2 (not on PyPI, so not part of the test
# command) without a ROS 2 installation: `cryptography` and `lxml` from PyPI in a venv (Ubuntu 24.04's versions), and what
# sros2 imports from ROS 2's own packages stood in by a few lines written here (rclpy and
# ament_index_python need a ROS 2 build): rclpy's `validate_namespace`, `InvalidNamespaceException`
# and `get_rmw_implementation_identifier`, and ament's `get_package_share_directory('sros2')` (the
# checkout's `sros2/` folder, where sros2's XML cache lies). Then `tests/security_dds.rs::a_keystore_made_by_sros2_works` (ignored in the test
# command) starts env0's sim and policy in their enclaves of that keystore, domain 78, and they must
# exchange commands and observations over DDS Security.
#
#   bash bench/sros2_keystore.sh SROS2_CHECKOUT [--out DIR]
#
# The keystore is what `ROS_DOMAIN_ID=78 ros2 security create_keystore DIR` and `ros2 security
# create_enclave DIR /equiarm/env0/sim` (and `/equiarm/env0/policy`) write: one CA for identities
# and permissions, sros2's governance for domain 78, and per enclave sros2's default permissions
# (every topic, service and action allowed), signed. Runs in a private network namespace.
set -euo pipefail
cd "$(dirname "$0")/.."
src=${1:?usage: bash bench/sros2_keystore.sh SROS2_CHECKOUT [--out DIR]}
shift
out=bench/out/sros2_keystore
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    *) echo "sros2_keystore.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -f "$src/sros2/sros2/keystore/_keystore.py" ] || { echo "$src: not a checkout of ros2/sros2 (no sros2/sros2/keystore/_keystore.py)" >&2; exit 2; }
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
venv="$HOME/.cache/equiarm/venvs/sros2"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
# the versions Ubuntu 24.04 ships with ROS 2 Jazzy (sros2 0.13): later cryptography releases refuse
# the curve class sros2 passes where they now want an instance
"$venv/bin/pip" install --quiet cryptography==41.0.7 lxml==5.2.1
rm -rf "$out"
mkdir -p "$out/shim/rclpy" "$out/shim/ament_index_python"
out=$(cd "$out" && pwd)
cat > "$out/shim/ament_index_python/__init__.py" <<EOF
def get_package_share_directory(name):
    assert name == 'sros2', name
    return '$(cd "$src/sros2" && pwd)'
EOF
: > "$out/shim/rclpy/__init__.py"
cat > "$out/shim/rclpy/exceptions.py" <<'EOF'
class InvalidNamespaceException(Exception):
    pass
EOF
cat > "$out/shim/rclpy/validate_namespace.py" <<'EOF'
import re

from rclpy.exceptions import InvalidNamespaceException


def validate_namespace(namespace):
    # ROS 2's rules: absolute, tokens of letters, digits and underscores not starting with a digit
    if namespace == '/':
        return True
    if not re.fullmatch(r'(/[A-Za-z_][A-Za-z0-9_]*)+', namespace):
        raise InvalidNamespaceException(namespace)
    return True
EOF
cat > "$out/shim/rclpy/utilities.py" <<'EOF'
import os


def get_rmw_implementation_identifier():
    return os.environ.get('RMW_IMPLEMENTATION', 'rmw_cyclonedds_cpp')
EOF
ks="$out/keystore"
ROS_DOMAIN_ID=78 PYTHONPATH="$src/sros2:$out/shim" "$venv/bin/python" - "$ks" <<'EOF'
import pathlib, sys
from sros2.keystore import create_enclave, create_keystore
ks = pathlib.Path(sys.argv[1])
create_keystore(ks)
for e in ('/equiarm/env0/sim', '/equiarm/env0/policy'):
    create_enclave(ks, e)
print(f'sros2 made {ks}')
EOF
source tests/netns.sh
"${ns[@]}" bash -c "$netup; EQUIARM_SROS2_KEYSTORE='$ks' cargo test --locked --workspace --features vulkan \
  --test security_dds a_keystore_made_by_sros2_works -- --ignored"
