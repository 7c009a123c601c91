#!/usr/bin/env bash
# The main job: the whole suite training on one task over DDS on this machine.
#
# Builds `equiarm` once (the optimised dev profile the tests use, in CARGO_TARGET_DIR, by default a
# folder outside the clone shared with the test command), then starts, each in its own process group:
#   - the recorder        equiarm record --all -o RUN/bag
#   - the trainer         equiarm train (SAC + prioritised replay; weights out on /policy/weights)
#   - N sim+policy pairs  /env0 … /envN-1 (the policy answers the first --demo-episodes episodes of
#                         each env with the expert, then samples from the learned actor)
#   - one eval pair       /eval (greedy policy; its episodes are the trainer's evaluations)
# (in that order, all policies before all sims: see "Start order" below), follows the trainer's
# output until it finishes, stops every process cleanly (also on Ctrl-C: SIGINT, the trainer then
# saves a checkpoint; SIGKILL after EQA_STOP_TIMEOUT_S, default 30 s), and prints the evaluation
# table and where the bag, checkpoints, metrics and learning curve are.
#
# Options (defaults: block pulling at the reduced16 CPU config, 5 envs, seed 0):
#   --task T            block_pulling | block_pushing | block_picking | drawer_opening | block_in_bowl
#   --preset P          reduced16 (2-core CPU, ~50 min) | reduced (hidden 8, 1,250 updates: fast, learns little) | paper (docs/paper.md §2, for a GPU)
#   --config FILE       a JSON run config (launch_scripts/configs/*.json); replaces the preset
#   --num-envs N        sim+policy pairs (the paper uses 5)
#   --seed S            base seed
#   --run-dir DIR       where everything goes (default runs/<task>-<date>)
#   --total-updates U   override the config's number of updates
#   --no-record         do not record a bag
#   --foxglove [H:]PORT the recorder also serves the run to Foxglove over WebSocket (PORT on loopback,
#                       or H:PORT): open ws://127.0.0.1:PORT in Foxglove, no ROS install needed
#   --force             a --run-dir that holds a run (metrics, checkpoints) is moved aside to
#                       RUN_DIR.old-N first (without it such a directory is refused)
#   --secure            DDS Security (SROS2, docs/security.md): every node joins in its own enclave of
#                       the keystore ROS_SECURITY_KEYSTORE names, else RUN/keystore (made, then reused)
#   --deterministic     lock-step rounds: the trainer and the training policies get --deterministic
#                       (no --max-lead); with one seed two runs record the same /transitions of the
#                       training envs and end with the same weights. The eval pair is not lock-stepped:
#                       it evaluates whatever weights are current, so evaluations may differ.
#   -- ARGS...          passed on to `equiarm train`; `--run-dir RUN -- --resume RUN` continues the run
#                       in RUN (its recorder writes a new bag beside the first: RUN/bag-2, ...)
# Environment: ROS_DOMAIN_ID (default 0), ROS_LOCALHOST_ONLY (default 1: loopback only),
# EQUIARM_BIN (use this binary instead of building), CARGO_TARGET_DIR, EQA_ENV_NICE (niceness of the
# sims and policies, default 0: as the trainer and the recorder).
#
# Example: bash launch_scripts/train.sh --task block_pulling --num-envs 5
set -euo pipefail
# before lib.sh, whose default is 10 s
export EQA_STOP_TIMEOUT_S=${EQA_STOP_TIMEOUT_S:-30}
source "$(dirname "$0")/lib.sh"
eqa_default_signals "$0" "$@"
cd "$(dirname "$0")/.."

task=block_pulling preset=reduced16 config="" num_envs=5 seed=0 run_dir="" total_updates="" record=1 det=0 force=0 secure=0
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --task) task=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --config) config=$2; shift 2 ;;
    --num-envs) num_envs=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --run-dir) run_dir=$2; shift 2 ;;
    --total-updates) total_updates=$2; shift 2 ;;
    --no-record) record=0; shift ;;
    --foxglove) EQA_RECORD_FLAGS=(--foxglove "$2"); shift 2 ;;
    --force) force=1; shift ;;
    --deterministic) det=1; shift ;;
    --secure) secure=1; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,40p' "$0"; exit 0 ;;
    *) echo "train.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
