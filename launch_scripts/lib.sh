# shellcheck shell=bash
# Shared by the launch scripts (sourced, not run): find or build the equiarm binary, start processes
# each in its own process group, and stop them all (SIGINT, up to 10 s, then SIGKILL).
#
#   source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
#   eqa_default_signals "$0" "$@"   # first: makes SIGINT trappable when the script started with it ignored
#   eqa_bin                      # sets EQUIARM_BIN (builds once when it is unset)
#   eqa_start NAME LOG cmd...    # starts cmd in a new session (own process group), logs to LOG
#   eqa_stop_all                 # SIGINT to every group started, wait <= EQA_STOP_TIMEOUT_S, SIGKILL
#   trap eqa_on_exit EXIT; trap 'exit 130' INT; trap 'exit 143' TERM

EQA_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
EQA_PIDS=()
EQA_NAMES=()
EQA_STOP_TIMEOUT_S=${EQA_STOP_TIMEOUT_S:-10}
EQA_EXIT_MESSAGE=""  # printed after everything stopped, on any exit
EQA_DEFAULT_SIGNAL=()
if env --default-signal=INT true 2>/dev/null; then EQA_DEFAULT_SIGNAL=(env --default-signal=INT,QUIT); fi

# eqa_default_signals "$0" "$@": call before the script changes directory or parses its arguments.
# A script started with SIGINT ignored (a background job of another script, `cmd &`) can neither trap
# nor reset it, so Ctrl-C or `kill -INT` would not stop it; this runs the script again, in the same
# process, with SIGINT and SIGQUIT at their defaults. Without `env --default-signal` it does nothing.
eqa_default_signals() {
  if [ -n "$(trap -p INT)" ] && [ ${#EQA_DEFAULT_SIGNAL[@]} -gt 0 ]; then
    exec "${EQA_DEFAULT_SIGNAL[@]}" bash "$@"
  fi
}

eqa_log() { printf '[%s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

# eqa_private_netns SCRIPT ARGS...: runs the script again (once, replacing this process) in a private
# network namespace (as root, or with unprivileged user namespaces) so that its DDS traffic stays on
# this machine's loopback; inside it, brings loopback up with multicast. Where no namespace can be
# made it says so and the script goes on on the host's interfaces. (The benchmarks that start suites.)
eqa_private_netns() {
  if [ -z "${EQA_PRIVATE_NETNS:-}" ]; then
    local ns
    for ns in "unshare -n" "unshare -rn"; do
      if $ns true 2>/dev/null; then exec $ns env EQA_PRIVATE_NETNS=1 bash "$@"; fi
    done
    eqa_log "$(basename "$1"): cannot create a network namespace; running on the host's interfaces"
  else
    ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo 2>/dev/null || true
  fi
}

# The build the launch scripts and the test command share (tests/run_all.sh builds the same): the dev
# profile (dependencies and the hot crates optimised) of every program, as the GPU build (the CPU
# stays the default device; docs/backends.md), so whichever runs first builds for both.
# Where every sim a script starts begins its stamps' clock (`equiarm sim --stamp-origin`): the
# script's start in whole seconds since 1970, one value for all its sims, so viewers show the run's
# date and the envs' stamps line up; EQA_STAMP_ORIGIN=zero gives stamps from 0 (the same bytes every run).
EQA_STAMP_ORIGIN=${EQA_STAMP_ORIGIN:-$(date +%s)}
EQA_FEATURES=(--features vulkan)
EQA_BUILD=(cargo build --locked --workspace --bins "${EQA_FEATURES[@]}")

# EQUIARM_BIN when set (nothing is built); else EQA_BUILD into CARGO_TARGET_DIR (default
# ~/.cache/equiarm/target).
eqa_bin() {
  if [ -n "${EQUIARM_BIN:-}" ]; then
    [ -x "$EQUIARM_BIN" ] || command -v "$EQUIARM_BIN" >/dev/null \
      || { eqa_log "EQUIARM_BIN=$EQUIARM_BIN is not an executable"; return 1; }
    return 0
  fi
  export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
  eqa_log "building equiarm (${EQA_BUILD[*]}, target dir $CARGO_TARGET_DIR)"
  (cd "$EQA_ROOT" && "${EQA_BUILD[@]}") >&2
  EQUIARM_BIN="$CARGO_TARGET_DIR/debug/equiarm"
  export EQUIARM_BIN
}

# eqa_secure RUN_DIR NUM_ENVS: DDS Security for a run of the suite (docs/security.md): the keystore
# ROS_SECURITY_KEYSTORE names, else RUN_DIR/keystore (made on first use, reused by a resumed run), an
# enclave for each node (the trainer, the recorder, /env0 … /envN-1 and /eval's sim and policy), and
# the ROS 2 security variables (Enforce) that every node started afterwards reads. With
# EQUIARM_SECURITY_KEY_PASSWORD_FILE set, new enclaves' keys are encrypted with that file's password
# (and the nodes decrypt them with it).
eqa_secure() {
  local run_dir=$1 n=$2 ks e pw=()
  [ -n "${EQUIARM_SECURITY_KEY_PASSWORD_FILE:-}" ] && pw=(--key-password-file "$EQUIARM_SECURITY_KEY_PASSWORD_FILE")
  ks=${ROS_SECURITY_KEYSTORE:-$run_dir/keystore}
  if [ ! -e "$ks/enclaves/governance.p7s" ]; then
    "$EQUIARM_BIN" security create-keystore "$ks" >/dev/null || return 1
  fi
  local enclaves=(/equiarm/trainer /equiarm/equiarm_recorder /equiarm/eval/sim /equiarm/eval/policy)
  for i in $(seq 0 $((n - 1))); do enclaves+=("/equiarm/env$i/sim" "/equiarm/env$i/policy"); done
  for e in "${enclaves[@]}"; do
    "$EQUIARM_BIN" security create-enclave "$ks" "$e" "${pw[@]}" >/dev/null || return 1
  done
  ROS_SECURITY_KEYSTORE=$(cd "$ks" && pwd)
  export ROS_SECURITY_KEYSTORE ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce
  eqa_log "DDS Security: keystore $ROS_SECURITY_KEYSTORE, ${#enclaves[@]} enclaves, Enforce"
}

# eqa_start NAME LOG cmd... : runs cmd in its own session and process group (setsid; the group id is
# the pid), stdout+stderr to LOG.
eqa_start() {
  local name=$1 log=$2
  shift 2
  # A script's background commands start with SIGINT ignored (and a script started in the background
  # cannot un-ignore it): reset it in the child with `env --default-signal` (coreutils >= 8.31) when
  # available, so that SIGINT stops the process.
  # The log is appended to: a resumed run keeps the logs of the part before.
  [ -s "$log" ] && echo "==== $(date '+%F %T') started again: $*" >> "$log"
  ( trap - INT QUIT; exec setsid "${EQA_DEFAULT_SIGNAL[@]}" "$@" >>"$log" 2>&1 </dev/null ) &
  EQA_PIDS+=("$!")
  EQA_NAMES+=("$name")
  eqa_log "started $name (pid $!): $*"
}

# Members of process group $1 that are not zombies.
eqa_group_alive() {
  ps -eo pgid=,stat= | awk -v g="$1" '$1 == g && $2 !~ /^Z/ { found = 1 } END { exit !found }'
}

# eqa_running NAME: true while the process started as NAME (or a member of its group) runs.
eqa_running() {
  local pid
  pid=$(eqa_pid "$1") && eqa_group_alive "$pid"
}

# eqa_stop NAME...: SIGINT to those groups, wait for them (<= EQA_STOP_TIMEOUT_S), then SIGKILL.
eqa_stop() {
  local names=" $* " pids=() i pid deadline left
  for i in "${!EQA_NAMES[@]}"; do
    [[ "$names" == *" ${EQA_NAMES[$i]} "* ]] && pids+=("${EQA_PIDS[$i]}")
  done
  _eqa_stop_pids "${pids[@]}"
}

eqa_stop_all() { _eqa_stop_pids "${EQA_PIDS[@]}"; }

_eqa_stop_pids() {
  local pid left deadline=$((SECONDS + EQA_STOP_TIMEOUT_S))
  [ $# -gt 0 ] || return 0
  for pid in "$@"; do kill -INT -- "-$pid" 2>/dev/null || true; done
  while :; do
    left=()
    for pid in "$@"; do eqa_group_alive "$pid" && left+=("$pid"); done
    [ ${#left[@]} -eq 0 ] && break
    if [ $SECONDS -ge $deadline ]; then
      eqa_log "still running after ${EQA_STOP_TIMEOUT_S} s, SIGKILL: process groups ${left[*]}"
      for pid in "${left[@]}"; do kill -KILL -- "-$pid" 2>/dev/null || true; done
      break
    fi
    sleep 0.2
  done
  for pid in "$@"; do wait "$pid" 2>/dev/null || true; done
}

# eqa_wait_for NAME TIMEOUT_S: waits until NAME exits (0) or the timeout passes (1).
eqa_wait_for() {
  local deadline=$((SECONDS + $2))
  while eqa_running "$1"; do
    [ $SECONDS -ge $deadline ] && return 1
    sleep 0.5
  done
  return 0
}

# eqa_exit_status NAME: exit status of the process started as NAME (waits for it to finish; a
# trapped signal interrupts the wait).
eqa_exit_status() {
  local pid
  pid=$(eqa_pid "$1") || return 127
  wait "$pid"
}

# eqa_pid NAME: the pid (= process group id) of the process started as NAME.
eqa_pid() {
  local i
  for i in "${!EQA_NAMES[@]}"; do
    [ "${EQA_NAMES[$i]}" = "$1" ] && { echo "${EQA_PIDS[$i]}"; return 0; }
  done
  return 1
}

# eqa_wait_log NAME LOG PATTERN TIMEOUT_S: waits until LOG contains PATTERN (0); 1 when NAME exits
# first or the timeout passes.
eqa_wait_log() {
  local deadline=$((SECONDS + $4))
  until grep -q -- "$3" "$2" 2>/dev/null; do
    eqa_running "$1" || return 1
    [ $SECONDS -ge $deadline ] && return 1
    sleep 0.2
  done
}

eqa_on_exit() {
  local rc=$?
  trap - EXIT INT TERM
  eqa_stop_all
  # a `tail --pid` follower (EQA_FOLLOW_PID) ends by itself once its process is gone; give it a
  # moment to print the last lines, then stop it (a script's background commands ignore SIGINT)
  if [ -n "${EQA_FOLLOW_PID:-}" ]; then
    local _i
    for _i in 1 2 3 4 5 6 7 8 9 10; do kill -0 "$EQA_FOLLOW_PID" 2>/dev/null || break; sleep 0.1; done
    kill "$EQA_FOLLOW_PID" 2>/dev/null || true
  fi
  [ -z "$EQA_EXIT_MESSAGE" ] || echo "$EQA_EXIT_MESSAGE"
  return $rc
}

# eqa_recorded_run OUT [TOPIC:TYPE...]: creates OUT/logs, sets EQA_BAG=OUT/bag (printed at exit; a run
# resumed in OUT records into the first free OUT/bag-2, OUT/bag-3, ..., the earlier bags kept whole),
# installs the exit and signal traps, starts the recorder of every topic and gives it a second to join
# the graph. The TOPIC:TYPE arguments (the callers pass each env's `observation` topic) are subscribed
# from the start too.
eqa_recorded_run() {
  mkdir -p "$1/logs"
  EQA_BAG="$1/bag"
  local n=2
  while [ -e "$EQA_BAG" ]; do EQA_BAG="$1/bag-$n"; n=$((n + 1)); done
  EQA_EXIT_MESSAGE="bag: $EQA_BAG"
  trap eqa_on_exit EXIT
  trap 'exit 130' INT
  trap 'exit 143' TERM
  # /episodes, /transitions and the given topics (each env's observation: a Transition names its
  # Observations by seq, so a bag without them is not self-contained) by name, so they are subscribed
  # from the start (`--all` looks for new topics every 100 ms and can miss the start of a short first
  # episode); the rest through --all.
  # EQA_RECORD_FLAGS: more recorder flags (train.sh --foxglove).
  eqa_start recorder "$1/logs/record.log" "$EQUIARM_BIN" record --all -q -o "$EQA_BAG" \
    ${EQA_RECORD_FLAGS[@]+"${EQA_RECORD_FLAGS[@]}"} /episodes:equiarm_msgs/msg/EpisodeResult /transitions:equiarm_msgs/msg/Transition "${@:2}"
  sleep 1
}

# The suite's nodes, as train.sh starts them (bench/soak.sh restarts some). They read: EQUIARM_BIN,
# run_dir (its config.json; logs go to run_dir/logs/NAME.log), task, seed, num_envs, image (the frame
# size), arch (the policies' architecture flags), per_env (expert episodes per env), pace (the
# training policies' pacing flags), trainer_mode, extra (more trainer flags) and sim_wait (the
# subscribers each sim waits for on /transitions and /episodes before its first step: the trainer, and
# the recorder when recording; unset: none).
# Start order: the recorder, the trainer, the policies, then the sims. Without multicast on the
# loopback interface (Linux's default `lo`) RustDDS discovers same-host participants by unicast to the
# first 12 participant ids only, so two participants started 13th and later never discover each
# other: those must be sims, which talk only to their policy, the trainer and the recorder.

# eqa_suite_trainer NAME [ARGS...]: the trainer, started as NAME with ARGS added; fails (1) when it has
# not joined the graph within 120 s.
eqa_suite_trainer() {
  local name=$1
  shift
  eqa_start "$name" "$run_dir/logs/$name.log" "$EQUIARM_BIN" train --config "$run_dir/config.json" \
    --run-dir "$run_dir" --eval-namespace /eval "${trainer_mode[@]}" "${extra[@]}" "$@"
  eqa_wait_log "$name" "$run_dir/logs/$name.log" "joined ROS 2 domain" 120 || {
    eqa_log "the trainer did not join the ROS 2 graph; see $run_dir/logs/$name.log"
    tail -n 20 "$run_dir/logs/$name.log" >&2
    return 1
  }
}

# The sims and policies (training and eval) run at niceness EQA_ENV_NICE (default 0: as the
# trainer), so that their many short steps can be kept from preempting the learner's threads.
eqa_env_nice() {
  if [ "${EQA_ENV_NICE:-0}" != 0 ]; then echo nice -n "$EQA_ENV_NICE"; fi
}

# eqa_suite_policies: the training policies (/env0 … /envN-1) and the greedy eval policy (/eval).
eqa_suite_policies() {
  local i every episodes rate
  for i in $(seq 0 $((num_envs - 1))); do
    eqa_start "policy$i" "$run_dir/logs/policy$i.log" $(eqa_env_nice) "$EQUIARM_BIN" policy --namespace "/env$i" --mode sample \
      "${arch[@]}" --seed $((seed * 1000 + i)) --expert-episodes "$per_env" "${pace[@]}"
  done
  # the eval pair plays the evaluations' episodes only: eval_episodes of them on the trainer's weights
  # of each evaluation (every eval_every updates), waiting in between (without evaluations: throttled)
  every=$(eqa_config_get "$run_dir/config.json" eval_every)
  episodes=$(eqa_config_get "$run_dir/config.json" eval_episodes)
  if [ "$every" -gt 0 ] && [ "$episodes" -gt 0 ]; then
    rate=(--eval-every "$every" --eval-episodes "$episodes")
  else
    rate=(--max-lead 50 --steps-per-update 1)
  fi
  eqa_start policy_eval "$run_dir/logs/policy_eval.log" $(eqa_env_nice) "$EQUIARM_BIN" policy --namespace /eval --mode greedy \
    "${arch[@]}" --seed $((seed * 1000 + 999)) "${rate[@]}"
}

# eqa_scene_args FILE: the sim flags for a training config's camera view, corruptions and arm
# (`--view V --corrupt C --arm A`, one per line). Where the config has no key: the default view, no
# corruption, and the arm hidden (a config without `arm` was written before the arm was drawn).
eqa_scene_args() {
  local view corrupt arm
  view=$(eqa_config_get "$1" view) corrupt=$(eqa_config_get "$1" corruption) arm=$(eqa_config_get "$1" arm)
  printf '%s\n' --view "${view:-side}" --corrupt "${corrupt:-none}" --arm "${arm:-hidden}"
}

# eqa_suite_sim I [NAME]: the sim of /envI, started as NAME (default simI), with the config's view and
# corruptions; /env0's also publishes its simulated time on /clock (for tools with use_sim_time).
eqa_suite_sim() {
  local i=$1 name=${2:-sim$1} clock=() scene
  [ "$i" -eq 0 ] && clock=(--clock)
  mapfile -t scene < <(eqa_scene_args "$run_dir/config.json")
  eqa_start "$name" "$run_dir/logs/$name.log" $(eqa_env_nice) "$EQUIARM_BIN" sim --namespace "/env$i" --task "$task" \
    --seed $((seed * 1000 + i)) --resolution "$image" "${scene[@]}" "${clock[@]}" --stamp-origin "$EQA_STAMP_ORIGIN" \
    --wait-subscribers "${sim_wait:-0}"
}

# eqa_suite_sims: the training sims and the eval sim.
eqa_suite_sims() {
  local i scene
  for i in $(seq 0 $((num_envs - 1))); do eqa_suite_sim "$i"; done
  mapfile -t scene < <(eqa_scene_args "$run_dir/config.json")
  eqa_start sim_eval "$run_dir/logs/sim_eval.log" $(eqa_env_nice) "$EQUIARM_BIN" sim --namespace /eval --eval --task "$task" \
    --seed $((seed * 1000 + 999)) --resolution "$image" "${scene[@]}" --stamp-origin "$EQA_STAMP_ORIGIN" \
    --wait-subscribers "${sim_wait:-0}"
}

# eqa_config_get FILE KEY: a number or string value of KEY in a config JSON (as written by
# `equiarm train --print-config`: one key per line; image_size, input_size, hidden and model are unique).
# A string value may hold commas (a list of corruptions); one with quotes or backslashes is not read.
eqa_config_get() {
  sed -n -e "s/^ *\"$2\": *\"\([^\"\\]*\)\",\{0,1\} *\$/\1/p" \
    -e "s/^ *\"$2\": *\([^\",]*\),\{0,1\} *\$/\1/p" "$1" | head -n 1
}

# eqa_demos_per_env FILE N: the config's demo episodes spread over N envs (rounded up, so at least
# one each): every training policy answers that many first episodes with the expert.
eqa_demos_per_env() {
  local demos
  demos=$(eqa_config_get "$1" demo_episodes)
  echo $(( (demos + $2 - 1) / $2 ))
}

# eqa_wait_sims TIMEOUT_S LOGDIR SIM...: waits until every named sim process has exited; fails (1) on
# a timeout, a sim's non-zero exit, or a policy_* / recorder process dying while sims still run.
eqa_wait_sims() {
  local timeout_s=$1 logs=$2 deadline=$(($1 + SECONDS)) s i rc ok=0 pending
  shift 2
  pending=("$@")
  while [ ${#pending[@]} -gt 0 ]; do
    local still=()
    for s in "${pending[@]}"; do
      if eqa_running "$s"; then
        still+=("$s")
      else
        rc=0; eqa_exit_status "$s" || rc=$?
        if [ $rc -eq 0 ]; then eqa_log "$s finished"
        else eqa_log "$s exited with status $rc (log: $logs/$s.log)"; ok=1; fi
      fi
    done
    pending=("${still[@]+"${still[@]}"}")
    [ ${#pending[@]} -eq 0 ] && break
    for i in "${!EQA_NAMES[@]}"; do
      case ${EQA_NAMES[$i]} in
        policy_*|recorder)
          if ! eqa_group_alive "${EQA_PIDS[$i]}"; then
            eqa_log "${EQA_NAMES[$i]} stopped while sims still run (log: $logs/${EQA_NAMES[$i]}.log):"
            tail -n 5 "$logs/${EQA_NAMES[$i]}.log" >&2 || true
            return 1
          fi ;;
      esac
    done
    if [ $SECONDS -ge $deadline ]; then
      eqa_log "timeout after $timeout_s s: still running: ${pending[*]}"
      return 1
    fi
    sleep 0.5
  done
  return $ok
}
