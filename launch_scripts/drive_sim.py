#!/usr/bin/env python3
"""Drives ONE `equiarm sim` node by hand, with a scripted action instead of a policy node.

Subscribes `/<ns>/observation`, answers each Observation with a GripperCommand naming its seq on
`/<ns>/gripper_cmd` (except an episode's last frame, `terminal`, which no command answers), prints
one line per step (from the Transition on `/transitions` of this env: its obs_seq, episode, step, the
action, the reward and the done/timeout flags, plus the holding flag of the Observation it names) and
one line per episode (the EpisodeResult from `/episodes`), and stops after `--episodes N`.

A Transition carries no images: it names its two Observations by `obs_seq` / `next_obs_seq` (same
env); launch_scripts/bag_transitions.py shows how to join them again from a bag.

Actions: by default the expert action the sim puts into every Observation (`source = EXPERT`);
`--random` draws uniformly in the sim's action ranges (dx, dy, dz in +-0.05 m, dtheta in +-pi/4,
open ratio in [0, 1]; `source = RANDOM`, seeded by `--seed`).

Transport: rclpy when it and the `equiarm_msgs` interface package (msgs/ built with colcon) import;
otherwise the Cyclone DDS Python binding (`pip install cyclonedds`) with the IDL types of
`tests/python/equiarm_idl.py` (found relative to this file), which puts the same bytes on the wire as
rclpy on rmw_cyclonedds. `--backend rclpy|cyclone` forces one. `ROS_DOMAIN_ID` picks the domain
(default 0). With Cyclone, `CYCLONEDDS_URI` selects interfaces as usual.

Options:
    --namespace NS    the sim's namespace (default /env0)
    --episodes N      stop after N episodes of that env (default 1)
    --random          uniform random actions instead of the expert's
    --seed S          seed of the random actions (default 0)
    --timeout-s T     give up (exit 2) after T seconds in all (default 300)
    --json            print JSON lines ({"event": "step"|"episode"|"done", ...}) instead of text
    --quiet-steps     print episodes only

Example (two terminals):
    equiarm sim --task block_pulling --namespace /env0 --seed 3 --episodes 2
    python3 launch_scripts/drive_sim.py --namespace /env0 --episodes 2

Exit status: 0 when N episodes were seen, 2 on timeout.
"""

import argparse
import importlib.util
import json
import math
import os
import pathlib
import random
import sys
import time

EXPERT, RANDOM = 1, 2  # GripperCommand.source


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--namespace", default="/env0")
    p.add_argument("--episodes", type=int, default=1)
    p.add_argument("--random", action="store_true")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--timeout-s", type=float, default=300.0)
    p.add_argument("--json", action="store_true")
    p.add_argument("--quiet-steps", action="store_true")
    p.add_argument("--backend", choices=["auto", "rclpy", "cyclone"], default="auto")
    return p.parse_args(argv)


def norm_ns(ns: str) -> str:
    ns = "/" + ns.strip("/")
    return "" if ns == "/" else ns


