"""Tests of the example scripts in launch_scripts/: drive_sim.py and read_bag.py against a real
`equiarm sim` and `equiarm record`, and equiarm.launch.py with stub `launch`/`launch_ros` modules
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
        rec = subprocess.Popen([BIN, "record", "--all", "-q", "-o", str(bag)], env=env,
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


def test_read_bag_metadata_parser():
    spec = importlib.util.spec_from_file_location("read_bag", SCRIPTS / "read_bag.py")
    rb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rb)
    meta = ("rosbag2_bagfile_information:\n  version: 8\n  storage_identifier: mcap\n"
            "  relative_file_paths:\n    - run_0.mcap\n    - run_1.mcap\n  duration:\n    nanoseconds: 5\n")
    assert rb.relative_file_paths(meta) == ["run_0.mcap", "run_1.mcap"]
