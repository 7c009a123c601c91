# shellcheck shell=bash
# Sourced by tests/run_all.sh and tests/bench_smoke.sh: sets `ns` (the command prefix that runs a
# command in a private network namespace, as root (CI) or through an unprivileged user namespace) and
# `netup` (the shell line that brings its loopback up with multicast, for DDS discovery).
ns=()
if unshare -n true 2>/dev/null; then
  ns=(unshare -n)
elif unshare -rn true 2>/dev/null; then
  ns=(unshare -rn)
else
  echo "WARNING: cannot create a network namespace; DDS tests use the host's interfaces" >&2
fi
netup='if command -v ip >/dev/null; then ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo 2>/dev/null || true; fi'
