"""ROS 2 launch file of the equiarm suite: the same processes as the bash scripts, started by
`ros2 launch`.

    ros2 launch launch_scripts/equiarm.launch.py task:=block_pulling num_envs:=5
    ros2 launch launch_scripts/equiarm.launch.py task:=drawer_opening preset:=paper run_dir:=runs/drawer \
        equiarm:=$HOME/.cache/equiarm/target/release/equiarm

Processes (all `ExecuteProcess`: equiarm is one Rust program, not a ROS package executable), the
same as `train.sh` starts:
- the recorder: `equiarm record --all -q -o <run_dir>/bag /episodes:... /transitions:...`;
- the trainer: `equiarm train --preset P --task T --num-envs N --seed S --run-dir <run_dir>
  --eval-namespace /eval [--total-updates U] [--model M] [--deterministic]` (over DDS); when it exits
  the whole launch shuts down (the recorder gets SIGINT and closes its bag);
- N training pairs: `equiarm sim --namespace /envK --task T --seed 1000·S+K --resolution FRAME`
  `--wait-subscribers 2` (`--clock` for /env0) and
  `equiarm policy --namespace /envK --mode sample --model M --hidden H --image FRAME:INPUT
  --seed 1000·S+K --expert-episodes D --max-lead 10` (D: the config's demo episodes spread over the
  envs; `--deterministic` instead of `--max-lead` with deterministic:=true);
- one evaluation pair in /eval: the sim with seed 1000·S+999 and `--eval`, the policy in
  `--mode greedy --eval-every E --eval-episodes K` (the config's eval_every and eval_episodes: it
  plays K episodes per evaluation, on the trainer's weights of that evaluation, and waits between).
FRAME, INPUT and H (and the default model) come from the preset's config,
`launch_scripts/configs/<preset>_<task>.json` (written by `configs/regenerate.sh` from
`equiarm train --print-config`), or from the file given as `config:=FILE.json`, which the trainer
then gets with `--config` instead of `--preset`.

Arguments: task, preset (reduced | reduced16 | paper), num_envs, seed, run_dir, total_updates (empty: the
preset's), model (empty: the config's), config (empty: the preset's file), deterministic (true: the
lock-step mode of `train.sh --deterministic`), equiarm (path of the
binary; default `equiarm` on PATH), stamp_origin (`--stamp-origin` of every sim: `launch`, the
default, is the launch's start time in whole seconds, one value for all, as train.sh gives), secure
(true: DDS Security as `train.sh --secure`, docs/security.md). ROS_DOMAIN_ID and the other ROS variables of the environment
apply to every process. Needs the `launch` package only (launch_ros is not used: no ROS package
executables are involved); nothing is built here.
"""

import json
import os
import subprocess
import time

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration

HERE = os.path.dirname(os.path.realpath(__file__))
EVAL_NAMESPACE = "/eval"
EVAL_SEED_OFFSET = 999

ARGUMENTS = [
    ("task", "block_pulling", "block_pulling, block_pushing, block_picking, drawer_opening or block_in_bowl"),
    ("preset", "reduced16", "reduced16 (2-core CPU, ~50 min), reduced (hidden 8, 1,250 updates: fast) or paper (the paper's sizes, docs/paper.md §2)"),
    ("num_envs", "5", "training sim+policy pairs /env0 ... /envN-1"),
    ("seed", "0", "base seed S: env K uses 1000*S+K, the eval env 1000*S+999 (as train.sh)"),
    ("run_dir", "runs/launch", "run directory of the trainer; the bag goes to <run_dir>/bag"),
    ("total_updates", "", "gradient updates (empty: the preset's)"),
    ("model", "", "equi, cnn, sen or ferm (empty: the config's)"),
    ("config", "", "a training config JSON instead of the preset (sizes are read from it)"),
    ("deterministic", "false", "true: lock-step rounds (train.sh --deterministic)"),
    ("equiarm", "equiarm", "path of the equiarm binary"),
    ("stamp_origin", "launch", "where the sims' stamps start: launch (the launch's start, the same for every sim, "
     "as train.sh), now (each sim's start), zero, or seconds since 1970"),
    ("secure", "false", "true: DDS Security as train.sh --secure (the keystore ROS_SECURITY_KEYSTORE names, else "
     "<run_dir>/keystore, made if missing; an enclave per node; Enforce)"),
]


def load_config(preset, task, config_file):
    path = config_file or os.path.join(HERE, "configs", f"{preset}_{task}.json")
    with open(path) as f:
        return json.load(f)