class Driver:
    """Transport-independent part: chooses actions, matches transitions, prints, counts episodes."""

    def __init__(self, args, make_command):
        self.args = args
        self.env = norm_ns(args.namespace).lstrip("/")
        self.make_command = make_command  # (obs_seq, open, dx, dy, dz, dtheta, source) -> message
        self.rng = random.Random(args.seed)
        self.answered = {}  # seq -> command sent (re-sent when the sim re-publishes the observation)
        self.holding = {}  # seq -> holding flag of the answered Observations no Transition named yet
        self.last_obs_seq = -1  # obs_seq of the latest Transition of this env
        self.episodes = []
        self.steps = 0

    def emit(self, text, **kw):
        if self.args.json:
            print(json.dumps(kw), flush=True)
        else:
            print(text, flush=True)

    def on_observation(self, obs):
        """The command that answers `obs` (the same one again for a re-published observation)."""
        if obs.env != self.env or obs.terminal:
            return None  # another env's, or an episode's last frame: nothing answers it
        if obs.seq > self.last_obs_seq:
            self.holding[obs.seq] = bool(obs.holding)
            while len(self.holding) > 256:  # bounded, should Transitions not arrive
                del self.holding[min(self.holding)]
        cmd = self.answered.get(obs.seq)
        if cmd is None:
            if self.args.random:
                r = self.rng.uniform
                cmd = self.make_command(obs.seq, r(0.0, 1.0), r(-0.05, 0.05), r(-0.05, 0.05), r(-0.05, 0.05),
                                        r(-math.pi / 4, math.pi / 4), RANDOM)
            else:
                e = obs.expert_action
                cmd = self.make_command(obs.seq, e.open_ratio, e.dx, e.dy, e.dz, e.dtheta, EXPERT)
            self.answered = {obs.seq: cmd}  # keep only the latest
        return cmd

    def on_transition(self, t):
        """One step line. The Transition names its observations by seq; the holding flag comes from the
        Observation `obs_seq`, which this driver answered before the step could happen (None if not)."""
        if t.env != self.env:
            return
        holding = self.holding.pop(t.obs_seq, None)
        self.last_obs_seq = max(self.last_obs_seq, t.obs_seq)
        for seq in [s for s in self.holding if s < t.obs_seq]:
            del self.holding[seq]
        if self.args.quiet_steps:
            return
        self.steps += 1
        a = t.action
        self.emit(f"{self.env} seq {t.obs_seq:5d}  episode {t.episode:3d}  step {t.step:3d}  "
                  f"holding {'?' if holding is None else int(holding)}  action open {a.open_ratio:.2f} "
                  f"dx {a.dx:+.3f} dy {a.dy:+.3f} dz {a.dz:+.3f} dth {a.dtheta:+.3f}  reward {t.reward:.1f}"
                  f"{'  done' if t.done else ''}{'  timeout' if t.timeout else ''}",
                  event="step", env=self.env, seq=int(t.obs_seq), next_seq=int(t.next_obs_seq),
                  episode=int(t.episode), step=int(t.step), holding=holding, reward=float(t.reward),
                  done=bool(t.done), timeout=bool(t.timeout), expert=bool(t.expert), source=int(a.source))

    def on_episode(self, r):
        if r.env != self.env:
            return
        self.episodes.append(r)
        self.emit(f"{r.env} EPISODE {r.episode}  task {r.task}  seed {r.seed}  steps {r.steps}  "
                  f"success {int(r.success)}  return {r.ret:.2f}  discounted {r.discounted_return:.3f}",
                  event="episode", env=r.env, task=r.task, seed=int(r.seed), episode=r.episode, steps=r.steps,
                  success=bool(r.success), ret=float(r.ret), discounted_return=float(r.discounted_return),
                  expert=bool(r.expert), eval=bool(r.eval))

    def finished(self):
        return len(self.episodes) >= self.args.episodes

    def summary(self):
        n = len(self.episodes)
        ok = sum(bool(r.success) for r in self.episodes)
        self.emit(f"{self.env}: {n} episodes, {ok} successful", event="done", env=self.env, episodes=n,
                  successes=ok)


# --- Cyclone DDS --------------------------------------------------------------------------------------

