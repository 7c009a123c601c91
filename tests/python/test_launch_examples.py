"""Tests of the example scripts in launch_scripts/: drive_sim.py, read_bag.py and bag_transitions.py
against a real `equiarm sim` and `equiarm record`, and equiarm.launch.py with stub `launch`/`launch_ros` modules
(no ROS 2 needed).

    EQUIARM_BIN=target/debug/equiarm python -m pytest tests/python/test_launch_examples.py

The DDS tests need the binary (env `EQUIARM_BIN`; they are skipped with a message when it is unset)
and run in the network the test process is in, on a random ROS_DOMAIN_ID in 120..200 so that other
DDS programs on this host are unlikely to share the domain (RustDDS has no way to keep traffic on one
host, and this test does not create a network namespace: run pytest inside one, e.g. with
`unshare -n` and multicast on lo as tests/run_all.sh does, to be sure nothing leaves the machine).
"""

import importlib.util
import json
import os
import pathlib
import random
import signal
import subprocess
import sys
import time
import types

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "launch_scripts"
BIN = os.environ.get("EQUIARM_BIN")

needs_bin = pytest.mark.skipif(not BIN, reason="EQUIARM_BIN is not set: point it at a built `equiarm` "
                                                "binary to run the DDS tests of launch_scripts/")


