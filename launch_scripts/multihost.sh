#!/usr/bin/env bash
# The suite spread over "hosts" simulated by network namespaces: actors on other machines talking to
# the trainer over a real (virtual) Ethernet, as DDS would across a LAN.
#
#   eqa-trainer  10.77.0.1/24  the trainer (`equiarm train`, over DDS) and the recorder
#   eqa-actor1   10.77.0.11/24 sim + policy pair /env0
#   eqa-actor2   10.77.0.12/24 sim + policy pair /env1
#   eqa-hub      the switch: a bridge (br0, multicast snooping off) with one veth per host
# Each host has lo and eth0 (a veth into the hub, multicast on, route 224.0.0.0/4 via eth0), so DDS
# discovery (SPDP multicast) and data (unicast) go over the veths. Nothing is created in the
# namespace this script runs in; on exit (normal, failure, Ctrl-C) every process is stopped (SIGINT,
# up to 10 s, then SIGKILL) and the namespaces are deleted.
#
# Options:
#   --task T             task (default block_pulling)
#   --preset P           reduced16 (default), reduced or paper
#   --seconds S          run for S seconds, then stop (default 120; 0: until the trainer exits)
#   --total-updates U    pass --total-updates U to the trainer (the run ends when it exits)
#   --out DIR            run directory (trainer's run dir DIR/run, bag DIR/bag, logs DIR/logs;
#                        default runs/multihost-<time>)
#   --check-discovery    instead of training: a sim in eqa-actor1 driven from eqa-trainer by
#                        drive_sim.py (Cyclone DDS) with the expert for 2 episodes, recorded in
#                        eqa-trainer, and `equiarm topic echo /episodes` in eqa-actor2: shows that DDS
#                        discovery and the lock-step loop work across the veths
#   --cleanup            only delete leftover eqa-* namespaces (and what runs in them), then exit
# Environment: EQUIARM_BIN (else built once with cargo), ROS_DOMAIN_ID (default 0),
# EQUIARM_PYTHON (a Python with cyclonedds for --check-discovery; default python3).
#
# Needs root and iproute2 (`ip netns`); without them it prints why and exits 0 with "skipped".
#
# Example:
#   sudo EQUIARM_BIN=target/debug/equiarm bash launch_scripts/multihost.sh --total-updates 20
#   sudo bash launch_scripts/multihost.sh --check-discovery
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$here/lib.sh"
eqa_default_signals "$0" "$@"

task=block_pulling preset=reduced16 seconds=120 total_updates="" out="" check=0 cleanup_only=0
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
  case $1 in
    --task) task=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --seconds) seconds=$2; shift 2 ;;
    --total-updates) total_updates=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --check-discovery) check=1; shift ;;
    --cleanup) cleanup_only=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "multihost.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

HUB=eqa-hub
HOSTS=(eqa-trainer eqa-actor1 eqa-actor2)
declare -A ADDR=([eqa-trainer]=10.77.0.1 [eqa-actor1]=10.77.0.11 [eqa-actor2]=10.77.0.12)
ALL_NS=("$HUB" "${HOSTS[@]}")

skip() { echo "multihost.sh: skipped: $*"; exit 0; }
[ "$(id -u)" -eq 0 ] || skip "needs root to create network namespaces (run it with sudo)"
command -v ip >/dev/null || skip "no 'ip' command (install iproute2)"
probe="eqa-probe-$$"
ip netns add "$probe" 2>/dev/null || skip "cannot create a network namespace here ('ip netns add' failed)"
ip netns del "$probe"

ns_exists() { ip netns list | awk '{print $1}' | grep -x "$1" >/dev/null; }  # not -q: an early exit could SIGPIPE awk under pipefail

delete_namespaces() {
  local ns pid
  for ns in "${ALL_NS[@]}"; do
    ns_exists "$ns" || continue
    # processes still inside (only ours can be there): SIGKILL, then delete
    for pid in $(ip netns pids "$ns" 2>/dev/null); do kill -KILL "$pid" 2>/dev/null || true; done
    ip netns del "$ns" && eqa_log "deleted namespace $ns"
  done
}

if [ $cleanup_only -eq 1 ]; then
  delete_namespaces
  exit 0