def load_idl():
    """tests/python/equiarm_idl.py of this repository, imported by path."""
    path = pathlib.Path(__file__).resolve().parent.parent / "tests" / "python" / "equiarm_idl.py"
    spec = importlib.util.spec_from_file_location("equiarm_idl", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run_cyclone(args):
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    idl = load_idl()
    cdr1 = Policy.DataRepresentation(use_cdrv0_representation=True)
    command_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
                      Policy.History.KeepLast(10), cdr1)
    stream_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
                     Policy.History.KeepLast(100), cdr1)
    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    ns = norm_ns(args.namespace)
    obs_r = DataReader(dp, Topic(dp, f"rt{ns}/observation", idl.Observation), qos=command_qos)
    cmd_w = DataWriter(dp, Topic(dp, f"rt{ns}/gripper_cmd", idl.GripperCommand), qos=command_qos)
    tr_r = DataReader(dp, Topic(dp, "rt/transitions", idl.Transition), qos=stream_qos)
    ep_r = DataReader(dp, Topic(dp, "rt/episodes", idl.EpisodeResult), qos=stream_qos)

    def make_command(seq, open_ratio, dx, dy, dz, dtheta, source):
        now = time.time_ns()
        return idl.GripperCommand(header=idl.Header(stamp=idl.Time(sec=now // 10**9, nanosec=now % 10**9),
                                                    frame_id="world"),
                                  obs_seq=seq, open_ratio=open_ratio, dx=dx, dy=dy, dz=dz, dtheta=dtheta,
                                  source=source)

    drv = Driver(args, make_command)
    deadline = time.monotonic() + args.timeout_s
    while time.monotonic() < deadline and not drv.finished():
        idle = True
        # Transitions and episodes first, so a step's line precedes the next one's command.
        for reader, cls, handler in ((tr_r, idl.Transition, drv.on_transition),
                                     (ep_r, idl.EpisodeResult, drv.on_episode), (obs_r, idl.Observation, None)):
            for sample in reader.take(N=32):
                if not isinstance(sample, cls):
                    continue  # an InvalidSample (a writer went away), not data
                idle = False
                if handler is not None:
                    handler(sample)
                else:
                    cmd = drv.on_observation(sample)
                    if cmd is not None:
                        cmd_w.write(cmd)
        if idle:
            time.sleep(0.005)
    drv.summary()
    return 0 if drv.finished() else 2


# --- rclpy ------------------------------------------------------------------------------------------

def run_rclpy(args):
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, DurabilityPolicy, HistoryPolicy
    from equiarm_msgs.msg import EpisodeResult, GripperCommand, Observation, Transition

    rclpy.init()
    node = rclpy.create_node("drive_sim")
    ns = norm_ns(args.namespace)
    stream = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE,
                        history=HistoryPolicy.KEEP_LAST, depth=100)
    pub = node.create_publisher(GripperCommand, f"{ns}/gripper_cmd", 10)

    def make_command(seq, open_ratio, dx, dy, dz, dtheta, source):
        c = GripperCommand()
        c.header.stamp = node.get_clock().now().to_msg()
        c.header.frame_id = "world"
        c.obs_seq, c.open_ratio, c.dx, c.dy, c.dz, c.dtheta, c.source = (
            int(seq), float(open_ratio), float(dx), float(dy), float(dz), float(dtheta), int(source))
        return c

    drv = Driver(args, make_command)

    def on_obs(msg):
        cmd = drv.on_observation(msg)
        if cmd is not None:
            pub.publish(cmd)

    node.create_subscription(Observation, f"{ns}/observation", on_obs, 10)
    node.create_subscription(Transition, "/transitions", drv.on_transition, stream)
    node.create_subscription(EpisodeResult, "/episodes", drv.on_episode, stream)
    deadline = time.monotonic() + args.timeout_s
    try:
        while rclpy.ok() and time.monotonic() < deadline and not drv.finished():
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        drv.summary()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if drv.finished() else 2


def have_rclpy():
    try:
        import rclpy  # noqa: F401
        from equiarm_msgs.msg import Observation  # noqa: F401
        return True
    except ImportError:
        return False


def main(argv=None):
    args = parse_args(argv)
    backend = args.backend
    if backend == "auto":
        backend = "rclpy" if have_rclpy() else "cyclone"
    if not args.json:
        print(f"drive_sim: {backend}, namespace {norm_ns(args.namespace) or '/'}, domain "
              f"{os.environ.get('ROS_DOMAIN_ID', '0')}, {'random' if args.random else 'expert'} actions, "
              f"{args.episodes} episode(s)", file=sys.stderr, flush=True)
    try:
        return run_rclpy(args) if backend == "rclpy" else run_cyclone(args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