def stop(proc, timeout=10):
    """SIGINT, wait, then SIGKILL: never leaves the process running."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


@pytest.fixture(scope="module")
def expert_session(tmp_path_factory):
    """A recorder, one block_pulling sim in /env0 driven by drive_sim.py with the expert for two
    episodes: (drive_sim's JSON lines, its exit status, the bag directory, the sim's exit status)."""
    if not BIN:
        pytest.skip("EQUIARM_BIN is not set")
    pytest.importorskip("cyclonedds")
    tmp = tmp_path_factory.mktemp("launch")
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(120, 200)), RUST_LOG="warn")
    bag = tmp / "bag"
    procs = []
    try:
        # Explicit topics, so the recorder subscribes before the sim starts (`--all` looks for new
        # topics once a second and can miss a short first episode).
        topics = ["/episodes:equiarm_msgs/msg/EpisodeResult", "/transitions:equiarm_msgs/msg/Transition",
                  "/env0/gripper_cmd:equiarm_msgs/msg/GripperCommand", "/env0/observation:equiarm_msgs/msg/Observation"]
        rec = subprocess.Popen([BIN, "record", "-q", "-o", str(bag), *topics], env=env,
                               stdout=subprocess.DEVNULL, stderr=open(tmp / "record.log", "w"))
        procs.append(rec)
        time.sleep(1.0)
        sim = subprocess.Popen([BIN, "sim", "--task", "block_pulling", "--namespace", "/env0", "--seed", "3",
                                "--resolution", "64", "--episodes", "2"], env=env,
                               stdout=subprocess.DEVNULL, stderr=open(tmp / "sim.log", "w"))
        procs.append(sim)
        drive = subprocess.run([sys.executable, str(SCRIPTS / "drive_sim.py"), "--namespace", "/env0",
                                "--episodes", "2", "--json", "--timeout-s", "150"], env=env,
                               capture_output=True, text=True, timeout=180)
        sim_rc = sim.wait(30)
        time.sleep(2.0)  # the recorder flushes every 250 ms; let the last samples arrive
        assert stop(rec) == 0, (tmp / "record.log").read_text()[-2000:]
        lines = [json.loads(line) for line in drive.stdout.splitlines() if line.startswith("{")]
        return lines, drive.returncode, drive.stderr, bag, sim_rc
    finally:
        for p in procs:
            stop(p)


@needs_bin
def test_drive_sim_expert_completes_two_episodes(expert_session):
    lines, rc, stderr, _, sim_rc = expert_session
    assert rc == 0, stderr[-2000:]
    assert sim_rc == 0
    episodes = [e for e in lines if e["event"] == "episode"]
    steps = [e for e in lines if e["event"] == "step"]
    assert len(episodes) == 2
    assert [e["episode"] for e in episodes] == [0, 1]
    assert all(e["env"] == "env0" and e["task"] == "block_pulling" and e["expert"] for e in episodes)
    assert sum(e["success"] for e in episodes) >= 1
    # one step line per Transition, each answered by the expert
    assert len(steps) == sum(e["steps"] for e in episodes)
    assert all(s["expert"] and s["source"] == 1 for s in steps)
    # Transitions name their observations by seq: consecutive frames of env0, numbered across
    # episodes (an episode's terminal frame is answered by nothing and named by no step as its obs)
    assert all(s["next_seq"] == s["seq"] + 1 for s in steps)
    for ep in episodes:
        mine = [s for s in steps if s["episode"] == ep["episode"]]
        assert [s["step"] for s in mine] == list(range(ep["steps"]))
        assert [s["seq"] for s in mine] == list(range(mine[0]["seq"], mine[0]["seq"] + ep["steps"]))
        assert sum(s["done"] or s["timeout"] for s in mine) == 1 and (mine[-1]["done"] or mine[-1]["timeout"])
    assert steps[0]["seq"] == 0
    ep1 = [s for s in steps if s["episode"] == 1]
    assert ep1[0]["seq"] == episodes[0]["steps"] + 1, "episode 1 starts after episode 0's terminal frame"
    # the holding flag comes from the Observation the driver answered
    assert all(isinstance(s["holding"], bool) for s in steps)
    assert lines[-1] == {"event": "done", "env": "env0", "episodes": 2,
                         "successes": sum(e["success"] for e in episodes)}


@needs_bin
def test_read_bag_matches_the_run_and_bag_eval(expert_session):
    pytest.importorskip("mcap_ros2")
    lines, _, _, bag, _ = expert_session
    out = subprocess.run([sys.executable, str(SCRIPTS / "read_bag.py"), str(bag), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    topics = s["topics"]
    assert topics["/episodes"] == {"type": "equiarm_msgs/msg/EpisodeResult", "count": 2}
    assert topics["/transitions"]["type"] == "equiarm_msgs/msg/Transition"
    assert topics["/env0/gripper_cmd"]["type"] == "equiarm_msgs/msg/GripperCommand"
    steps = [e for e in lines if e["event"] == "step"]
    assert topics["/transitions"]["count"] == len(steps)
    # every frame is on /env0/observation, each episode's terminal one included (re-publishes may add)
    assert topics["/env0/observation"]["type"] == "equiarm_msgs/msg/Observation"
    assert topics["/env0/observation"]["count"] >= len(steps) + 2
    driven = [(e["episode"], e["steps"], e["success"]) for e in lines if e["event"] == "episode"]
    assert [(e["episode"], e["steps"], e["success"]) for e in s["episodes"]] == driven
    assert s["eval"]["episodes"] == 0 and s["train"]["episodes"] == 2
    assert s["train"]["successes"] == sum(ok for _, _, ok in driven)
    # the program's own evaluation of the same bag agrees
    ev = json.loads(subprocess.run([BIN, "bag", "eval", str(bag), "--json"], capture_output=True, text=True,
                                   timeout=60, check=True).stdout)
    assert ev["episodes"] == 2
    total = [g for g in ev["groups"] if g["env"] == "*"]
    assert sum(g["successes"] for g in total) == s["train"]["successes"]
    # and the human-readable form prints the table
    text = subprocess.run([sys.executable, str(SCRIPTS / "read_bag.py"), str(bag)], capture_output=True,
                          text=True, timeout=120, check=True).stdout
    assert "/episodes" in text and "training:" in text and "env0" in text


@needs_bin
def test_bag_transitions_joins_every_recorded_step(expert_session, tmp_path):
    pytest.importorskip("mcap_ros2")
    lines, _, _, bag, _ = expert_session
    steps = [e for e in lines if e["event"] == "step"]
    npz = tmp_path / "t.npz"
    out = subprocess.run([sys.executable, str(SCRIPTS / "bag_transitions.py"), str(bag), "--json", "--npz", str(npz)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    assert (s["joined"], s["unmatched"], s["inconsistent"]) == (len(steps), 0, 0), s
    env0 = s["envs"]["env0"]
    assert env0["episodes"] == 2 and env0["done"] + env0["timeout"] == 2
    import numpy as np
    a = np.load(npz)
    assert a["obs_seq"].tolist() == [st["seq"] for st in steps]
    assert a["done"].tolist() == [st["done"] for st in steps] and a["reward"].tolist() == [st["reward"] for st in steps]
    assert a["obs_color"].shape == (len(steps), 64, 64, 3) and a["obs_depth"].shape == (len(steps), 64, 64)
    assert a["obs_holding"].tolist() == [st["holding"] for st in steps]
    # within an episode, each step's next_obs is the following step's obs
    for k in range(len(steps) - 1):
        if steps[k]["episode"] == steps[k + 1]["episode"]:
            assert np.array_equal(a["next_obs_color"][k], a["obs_color"][k + 1])
            assert np.array_equal(a["next_obs_depth"][k], a["obs_depth"][k + 1], equal_nan=True)


def test_drive_sim_driver_answers_all_but_terminal_frames(capsys):
    """drive_sim.py's transport-free Driver: a terminal Observation gets no command, a re-published one
    the same command again, and the step line comes from the Transition's own fields."""
    spec = importlib.util.spec_from_file_location("drive_sim", SCRIPTS / "drive_sim.py")
    ds = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ds)
    ns = types.SimpleNamespace
    args = ds.parse_args(["--namespace", "/env0", "--json"])
    drv = ds.Driver(args, lambda *a: ns(obs_seq=a[0], args=a))
    expert = ns(open_ratio=0.5, dx=0.01, dy=0.02, dz=-0.03, dtheta=0.1)

    def obs(seq, step, terminal=False, env="env0", holding=False):
        return ns(env=env, seq=seq, episode=0, step=step, holding=holding, expert_action=expert,
                  terminal=terminal)

    def tr(obs_seq, step, done=False, env="env0"):
        return ns(env=env, episode=0, step=step, obs_seq=obs_seq, next_obs_seq=obs_seq + 1, reward=float(done),
                  done=done, timeout=False, expert=True, action=ns(open_ratio=0.5, dx=0.01, dy=0.02, dz=-0.03,
                                                                    dtheta=0.1, source=1))

    c0 = drv.on_observation(obs(0, 0, holding=True))
    assert c0.obs_seq == 0 and c0.args[1:] == (0.5, 0.01, 0.02, -0.03, 0.1, 1)
    assert drv.on_observation(obs(0, 0, holding=True)) is c0  # a re-published frame: the same command
    assert drv.on_observation(obs(0, 0, env="env1")) is None  # another env's
    c1 = drv.on_observation(obs(1, 1))
    drv.on_transition(tr(0, 0))
    assert drv.on_observation(obs(2, 2, terminal=True)) is None  # the episode's last frame
    drv.on_transition(tr(1, 1, done=True))
    drv.on_transition(tr(5, 0, env="env1"))  # another env's: no line
    assert c1.obs_seq == 1
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [(x["seq"], x["next_seq"], x["step"], x["holding"], x["done"]) for x in lines] == \
        [(0, 1, 0, True, False), (1, 2, 1, False, True)]
    assert all(x["event"] == "step" and x["env"] == "env0" and x["source"] == 1 for x in lines)
    assert not drv.holding  # nothing kept once the Transitions named the frames


