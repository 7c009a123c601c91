# shellcheck shell=bash
# Sourced by bench/export.sh and bench/lerobot_check.sh. `bench_demo_bag DOMAIN DEMO_ARGS...` builds
# equiarm as the launch scripts do (EQUIARM_BIN), makes a scratch folder $work (removed on exit) and
# records a demo.sh bag of expert episodes in $work/demo/bag inside a private network namespace
# (tests/netns.sh) on ROS domain DOMAIN; DEMO_ARGS go to demo.sh.
bench_demo_bag() {
  local domain=$1
  shift
  source launch_scripts/lib.sh
  "${EQA_BUILD[@]}" >&2
  export EQUIARM_BIN="$CARGO_TARGET_DIR/debug/equiarm"
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
  source tests/netns.sh
  "${ns[@]}" bash -c "$netup; ROS_DOMAIN_ID=$domain bash launch_scripts/demo.sh $* --out $work/demo" > "$work/demo.log" 2>&1 \
    || { cat "$work/demo.log" >&2; exit 1; }
}