fi
for ns in "${ALL_NS[@]}"; do
  ns_exists "$ns" && { echo "multihost.sh: namespace $ns already exists (another run? remove leftovers with --cleanup)" >&2; exit 1; }
done

cfg="$here/configs/${preset}_$task.json"
[ -f "$cfg" ] || { echo "multihost.sh: no config $cfg (unknown task or preset?)" >&2; exit 2; }
eqa_bin
out=${out:-runs/multihost-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$out/logs"
out=$(cd "$out" && pwd)
bag="$out/bag"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}

on_exit() {
  local rc=$?
  trap - EXIT INT TERM
  eqa_stop_all
  delete_namespaces
  [ -z "$EQA_EXIT_MESSAGE" ] || echo "$EQA_EXIT_MESSAGE"
  exit $rc
}
trap on_exit EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# --- the network ------------------------------------------------------------------------------------
for ns in "${ALL_NS[@]}"; do
  ip netns add "$ns"
  ip -n "$ns" link set lo up
done
ip -n "$HUB" link add br0 type bridge
ip -n "$HUB" link set br0 type bridge mcast_snooping 0
ip -n "$HUB" link set br0 up
for ns in "${HOSTS[@]}"; do
  port="v-${ns#eqa-}"
  # created inside the hub, the peer end moved straight into the host: nothing touches this namespace
  ip -n "$HUB" link add "$port" type veth peer name eth0 netns "$ns"
  ip -n "$HUB" link set "$port" master br0 up
  ip -n "$ns" addr add "${ADDR[$ns]}/24" dev eth0
  ip -n "$ns" link set eth0 multicast on up
  ip -n "$ns" route add 224.0.0.0/4 dev eth0
  eqa_log "host $ns: eth0 ${ADDR[$ns]}/24 <-> $HUB/$port on br0"
done
if command -v ping >/dev/null; then
  for ns in eqa-actor1 eqa-actor2; do  # the wire works: unicast from the trainer's host
    ip netns exec eqa-trainer ping -c 1 -W 2 "${ADDR[$ns]}" >/dev/null \
      && eqa_log "ping eqa-trainer -> $ns (${ADDR[$ns]}): ok" \
      || { eqa_log "ping eqa-trainer -> $ns failed"; exit 1; }
  done
fi

report_traffic() {  # bytes and packets each host's eth0 received and sent (the traffic went over the veths)
  local ns
  for ns in "${HOSTS[@]}"; do
    eqa_log "$ns eth0: $(ip -n "$ns" -s link show eth0 | awk 'f == 1 { rx = $1 " B / " $2 " packets" } f == 2 { tx = $1 " B / " $2 " packets" } /RX:/ { f = 1; next } /TX:/ { f = 2; next } { f = 0 } END { print "received " rx ", sent " tx }')"
  done
}

start_in() {  # start_in NAME NS cmd...
  local name=$1 ns=$2
  shift 2
  eqa_start "$name" "$out/logs/$name.log" ip netns exec "$ns" "$@"
}

frame=$(eqa_config_get "$cfg" image_size)
start_in recorder eqa-trainer "$EQUIARM_BIN" record --all -q -o "$bag"
EQA_EXIT_MESSAGE="bag: $bag   logs: $out/logs"
sleep 1

if [ $check -eq 1 ]; then
  # --- discovery check: no trainer or policy needed -----------------------------------------------
  py=${EQUIARM_PYTHON:-python3}
  start_in sim_env0 eqa-actor1 "$EQUIARM_BIN" sim --namespace /env0 --task "$task" --seed 0 --resolution "$frame" --episodes 2
  start_in echo_episodes eqa-actor2 "$EQUIARM_BIN" topic echo /episodes -t equiarm_msgs/msg/EpisodeResult --count 2
  status=0 driven=0
  if "$py" -c 'import cyclonedds' 2>/dev/null; then
    driven=1
    eqa_log "driving /env0 (in eqa-actor1) from eqa-trainer with drive_sim.py (Cyclone DDS) ..."
    ip netns exec eqa-trainer timeout 120 "$py" "$here/drive_sim.py" --namespace /env0 --episodes 2 --quiet-steps \
      --timeout-s 100 || status=$?
  else
    eqa_log "no cyclonedds for $py: echoing /env0/observation in eqa-trainer instead (the sim re-publishes it)"
    ip netns exec eqa-trainer timeout 30 "$EQUIARM_BIN" topic echo /env0/observation \
      -t equiarm_msgs/msg/Observation --count 3 | cut -c1-160 || status=$?
  fi
  if [ $driven -eq 1 ]; then  # the episodes were played: a third host saw their results
    eqa_wait_for echo_episodes 20 || true
    eqa_log "eqa-actor2 saw on /episodes (topic echo):"
    grep '^{' "$out/logs/echo_episodes.log" | cut -c1-200 >&2 || true
    grep -q '"success"' "$out/logs/echo_episodes.log" || status=1
  fi
  sleep 2
  eqa_stop_all
  report_traffic
  "$EQUIARM_BIN" bag info "$bag" | grep -E 'Messages|/episodes|/transitions|/env0/(observation|gripper_cmd)' || true
  [ $status -eq 0 ] && echo "multihost.sh: discovery across the veths: OK" || echo "multihost.sh: discovery check FAILED"
  exit $status