def test_read_bag_metadata_parser():
    spec = importlib.util.spec_from_file_location("read_bag", SCRIPTS / "read_bag.py")
    rb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rb)
    meta = ("rosbag2_bagfile_information:\n  version: 8\n  storage_identifier: mcap\n"
            "  relative_file_paths:\n    - run_0.mcap\n    - run_1.mcap\n  duration:\n    nanoseconds: 5\n")
    assert rb.relative_file_paths(meta) == ["run_0.mcap", "run_1.mcap"]


# --- equiarm.launch.py with stub `launch` / `launch_ros` modules ---------------------------------------

class _Action:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


def _stub_launch_modules():
    class LaunchConfiguration:
        def __init__(self, name, default=None):
            self.name = name

        def perform(self, context):
            return context.launch_configurations[self.name]

    class DeclareLaunchArgument(_Action):
        def __init__(self, name, default_value=None, description=""):
            super().__init__(name)
            self.name, self.default_value = name, default_value

    class LaunchDescription(_Action):
        def __init__(self, entities=()):
            super().__init__()
            self.entities = list(entities)

    mods = {name: types.ModuleType(name) for name in
            ("launch", "launch.actions", "launch.substitutions", "launch_ros", "launch_ros.actions")}
    mods["launch"].LaunchDescription = LaunchDescription
    acts = mods["launch.actions"]
    acts.DeclareLaunchArgument = DeclareLaunchArgument
    for name in ("ExecuteProcess", "OpaqueFunction", "Shutdown", "RegisterEventHandler", "TimerAction",
                 "SetEnvironmentVariable", "LogInfo", "GroupAction"):
        setattr(acts, name, type(name, (_Action,), {}))
    mods["launch.substitutions"].LaunchConfiguration = LaunchConfiguration
    mods["launch_ros.actions"].Node = type("Node", (_Action,), {})
    mods["launch"].actions, mods["launch"].substitutions = acts, mods["launch.substitutions"]
    mods["launch_ros"].actions = mods["launch_ros.actions"]
    return mods


