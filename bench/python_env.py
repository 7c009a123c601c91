#!/usr/bin/env python3
"""The Python package's speed at 152 px RGBD, per task (bench/python.sh builds and installs the wheel
first):

- `make`: one Gymnasium env stepped from Python with the expert's action (info["expert_action"]);
  median seconds per step, as env steps per second;
- Rust alone: the same loop inside the extension, without Python (`bench_rust_steps`); the Python
  overhead per step is (make - Rust) / Rust, medians;
- `make_vec(8)`: eight envs stepped in Rust threads per `step` call; env steps per second of wall time;
- PyBullet: bench/pybullet_peer.py's BulletArm-like step (modes floating, fixed, bulletarm) in the
  same run, as env steps per second; the ratios are make's steps/s over the peer's.

Rounds interleave ours and the peer's; each figure is the median over rounds. Prints a table, one JSON
line (`--json`) and the peak RSS of this process (the envs) and of the peer.

    bash bench/python.sh [--steps 300] [--rounds 2] [--tasks block_pulling ...] [--json]
"""

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

import equiarm
import equiarm._equiarm as native

MODES = ("floating", "fixed", "bulletarm")


def make_loop(task, steps, seed):
    env = equiarm.make(task, seed=seed)
    _, info = env.reset()
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        _, _, terminated, truncated, info = env.step(info["expert_action"])
        times.append(time.perf_counter() - t0)
        if terminated or truncated:
            _, info = env.reset()
    return statistics.median(times)


def vec_loop(task, n, steps, seed):
    env = equiarm.make_vec(task, n, seed=seed)
    _, infos = env.reset()
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, _, _, infos = env.step(infos["expert_action"])
    return n * steps / (time.perf_counter() - t0)


def peer(python, script, mode, steps):
    out = subprocess.run([python, script, "--steps", str(steps), "--mode", mode], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"PyBullet peer ({mode}) failed: {out.stderr[-1000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])["median_ms"] / 1e3


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=300, help="steps per loop and round")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--vec-envs", type=int, default=8)
    p.add_argument("--tasks", nargs="*", default=list(equiarm.TASKS))
    p.add_argument("--peer", help="bench/pybullet_peer.py (no peer without it)")
    p.add_argument("--peer-steps", type=int, default=100)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    rows = {t: {"make": [], "rust": [], "vec": []} for t in a.tasks}
    peers = {m: [] for m in MODES}
    for r in range(a.rounds):
        for t in a.tasks:
            rows[t]["rust"].append(statistics.median(native.bench_rust_steps(t, 152, a.steps, r)))
            rows[t]["make"].append(make_loop(t, a.steps, r))
            rows[t]["vec"].append(vec_loop(t, a.vec_envs, max(1, a.steps // a.vec_envs), r))
        if a.peer:
            for m in MODES:
                peers[m].append(peer(sys.executable, a.peer, m, a.peer_steps))
    med = statistics.median
    peer_s = {m: med(v) for m, v in peers.items() if v}
    result = {"steps": a.steps, "rounds": a.rounds, "vec_envs": a.vec_envs, "tasks": {}}
    print(f"{'task':<16}{'make steps/s':>14}{'Rust alone':>12}{'overhead':>10}{f'make_vec({a.vec_envs}) env steps/s':>28}")
    for t, v in rows.items():
        mk, rs, vc = med(v["make"]), med(v["rust"]), med(v["vec"])
        result["tasks"][t] = {"make_steps_per_s": 1 / mk, "rust_steps_per_s": 1 / rs, "overhead": (mk - rs) / rs,
                              "vec_env_steps_per_s": vc, "make_ms": mk * 1e3, "rust_ms": rs * 1e3}
        print(f"{t:<16}{1 / mk:>14.0f}{1 / rs:>12.0f}{(mk - rs) / rs:>10.1%}{vc:>28.0f}")
    make_all = med([med(v["make"]) for v in rows.values()])
    rust_all = med([med(v["rust"]) for v in rows.values()])
    vec_all = med([med(v["vec"]) for v in rows.values()])
    result["all"] = {"make_steps_per_s": 1 / make_all, "rust_steps_per_s": 1 / rust_all,
                     "overhead": (make_all - rust_all) / rust_all, "vec_env_steps_per_s": vec_all}
    print(f"{'median of tasks':<16}{1 / make_all:>14.0f}{1 / rust_all:>12.0f}{(make_all - rust_all) / rust_all:>10.1%}{vec_all:>28.0f}")
    if peer_s:
        print("\nPyBullet BulletArm-like step, same run (bench/pybullet_peer.py):")
        result["pybullet"] = {}
        for m, s in peer_s.items():
            result["pybullet"][m] = {"steps_per_s": 1 / s, "make_ratio": s / make_all, "vec_ratio": vec_all * s}
            print(f"  {m:<10} {1 / s:8.1f} steps/s   make {s / make_all:6.1f}x   make_vec({a.vec_envs}) {vec_all * s:6.1f}x")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    peer_rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    result["peak_rss_mb"] = {"ours": rss, "peer": peer_rss}
    print(f"\npeak RSS: this process (the envs) {rss:.0f} MB; PyBullet peer {peer_rss:.0f} MB")
    if a.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
