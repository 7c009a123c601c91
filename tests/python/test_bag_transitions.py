"""Tests of launch_scripts/bag_transitions.py on small synthetic MCAP bags written here with the
`mcap` + `mcap-ros2-support` writer, the schemas being the rosbag2 "complete message definitions" built
from msgs/msg/*.msg and msgs/ros_std/ (as the recorder embeds them). No equiarm binary needed.

    python -m pytest tests/python/test_bag_transitions.py
"""

import importlib.util
import json
import pathlib
import re
import struct
import subprocess
import sys

import numpy as np
import pytest
import zstandard

pytest.importorskip("mcap_ros2")
from mcap_ros2.writer import Writer  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "launch_scripts" / "bag_transitions.py"
OBSERVATION, TRANSITION = "equiarm_msgs/msg/Observation", "equiarm_msgs/msg/Transition"
H, W = 3, 2  # image rows, columns


def msg_path(full):
    pkg, _, name = full.split("/")
    if pkg == "equiarm_msgs":
        return ROOT / "msgs" / "msg" / f"{name}.msg"
    return ROOT / "msgs" / "ros_std" / pkg / "msg" / f"{name}.msg"


def deps(full):
    """The message types a definition's fields use, as pkg/msg/Type, in field order."""
    pkg = full.split("/")[0]
    out = []
    for line in msg_path(full).read_text().splitlines():
        words = line.split("#", 1)[0].split()
        if len(words) < 2 or "=" in words[1]:
            continue  # blank, comment or constant
        line = " ".join(words)
        base = re.sub(r"\[.*\]$", "", line.split()[0])
        if base in ("bool", "byte", "char", "string", "wstring") or re.fullmatch(r"u?int\d+|float\d+", base):
            continue
        p, _, t = base.rpartition("/")
        out.append(f"{p or pkg}/msg/{t}")
    return out


def full_definition(full):
    """rosbag2's complete definition: the text, then each dependency once (depth first), each behind a
    line of 80 '=' and `MSG: pkg/Type`."""
    text, seen = msg_path(full).read_text(), set()

    def visit(name):
        nonlocal text
        for d in deps(name):
            if d not in seen:
                seen.add(d)
                pkg, _, t = d.split("/")
                text += "\n" + "=" * 80 + f"\nMSG: {pkg}/{t}\n" + msg_path(d).read_text()
                visit(d)

    visit(full)
    return text