def commands(args):
    """The command lines, as (name, argv) pairs, for the launch arguments `args` (a dict of strings).
    Kept free of launch types so it can be read and tested on its own."""
    exe, task, preset, run_dir = args["equiarm"], args["task"], args["preset"], args["run_dir"]
    n, seed = int(args["num_envs"]), int(args["seed"])
    cfg = load_config(preset, task, args.get("config", ""))
    frame, size = int(cfg["image_size"]), int(cfg["agent"]["input_size"])
    hidden = int(cfg["agent"]["hidden"])
    model = args.get("model") or cfg["agent"]["model"]
    image = f"{frame}:{size}"
    # the scene the trainer's config names: its sims render that view with those corruptions
    view, corrupt = cfg.get("view", "side"), cfg.get("corruption", "none")
    arm = cfg.get("arm", "hidden")  # a config without the key was written before the arm was drawn

    deterministic = str(args.get("deterministic", "false")).lower() in ("1", "true", "yes")
    # by name, so they are subscribed from the start; each env's observation topic too (a Transition
    # names its two Observations by seq: without them a bag holds no images)
    recorded = ["/episodes:equiarm_msgs/msg/EpisodeResult", "/transitions:equiarm_msgs/msg/Transition"]
    recorded += [f"{ns}/observation:equiarm_msgs/msg/Observation" for ns in
                 [f"/env{k}" for k in range(n)] + [EVAL_NAMESPACE]]
    cmds = [("recorder", [exe, "record", "--all", "-q", "-o", os.path.join(run_dir, "bag")] + recorded)]
    trainer = [exe, "train"]
    trainer += ["--config", args["config"]] if args.get("config") else ["--preset", preset]
    trainer += ["--task", task, "--num-envs", str(n), "--seed", str(seed), "--run-dir", run_dir,
                "--eval-namespace", EVAL_NAMESPACE]
    if args.get("total_updates"):
        trainer += ["--total-updates", str(int(args["total_updates"]))]
    if args.get("model"):
        trainer += ["--model", model]
    if deterministic:
        trainer.append("--deterministic")
    cmds.append(("trainer", trainer))

    # as train.sh: demos spread over the envs, flow control (or lock-step), an eval pair in windows
    per_env = (int(cfg["demo_episodes"]) + n - 1) // n
    pace = ["--deterministic"] if deterministic else ["--max-lead", "10"]
    every, episodes = int(cfg["eval_every"]), int(cfg["eval_episodes"])
    # the eval pair plays the evaluations' episodes only (a config without evaluations: throttled)
    eval_pace = (["--eval-every", str(every), "--eval-episodes", str(episodes)] if every > 0 and episodes > 0
                 else ["--max-lead", "50", "--steps-per-update", "1"])

    def pair(ns, env_seed, mode, extra):
        name = ns.strip("/")
        sim = [exe, "sim", "--namespace", ns, "--task", task, "--seed", str(env_seed), "--resolution", str(frame),
               "--view", view, "--corrupt", corrupt, "--arm", arm, "--stamp-origin", args.get("stamp_origin", "zero"),
               "--wait-subscribers", "2"]  # as train.sh: steps once the trainer and the recorder subscribe
        if ns == EVAL_NAMESPACE:
            sim.append("--eval")  # its EpisodeResults are marked as evaluation episodes
        if ns == "/env0":
            sim.append("--clock")  # its simulated time on /clock, as train.sh does
        policy = [exe, "policy", "--namespace", ns, "--mode", mode, "--model", model, "--hidden", str(hidden),
                  "--image", image, "--seed", str(env_seed)] + extra
        return [(f"sim_{name}", sim), (f"policy_{name}", policy)]

    for k in range(n):
        cmds += pair(f"/env{k}", 1000 * seed + k, "sample", ["--expert-episodes", str(per_env)] + pace)
    cmds += pair(EVAL_NAMESPACE, 1000 * seed + EVAL_SEED_OFFSET, "greedy", eval_pace)
    return cmds


def security(args):
    """With secure:=true, as train.sh --secure (lib.sh's eqa_secure): the commands that make the keystore
    (if it has no governance yet) and an enclave for each node, and the variables every process gets;
    else nothing. Kept free of launch types, like `commands`."""
    if str(args.get("secure", "false")).lower() not in ("1", "true", "yes"):
        return [], {}
    exe = args["equiarm"]
    ks = os.path.abspath(os.environ.get("ROS_SECURITY_KEYSTORE") or os.path.join(args["run_dir"], "keystore"))
    make = [] if os.path.exists(os.path.join(ks, "enclaves", "governance.p7s")) else [[exe, "security", "create-keystore", ks]]
    enclaves = ["/equiarm/trainer", "/equiarm/equiarm_recorder", "/equiarm/eval/sim", "/equiarm/eval/policy"]
    enclaves += [f"/equiarm/env{k}/{node}" for k in range(int(args["num_envs"])) for node in ("sim", "policy")]
    make += [[exe, "security", "create-enclave", ks, e] for e in enclaves]
    return make, {"ROS_SECURITY_KEYSTORE": ks, "ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce"}


def launch_setup(context, *_args, **_kwargs):
    args = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    if args["stamp_origin"] == "launch":  # read once, so every sim's clock starts at the same time
        args["stamp_origin"] = str(int(time.time()))
    make_keystore, secure_env = security(args)
    for cmd in make_keystore:  # before any node starts: each checks its enclave as it joins
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    actions = []
    for name, cmd in commands(args):
        extra = {"additional_env": secure_env} if secure_env else {}
        if name == "trainer":
            extra["on_exit"] = Shutdown(reason="the trainer finished")
        # SIGINT first (launch's default on shutdown): the recorder closes its bag, the trainer checkpoints.
        actions.append(ExecuteProcess(cmd=cmd, name=name, output="screen", sigterm_timeout="10",
                                      sigkill_timeout="5", **extra))
    return actions


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=desc) for name, default, desc in ARGUMENTS]
        + [OpaqueFunction(function=launch_setup)]
    )