@pytest.fixture
def launch_file(monkeypatch):
    for name, mod in _stub_launch_modules().items():
        monkeypatch.setitem(sys.modules, name, mod)
    spec = importlib.util.spec_from_file_location("equiarm_launch", SCRIPTS / "equiarm.launch.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)

    def processes(**overrides):
        ld = mod.generate_launch_description()
        declared = {e.name: e.default_value for e in ld.entities if type(e).__name__ == "DeclareLaunchArgument"}
        unknown = set(overrides) - set(declared)
        assert not unknown, f"not declared: {unknown}"
        context = types.SimpleNamespace(launch_configurations={**declared, **overrides})
        (opaque,) = [e for e in ld.entities if type(e).__name__ == "OpaqueFunction"]
        actions = opaque.kwargs["function"](context)
        assert all(type(a).__name__ == "ExecuteProcess" for a in actions)
        return declared, {a.kwargs["name"]: a for a in actions}

    return processes


def _flag(cmd, name):
    return cmd[cmd.index(name) + 1]


def test_launch_file_declares_its_arguments(launch_file):
    declared, _ = launch_file()
    for name in ("task", "preset", "num_envs", "seed", "run_dir", "total_updates", "deterministic", "equiarm"):
        assert name in declared
    assert declared["equiarm"] == "equiarm" and declared["preset"] == "reduced16"


def test_launch_file_starts_n_pairs_eval_trainer_and_recorder(launch_file):
    _, procs = launch_file(task="block_picking", num_envs="3", seed="7", run_dir="runs/x", total_updates="40",
                           equiarm="/opt/eq/equiarm")
    cfg = json.loads((SCRIPTS / "configs" / "reduced16_block_picking.json").read_text())
    frame, image = cfg["image_size"], f"{cfg['image_size']}:{cfg['agent']['input_size']}"
    assert sorted(procs) == sorted(["recorder", "trainer", "sim_env0", "policy_env0", "sim_env1", "policy_env1",
                                    "sim_env2", "policy_env2", "sim_eval", "policy_eval"])
    assert all(p.kwargs["cmd"][0] == "/opt/eq/equiarm" for p in procs.values())
    assert procs["recorder"].kwargs["cmd"][1:6] == ["record", "--all", "-q", "-o", os.path.join("runs/x", "bag")]
    assert "/transitions:equiarm_msgs/msg/Transition" in procs["recorder"].kwargs["cmd"]
    # the observations the Transitions name, subscribed from the start: a self-contained bag
    for ns in ("/env0", "/env1", "/env2", "/eval"):
        assert f"{ns}/observation:equiarm_msgs/msg/Observation" in procs["recorder"].kwargs["cmd"]
    tr = procs["trainer"].kwargs["cmd"]
    assert tr[1] == "train" and "--in-process" not in tr
    assert (_flag(tr, "--preset"), _flag(tr, "--task"), _flag(tr, "--num-envs"), _flag(tr, "--seed"),
            _flag(tr, "--run-dir"), _flag(tr, "--total-updates"), _flag(tr, "--eval-namespace")) == \
        ("reduced16", "block_picking", "3", "7", "runs/x", "40", "/eval")
    assert "on_exit" in procs["trainer"].kwargs  # the launch ends with the trainer
    origins = set()
    for k, ns in enumerate(["/env0", "/env1", "/env2", "/eval"]):
        name = ns.strip("/")
        sim, pol = procs[f"sim_{name}"].kwargs["cmd"], procs[f"policy_{name}"].kwargs["cmd"]
        seed = 7000 + (999 if ns == "/eval" else k)
        assert sim[1] == "sim" and _flag(sim, "--namespace") == ns and _flag(sim, "--task") == "block_picking"
        assert _flag(sim, "--seed") == str(seed) and _flag(sim, "--resolution") == str(frame)
        assert ("--eval" in sim) == (ns == "/eval")
        assert (_flag(sim, "--view"), _flag(sim, "--corrupt"), _flag(sim, "--arm")) == ("side", "none", "visible")
        assert ("--clock" in sim) == (ns == "/env0"), "exactly one sim publishes /clock"
        assert _flag(sim, "--wait-subscribers") == "2", "the sims wait for the trainer and the recorder"
        origins.add(_flag(sim, "--stamp-origin"))
        assert pol[1] == "policy" and _flag(pol, "--namespace") == ns
        assert _flag(pol, "--mode") == ("greedy" if ns == "/eval" else "sample")
        assert _flag(pol, "--image") == image and _flag(pol, "--hidden") == str(cfg["agent"]["hidden"])
        assert _flag(pol, "--model") == cfg["agent"]["model"]
        if ns != "/eval":  # demos spread over the 3 envs, flow control on the trainer
            assert _flag(pol, "--expert-episodes") == str((cfg["demo_episodes"] + 2) // 3)
            assert _flag(pol, "--max-lead") == "10" and "--deterministic" not in pol
        else:  # the evaluations' episodes only, in windows
            assert (_flag(pol, "--eval-every"), _flag(pol, "--eval-episodes")) == \
                (str(cfg["eval_every"]), str(cfg["eval_episodes"]))
            assert "--max-lead" not in pol
    assert "--deterministic" not in tr
    # one clock origin for every sim: the launch's start (whole seconds since 1970), not 1970 itself
    (origin,) = origins
    assert abs(int(origin) - time.time()) < 600, origins


def test_launch_file_secure_makes_the_keystore_and_secures_every_process(launch_file, tmp_path, monkeypatch):
    """secure:=true as train.sh --secure: the run's keystore with an enclave per node (made with the
    real binary), and every process started with the ROS 2 security variables (Enforce)."""
    monkeypatch.delenv("ROS_SECURITY_KEYSTORE", raising=False)
    run = tmp_path / "run"
    _, procs = launch_file(num_envs="2", run_dir=str(run), equiarm=BIN, secure="true")
    ks = run / "keystore"
    listed = subprocess.run([BIN, "security", "list-enclaves", str(ks)], capture_output=True, text=True, check=True)
    assert sorted(listed.stdout.split()) == sorted(
        ["/equiarm/trainer", "/equiarm/equiarm_recorder", "/equiarm/eval/sim", "/equiarm/eval/policy",
         "/equiarm/env0/sim", "/equiarm/env0/policy", "/equiarm/env1/sim", "/equiarm/env1/policy"])
    for name, p in procs.items():
        env = p.kwargs.get("additional_env", {})
        assert env == {"ROS_SECURITY_KEYSTORE": str(ks), "ROS_SECURITY_ENABLE": "true",
                       "ROS_SECURITY_STRATEGY": "Enforce"}, name
    # a second launch reuses the keystore (the identities stay)
    cert = (ks / "enclaves/equiarm/trainer/cert.pem").read_bytes()
    launch_file(num_envs="2", run_dir=str(run), equiarm=BIN, secure="true")
    assert (ks / "enclaves/equiarm/trainer/cert.pem").read_bytes() == cert
    # without it, no security variables
    _, plain = launch_file(num_envs="2", run_dir=str(tmp_path / "plain"), equiarm=BIN)
    assert all("additional_env" not in p.kwargs for p in plain.values())
    assert not (tmp_path / "plain" / "keystore").exists()


def test_launch_file_deterministic_matches_train_sh(launch_file):
    _, procs = launch_file(num_envs="2", deterministic="true")
    assert "--deterministic" in procs["trainer"].kwargs["cmd"]
    for ns in ("env0", "env1"):
        pol = procs[f"policy_{ns}"].kwargs["cmd"]
        assert "--deterministic" in pol and "--max-lead" not in pol
    assert "--deterministic" not in procs["policy_eval"].kwargs["cmd"]


def test_launch_file_paper_preset_and_config_file(launch_file, tmp_path):
    _, procs = launch_file(preset="paper", num_envs="1")
    paper = json.loads((SCRIPTS / "configs" / "paper_block_pulling.json").read_text())
    assert _flag(procs["policy_env0"].kwargs["cmd"], "--image") == \
        f"{paper['image_size']}:{paper['agent']['input_size']}"
    assert "--total-updates" not in procs["trainer"].kwargs["cmd"]
    cfg = dict(paper, image_size=100, agent=dict(paper["agent"], input_size=90, hidden=8, model="cnn"),
               view="angle30", corruption="random_reflection,gripper_only", arm="hidden")
    f = tmp_path / "mine.json"
    f.write_text(json.dumps(cfg))
    _, procs = launch_file(config=str(f), num_envs="2", model="sen")
    tr = procs["trainer"].kwargs["cmd"]
    assert _flag(tr, "--config") == str(f) and "--preset" not in tr and _flag(tr, "--model") == "sen"
    pol = procs["policy_env1"].kwargs["cmd"]
    assert (_flag(pol, "--image"), _flag(pol, "--hidden"), _flag(pol, "--model")) == ("100:90", "8", "sen")
    sims = [p.kwargs["cmd"] for name, p in procs.items() if name.startswith("sim_")]
    assert len(sims) == 3
    # the sims render the config's scene, or the trainer learns from another camera than it was told
    assert all((_flag(s, "--view"), _flag(s, "--corrupt"), _flag(s, "--arm")) ==
               ("angle30", "random_reflection,gripper_only", "hidden") for s in sims)
    # a config written before the arm was drawn has no `arm`: its scene had none
    del cfg["arm"]
    f.write_text(json.dumps(cfg))
    _, procs = launch_file(config=str(f), num_envs="1")
    assert all(_flag(p.kwargs["cmd"], "--arm") == "hidden" for name, p in procs.items() if name.startswith("sim_"))


def test_launch_scripts_compile():
    for name in ("equiarm.launch.py", "drive_sim.py", "read_bag.py", "bag_transitions.py"):
        compile((SCRIPTS / name).read_text(), name, "exec")


# --- demo.sh and eval.sh ------------------------------------------------------------------------------

def _has_policy(binary):
    return subprocess.run([binary, "policy", "--help"], capture_output=True, timeout=30).returncode == 0


def _policy_shim(tmp_path):
    """EQUIARM_BIN for the scripts: the real binary, except that while it has no `policy` subcommand,
    `policy --mode expert|greedy` is emulated by drive_sim.py answering with the expert action."""
    if _has_policy(BIN):
        return BIN
    shim = tmp_path / "equiarm"
    shim.write_text(f"""#!/usr/bin/env bash
if [ "$1" = policy ]; then
  shift; ns=/env0
  while [ $# -gt 0 ]; do case $1 in --namespace) ns=$2; shift 2 ;; *) shift ;; esac; done
  exec {sys.executable} {SCRIPTS / 'drive_sim.py'} --namespace "$ns" --episodes 1000000 --quiet-steps --timeout-s 600
fi
exec {BIN} "$@"
""")
    shim.chmod(0o755)
    return str(shim)


def _leftovers(marker):
    out = subprocess.run(["ps", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if marker in line and "ps -eo" not in line]


@needs_bin
def test_demo_sh_records_expert_episodes_and_leaves_nothing_running(tmp_path):
    pytest.importorskip("cyclonedds")
    pytest.importorskip("mcap_ros2")
    out = tmp_path / "demo"
    env = dict(os.environ, EQUIARM_BIN=_policy_shim(tmp_path), ROS_DOMAIN_ID=str(random.randint(120, 200)))
    env.pop("EQA_STAMP_ORIGIN", None)
    started = int(time.time())
    r = subprocess.run(["bash", str(SCRIPTS / "demo.sh"), "--num-envs", "2", "--episodes", "2", "--out", str(out)],
                       env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    # the stamps' clock starts at the script's start (one origin for both envs), not in 1970
    from bag_check import read_mcap
    first = {}
    for topic, _, _, _, msg in read_mcap(out / "bag"):
        if topic.endswith("/observation"):
            t = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            first[topic] = min(first.get(topic, t), t)
    assert sorted(first) == ["/env0/observation", "/env1/observation"], first
    assert len(set(first.values())) == 1, first
    assert started <= next(iter(first.values())) // 10**9 <= time.time(), (started, first)
    assert f"bag: {out / 'bag'}" in r.stdout
    assert "4 episodes" in r.stdout  # equiarm bag eval's table
    s = json.loads(subprocess.run([sys.executable, str(SCRIPTS / "read_bag.py"), str(out / "bag"), "--json"],
                                  capture_output=True, text=True, timeout=120, check=True).stdout)
    assert sorted((e["env"], e["episode"]) for e in s["episodes"]) == [("env0", 0), ("env0", 1), ("env1", 0), ("env1", 1)]
    assert all(e["expert"] for e in s["episodes"]) and s["train"]["successes"] >= 2
    # lib.sh records each env's observation topic: every Transition joins with its two Observations
    j = json.loads(subprocess.run([sys.executable, str(SCRIPTS / "bag_transitions.py"), str(out / "bag"), "--json"],
                                  capture_output=True, text=True, timeout=120, check=True).stdout)
    assert (j["joined"], j["unmatched"], j["inconsistent"]) == (sum(e["steps"] for e in s["episodes"]), 0, 0), j
    assert sorted(j["envs"]) == ["env0", "env1"]
    assert not _leftovers(str(out)), _leftovers(str(out))


@needs_bin
def test_eval_sh_video_writes_one_mp4_per_episode(tmp_path):
    """eval.sh --video on a committed checkpoint: the bag's episodes as videos that PyAV decodes, one
    frame per step plus the last, at the simulated rate (6 fps for the default physics)."""
    av = pytest.importorskip("av")
    run = ROOT / "crates" / "train" / "tests" / "fixtures" / "run_before_types"
    out = tmp_path / "eval"
    env = dict(os.environ, EQUIARM_BIN=BIN, ROS_DOMAIN_ID=str(random.randint(120, 200)))
    r = subprocess.run(["bash", str(SCRIPTS / "eval.sh"), "--checkpoint", str(run / "checkpoints" / "latest"),
                        "--config", str(run / "config.json"), "--episodes", "2", "--out", str(out), "--video"],
                       env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    s = json.loads(subprocess.run([sys.executable, str(SCRIPTS / "read_bag.py"), str(out / "bag"), "--json"],
                                  capture_output=True, text=True, timeout=120, check=True).stdout)
    videos = sorted((out / "videos").iterdir())
    assert [v.name for v in videos] == [f"eval_ep{e['episode']:04}.mp4" for e in sorted(s["episodes"], key=lambda e: e["episode"])]
    for v, e in zip(videos, sorted(s["episodes"], key=lambda e: e["episode"])):
        with av.open(str(v)) as c:
            stream = c.streams.video[0]
            assert sum(1 for _ in c.decode(stream)) == e["steps"] + 1, v
            assert stream.average_rate == 6
    assert not _leftovers(str(out)), _leftovers(str(out))


def test_eval_sh_refuses_without_a_checkpoint(tmp_path):
    r = subprocess.run(["bash", str(SCRIPTS / "eval.sh"), "--task", "block_pulling"], capture_output=True,
                       text=True, timeout=30, env=dict(os.environ, EQUIARM_BIN="/bin/true"))
    assert r.returncode == 2 and "--checkpoint" in r.stderr
    r = subprocess.run(["bash", str(SCRIPTS / "eval.sh"), "--checkpoint", str(tmp_path / "none")],
                       capture_output=True, text=True, timeout=30, env=dict(os.environ, EQUIARM_BIN="/bin/true"))
    assert r.returncode == 2 and "does not exist" in r.stderr


def test_train_sh_never_overwrites_a_run(tmp_path):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "metrics.csv").write_text("kept\n")
    (run / "config.json").write_text("{\"old\": 1}\n")
    env = dict(os.environ, EQUIARM_BIN="/bin/false", ROS_DOMAIN_ID="77")
    r = subprocess.run(["bash", str(SCRIPTS / "train.sh"), "--run-dir", str(run)], capture_output=True, text=True,
                       timeout=30, env=env)
    assert r.returncode == 2 and "holds a run already (metrics.csv checkpoints)" in r.stderr, r.stderr
    assert "--force" in r.stderr
    assert (run / "metrics.csv").read_text() == "kept\n" and (run / "config.json").read_text() == "{\"old\": 1}\n"
    # --force moves the old run aside whole before anything is written (here /bin/false then
    # fails the config step, which is beside the point).
    r = subprocess.run(["bash", str(SCRIPTS / "train.sh"), "--run-dir", str(run), "--force"], capture_output=True,
                       text=True, timeout=30, env=env)
    assert "moved aside to" in r.stdout, r.stdout + r.stderr
    old = tmp_path / "run.old-1"
    assert (old / "metrics.csv").read_text() == "kept\n" and (old / "config.json").read_text() == "{\"old\": 1}\n"
    assert (old / "checkpoints").is_dir() and not (run / "metrics.csv").exists()


def test_multihost_sh_skips_without_root():
    if os.geteuid() == 0 and not _can_drop_root():
        pytest.skip("running as root without setpriv")
    cmd = ["bash", str(SCRIPTS / "multihost.sh"), "--check-discovery"]
    if os.geteuid() == 0:
        cmd = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"] + cmd
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    assert r.returncode == 0 and "skipped" in r.stdout, r.stdout + r.stderr


def _can_drop_root():
    import shutil
    return shutil.which("setpriv") is not None