def header(stamp_ns):
    return {"stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9}, "frame_id": "world"}


def color_pixels(env, seq):
    """(H, W, 3) uint8 that differs per env and seq."""
    base = (7 * seq + 100 * (env == "env1")) % 200
    return (np.arange(H * W * 3, dtype=np.uint8).reshape(H, W, 3) + base).astype(np.uint8)


def depth_pixels(env, seq):
    """(H, W) float32 metres, each exactly a half float (the Observation carries half floats)."""
    return (np.arange(H * W, dtype=np.float32).reshape(H, W) * 0.25 + seq + (10.0 if env == "env1" else 0.0))


def observation(env, seq, episode, step, terminal=False):
    z = zstandard.ZstdCompressor(level=1)
    return {
        "header": header(1000 + seq), "seq": seq, "env": env, "episode": episode, "step": step,
        "height": H, "width": W,
        "color": z.compress(color_pixels(env, seq).tobytes()),
        "depth": z.compress(depth_pixels(env, seq).astype("<f2").tobytes()),
        "holding": seq % 2 == 1,
        "expert_action": command(seq, 1),
        "terminal": terminal,
    }


def command(obs_seq, source):
    return {"header": header(0), "obs_seq": obs_seq, "open_ratio": 0.5, "dx": 0.01 * obs_seq, "dy": -0.02,
            "dz": 0.03, "dtheta": 0.1, "source": source}


def transition(env, episode, step, obs_seq, reward=0.0, done=False, timeout=False, expert=True):
    return {"header": header(1000 + obs_seq + 1), "env": env, "episode": episode, "step": step,
            "obs_seq": obs_seq, "next_obs_seq": obs_seq + 1, "action": command(obs_seq, 1 if expert else 0),
            "reward": reward, "done": done, "timeout": timeout, "expert": expert}


def write_bag(path: pathlib.Path, records):
    """records: [(topic, type, message dict)], written in that order with increasing log times."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        w = Writer(f)
        schemas = {name: w.register_msgdef(name, full_definition(name)) for name in (OBSERVATION, TRANSITION)}
        for k, (topic, type_name, msg) in enumerate(records):
            w.write_message(topic, schemas[type_name], msg, log_time=10**9 + k * 1000, sequence=k)
        w.finish()


def O(env, *args, **kw):  # noqa: N802
    return (f"/{env}/observation", OBSERVATION, observation(env, *args, **kw))


def T(env, *args, **kw):  # noqa: N802
    return ("/transitions", TRANSITION, transition(env, *args, **kw))


# env0: episode 0 = frames 0, 1, 2, 3 (3 terminal, done), episode 1 = frames 4, 5, 6 (bag cut before
# frame 6 was recorded: its transition stays unmatched). env1: episode 0 = frames 0, 1 (1 terminal, timeout).
# Written out of order: transitions before their observations, transitions swapped, frame 1
# re-published (once before, once after it was consumed), the terminal frame after its transition.
RECORDS = [
    T("env0", 0, 1, 1),                # before its observations and before step 0's transition
    O("env0", 0, 0, 0),
    T("env0", 0, 0, 0),
    O("env0", 1, 0, 1),                # completes steps 0 and 1 at once
    O("env0", 1, 0, 1),                # re-published copy, after it was consumed as next_obs and obs
    O("env1", 0, 0, 0),
    O("env0", 2, 0, 2),
    T("env0", 0, 2, 2, reward=1.0, done=True),
    T("env1", 0, 0, 0, timeout=True),
    O("env0", 4, 1, 0),
    O("env1", 1, 0, 1, terminal=True),
    O("env0", 3, 0, 3, terminal=True),  # the terminal frame, after the Transition naming it
    O("env0", 5, 1, 1),
    T("env0", 1, 0, 4, expert=False),
    T("env0", 1, 1, 5),                 # next_obs (frame 6) never recorded
    O("env0", 2, 0, 2),                 # a late copy of a consumed frame
]


def run(bag, *extra):
    r = subprocess.run([sys.executable, str(SCRIPT), str(bag), *extra], capture_output=True, text=True, timeout=120)
    return r


@pytest.fixture(scope="module")
def module():
    spec = importlib.util.spec_from_file_location("bag_transitions", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def joined(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bag_transitions")
    bag = tmp / "bag"
    write_bag(bag / "bag_0.mcap", RECORDS)
    npz = tmp / "t.npz"
    r = run(bag, "--json", "--npz", str(npz))
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), dict(np.load(npz)), bag


def test_the_synthetic_schema_is_rosbag2_style():
    text = full_definition(TRANSITION)
    assert text.startswith(msg_path(TRANSITION).read_text())
    assert [line for line in text.splitlines() if line.startswith("MSG: ")] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: equiarm_msgs/GripperCommand"]
    assert [line for line in full_definition(OBSERVATION).splitlines() if line.startswith("MSG: ")] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: equiarm_msgs/GripperCommand"]


def test_counts(joined):
    s, _, _ = joined
    assert s["transitions"] == 6 and s["observations"] == 10
    assert s["joined"] == 5 and s["unmatched"] == 1 and s["inconsistent"] == 0, s
    assert s["duplicate_observations"] == 2
    assert s["envs"]["env0"] == {"joined": 4, "unmatched": 1, "episodes": 2, "done": 1, "timeout": 0,
                                 "inconsistent": 0, "duplicate_observations": 2}
    assert s["envs"]["env1"] == {"joined": 1, "unmatched": 0, "episodes": 1, "done": 0, "timeout": 1,
                                 "inconsistent": 0, "duplicate_observations": 0}
    # env0's frame 5 (next_obs of step 0 of episode 1, then waited for as the obs of the unmatched step)
    assert s["unused_observations"] == 1


def test_arrays_hold_the_observations_named_by_seq(joined):
    _, a, _ = joined
    assert a["env"].tolist() == ["env0"] * 4 + ["env1"]
    assert a["episode"].tolist() == [0, 0, 0, 1, 0] and a["step"].tolist() == [0, 1, 2, 0, 0]
    assert a["obs_seq"].tolist() == [0, 1, 2, 4, 0] and a["next_obs_seq"].tolist() == [1, 2, 3, 5, 1]
    assert a["obs_color"].shape == (5, H, W, 3) and a["obs_color"].dtype == np.uint8
    assert a["obs_depth"].shape == (5, H, W) and a["next_obs_depth"].dtype == np.float32
    for i, (env, seq, nxt) in enumerate(zip(a["env"], a["obs_seq"], a["next_obs_seq"])):
        assert np.array_equal(a["obs_color"][i], color_pixels(env, int(seq))), i
        assert np.array_equal(a["next_obs_color"][i], color_pixels(env, int(nxt))), i
        assert np.array_equal(a["obs_depth"][i], depth_pixels(env, int(seq))), i
        assert np.array_equal(a["next_obs_depth"][i], depth_pixels(env, int(nxt))), i
        assert a["obs_holding"][i] == (seq % 2 == 1) and a["next_obs_holding"][i] == (nxt % 2 == 1)
        f32 = lambda x: struct.unpack("<f", struct.pack("<f", x))[0]  # noqa: E731
        assert a["action"][i].tolist() == [0.5, f32(0.01 * int(seq)), f32(-0.02), f32(0.03), f32(0.1)], i
    assert a["action_fields"].tolist() == ["open_ratio", "dx", "dy", "dz", "dtheta"]
    assert a["reward"].tolist() == [0.0, 0.0, 1.0, 0.0, 0.0]
    assert a["done"].tolist() == [False, False, True, False, False]
    assert a["timeout"].tolist() == [False, False, False, False, True]
    assert a["expert"].tolist() == [True, True, True, False, True]
    assert a["action_source"].tolist() == [1, 1, 1, 0, 1]


def test_the_next_obs_of_a_step_is_the_obs_of_the_next_one(joined):
    _, a, _ = joined
    for k in (0, 1):  # env0, episode 0, steps 0 -> 1 -> 2
        assert np.array_equal(a["next_obs_color"][k], a["obs_color"][k + 1])
        assert np.array_equal(a["next_obs_depth"][k], a["obs_depth"][k + 1])
    # the last step of an episode ends at its terminal frame (published after its Transition here),
    # which is no step's obs
    assert np.array_equal(a["next_obs_color"][2], color_pixels("env0", 3))
    assert not any(np.array_equal(a["obs_color"][i], color_pixels("env0", 3)) for i in range(4))
    assert np.array_equal(a["next_obs_depth"][4], depth_pixels("env1", 1)) and a["timeout"][4]


def test_a_single_mcap_file_and_the_text_summary(joined):
    _, _, bag = joined
    r = run(bag / "bag_0.mcap")
    assert r.returncode == 0, r.stderr
    assert "transitions: 6 in the bag, 5 joined, 1 unmatched, 0 inconsistent" in r.stdout, r.stdout
    assert re.search(r"^env0 +4 +1 +2 +1 +0 +2$", r.stdout, re.M), r.stdout


def test_without_the_observation_topics_nothing_joins(tmp_path):
    write_bag(tmp_path / "only_transitions.mcap", [rec for rec in RECORDS if rec[0] == "/transitions"])
    r = run(tmp_path / "only_transitions.mcap", "--json")
    assert r.returncode == 1
    s = json.loads(r.stdout)
    assert s["joined"] == 0 and s["unmatched"] == 6


# --- the join on its own, with messages as plain objects ----------------------------------------------

def ns(d):
    from types import SimpleNamespace
    return SimpleNamespace(**{k: ns(v) if isinstance(v, dict) else v for k, v in d.items()})


def episode_stream(env, episodes, steps, first_seq=0, copies=True):
    """(type, message) of `episodes` episodes of `steps` steps in the order the sim publishes them,
    each answered frame published twice when `copies` (a re-publish), the next Observation before the
    Transition."""
    seq = first_seq
    for ep in range(episodes):
        yield OBSERVATION, ns(observation(env, seq, ep, 0))
        for k in range(steps):
            if copies:
                yield OBSERVATION, ns(observation(env, seq, ep, k))
            last = k == steps - 1
            yield OBSERVATION, ns(observation(env, seq + 1, ep, k + 1, terminal=last))
            yield TRANSITION, ns(transition(env, ep, k, seq, done=last))
            seq += 1
        seq += 1  # the terminal frame's seq; the next episode starts after it


def test_memory_stays_bounded_over_a_long_stream(module):
    window = 50
    j = module.EnvJoin(window)
    biggest = 0
    for name, m in episode_stream("env0", 40, 25):
        (j.add_observation if name == OBSERVATION else j.add_transition)(m)
        biggest = max(biggest, len(j.frames), len(j.waiting))
        assert len(j.consumed) <= window + 16
    assert j.joined == 40 * 25 and j.unmatched == 0 and j.duplicates == 40 * 25
    assert biggest <= 2 and j.finish() == 0
    # observations no transition ever names (a bag without /transitions) are dropped behind the window
    j = module.EnvJoin(window)
    for seq in range(2000):
        j.add_observation(ns(observation("env0", seq, 0, seq)))
        assert len(j.frames) <= window + 17
    assert j.finish() == 2000


def test_join_survives_reordering_within_the_window(module):
    msgs = list(episode_stream("env3", 3, 10, first_seq=100))
    obs = [m for m in msgs if m[0] == OBSERVATION]
    trs = [m for m in msgs if m[0] == TRANSITION]
    # every transition first, in reverse order, then the observations: worst case for the join
    s = module.join(trs[::-1] + obs, window=1000)
    assert (s["joined"], s["unmatched"], s["inconsistent"]) == (30, 0, 0), s
    assert s["envs"]["env3"]["episodes"] == 3 and s["envs"]["env3"]["done"] == 3
    # with a window smaller than the reordering, the oldest transitions are given up, never mis-joined
    s = module.join(trs[::-1] + obs, window=5)
    assert s["joined"] + s["unmatched"] == 30 and s["unmatched"] > 0 and s["inconsistent"] == 0


def test_inconsistent_transitions_are_reported(module):
    msgs = list(episode_stream("env0", 1, 3, copies=False))
    bad = [(n, m) for n, m in msgs]
    bad[-1][1].step = 7  # the last Transition claims another step
    msgs2 = list(episode_stream("env0", 1, 3, copies=False))
    msgs2[-1][1].done = False  # ends at the terminal frame without done or timeout
    s, s2 = module.join(bad), module.join(msgs2)
    assert s["joined"] == 3 and s["inconsistent"] == 1
    assert s["inconsistent_examples"] == [{"env": "env0", "obs_seq": 2, "failed": ["step"]}]
    assert s2["inconsistent_examples"] == [{"env": "env0", "obs_seq": 2, "failed": ["terminal"]}]