fi

# --- the suite: trainer + recorder on one host, one sim + policy pair per actor host -------------------
hidden=$(eqa_config_get "$cfg" hidden)
image="$frame:$(eqa_config_get "$cfg" input_size)"
model=$(eqa_config_get "$cfg" model)
mapfile -t scene < <(eqa_scene_args "$cfg")
train=("$EQUIARM_BIN" train --preset "$preset" --task "$task" --num-envs 2 --eval-every 0 --run-dir "$out/run" -q)
[ -z "$total_updates" ] || train+=(--total-updates "$total_updates")
start_in trainer eqa-trainer "${train[@]}"
# as train.sh: the config's demos spread over the 2 envs (expert first), flow control on the trainer
per_env=$(eqa_demos_per_env "$cfg" 2)
k=0
for ns in eqa-actor1 eqa-actor2; do
  start_in "policy_env$k" "$ns" "$EQUIARM_BIN" policy --namespace "/env$k" --mode sample --model "$model" \
    --hidden "$hidden" --image "$image" --seed "$k" --expert-episodes "$per_env" --max-lead 10
  start_in "sim_env$k" "$ns" "$EQUIARM_BIN" sim --namespace "/env$k" --task "$task" --seed "$k" --resolution "$frame" \
    "${scene[@]}" --stamp-origin "$EQA_STAMP_ORIGIN"
  k=$((k + 1))
done
eqa_log "running: trainer in eqa-trainer, /env0 in eqa-actor1, /env1 in eqa-actor2 (${seconds}s max; logs in $out/logs)"
deadline=$((SECONDS + seconds))
status=0
while eqa_running trainer; do
  if [ "$seconds" -gt 0 ] && [ $SECONDS -ge $deadline ]; then
    eqa_log "time is up ($seconds s)"
    break
  fi
  for name in sim_env0 sim_env1 policy_env0 policy_env1 recorder; do
    if ! eqa_running "$name"; then
      eqa_log "$name stopped early (log: $out/logs/$name.log):"
      tail -n 5 "$out/logs/$name.log" >&2 || true
      status=1
      break 2
    fi
  done
  sleep 1
done
if ! eqa_running trainer; then
  rc=0; eqa_exit_status trainer || rc=$?
  eqa_log "trainer exited with status $rc"
  if [ $rc -ne 0 ]; then
    tail -n 5 "$out/logs/trainer.log" >&2 || true
    status=1
  fi
fi
eqa_stop trainer  # first, so that it writes its checkpoint while the actors still run
eqa_stop_all
# what crossed the veths: the trainer's counts, the weights each actor host switched to, the traffic
grep -h "received .* transitions\|stopping (" "$out/logs/trainer.log" | sed 's/^/  trainer: /' >&2 || true
for k in 0 1; do
  switches=$(grep 'weights version [0-9]* (updates' "$out/logs/policy_env$k.log" || true)
  echo "  policy_env$k: $(printf '%s' "$switches" | grep -c . || true) weights loaded, last: $(printf '%s' "$switches" | tail -1 | sed 's/.*\] //')" >&2
done
report_traffic
"$EQUIARM_BIN" bag info "$bag" | grep -E 'Messages|/episodes|/transitions|/policy' || true
exit $status