run_dir=${run_dir:-runs/$task-$(date +%Y%m%d-%H%M%S)}
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}
export ROS_LOCALHOST_ONLY=${ROS_LOCALHOST_ONLY:-1}
# Logging: the nodes' own default filter (info, RustDDS's per-sample warnings off) unless RUST_LOG is set.

eqa_bin
bin=$EQUIARM_BIN

# Never overwrite a run: a directory holding one is refused, or moved aside with --force (a
# `-- --resume` of that run continues in it: the trainer checks that). What holds a run is the
# trainer's list (`equiarm_train::rundir::RUN_FILES`) plus the bag, which this script's recorder
# writes before the trainer starts, so the check has to happen here, before anything is written.
held=()
if [[ " ${extra[*]} " != *" --resume "* ]]; then
  for f in metrics.csv metrics.jsonl evals.json checkpoints bag; do [ -e "$run_dir/$f" ] && held+=("$f"); done
fi
if [ ${#held[@]} -gt 0 ]; then
  if [ $force = 0 ]; then
    echo "train.sh: $run_dir holds a run already (${held[*]}): choose another --run-dir, or pass --force to move it aside" >&2
    exit 2
  fi
  n=1; while [ -e "$run_dir.old-$n" ]; do n=$((n + 1)); done
  mv "$run_dir" "$run_dir.old-$n"
  echo "== the previous run in $run_dir was moved aside to $run_dir.old-$n"
fi
# The run config, resolved once and handed to every process.
mkdir -p "$run_dir"
cfg_args=(--preset "$preset" --task "$task" --num-envs "$num_envs" --seed "$seed")
[ -n "$config" ] && cfg_args+=(--config "$config")
[ -n "$total_updates" ] && cfg_args+=(--total-updates "$total_updates")
"$bin" train "${cfg_args[@]}" "${extra[@]}" --print-config > "$run_dir/config.json"
cfg_get() { eqa_config_get "$run_dir/config.json" "$1"; }
image=$(cfg_get image_size) input=$(cfg_get input_size) hidden=$(cfg_get hidden) model=$(cfg_get model)
# demo episodes spread over the envs (at least one each); the trainer drops unsuccessful ones
per_env=$(eqa_demos_per_env "$run_dir/config.json" "$num_envs")
arch=(--model "$model" --hidden "$hidden" --image "$image:$input")
# training policies: flow control on the trainer's update count, or the lock-step on weights versions
pace=(--max-lead 10) trainer_mode=()
[ $det = 1 ] && pace=(--deterministic) trainer_mode=(--deterministic)

[ $secure = 1 ] && { eqa_secure "$run_dir" "$num_envs" || exit 1; }
echo "== run directory $run_dir (ROS_DOMAIN_ID=$ROS_DOMAIN_ID, logs in $run_dir/logs)"
if [ $record = 1 ]; then
  obs_topics=(/eval/observation:equiarm_msgs/msg/Observation)
  for i in $(seq 0 $((num_envs - 1))); do obs_topics+=("/env$i/observation:equiarm_msgs/msg/Observation"); done
  eqa_recorded_run "$run_dir" "${obs_topics[@]}"
else
  mkdir -p "$run_dir/logs"
  trap eqa_on_exit EXIT; trap 'exit 130' INT; trap 'exit 143' TERM
fi
# Start order: the recorder, the trainer, the policies, then the sims (lib.sh, "The suite's nodes");
# each sim steps once the trainer (and the recorder) subscribe to its transitions.
sim_wait=$((1 + record))
# (the trainer's log is appended to: a resumed run's output is followed from where it starts)
log_from=$(( $(stat -c %s "$run_dir/logs/trainer.log" 2>/dev/null || echo 0) + 1 ))
eqa_suite_trainer trainer || exit 1
eqa_suite_policies
eqa_suite_sims

# The trainer's output (its progress line, then its evaluation table) follows on stdout until it exits.
tail -c +"$log_from" -f -s 0.2 --pid="$(eqa_pid trainer)" "$run_dir/logs/trainer.log" &
EQA_FOLLOW_PID=$!
set +e
eqa_exit_status trainer
status=$?
wait "$EQA_FOLLOW_PID" 2>/dev/null
set -e
echo "== training finished (exit $status); stopping the suite"
eqa_stop_all
if [ $record = 1 ] && [ -d "$EQA_BAG" ]; then
  echo "== bag"
  "$bin" bag info "$EQA_BAG" | head -20 || true
fi
exit $status
