"""A Cyclone DDS peer for the interop tests, using ROS 2's DDS naming (topics `rt/...`, types
`pkg::msg::dds_::Type_`) and rclpy's QoS profiles, i.e. what an rclpy node on rmw_cyclonedds puts on
the wire. Every loop is bounded in count and time.

    dds_peer.py receive DOMAIN SECONDS   subscribe to the interop topics; print one JSON line per
                                         received sample telling whether it equals the golden value
                                         (floats bit for bit); exit after 3 samples of each topic
    dds_peer.py send DOMAIN SECONDS      publish the golden GripperCommands alternately, 20 Hz
    dds_peer.py send-bad DOMAIN SECONDS  publish payloads that do not decode as GripperCommand under
                                         its type name, 20 Hz, then good ones
    dds_peer.py clock DOMAIN SECONDS     act as an expert policy for the sim in /clk (answer each
                                         Observation with its expert action) and print every /clock
                                         sample and every answered Observation's stamp ("obs"; the
                                         episode's terminal frame, which nothing answers, as
                                         "terminal"), every transform on /tf_static and /tf,
                                         until an EpisodeResult
    dds_peer.py oversized DOMAIN SECONDS [TOPIC] [RATE]
                                         publish Observations announcing an 8192x8192 frame (each
                                         plane a valid zstd frame of zeros, about 10 KB on the wire,
                                         335 MB decompressed) on TOPIC (default rt/env0/observation)
                                         at RATE Hz (default 10), as env0 with seqs from 2^40 (no
                                         real frame's) in episode 2^20 (past the expert episodes,
                                         so a policy decodes the frame)
    dds_peer.py intrude DOMAIN SECONDS   a plain participant beside a secured suite: subscribe to
                                         env0's observations, /transitions and /policy/weights,
                                         publish forged gripper commands (env0), transitions (reward
                                         FORGED_REWARD) and weights (run FORGED_RUN) at 10 Hz; print
                                         what it received and sent and how many readers matched
"""

import json
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int8, int32, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

import equiarm_idl as idl
import golden

# rclpy's default profile (what `create_subscription(Msg, topic, 10)` uses) and the sensor-data profile.
RCLPY_DEFAULT = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
                    Policy.History.KeepLast(10), Policy.DataRepresentation(use_cdrv0_representation=True))
SENSOR_DATA = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5),
                  Policy.DataRepresentation(use_cdrv0_representation=True))

# topic -> (type, QoS, golden case the Rust side publishes on it)
RECEIVE = {
    "rt/interop/color/image_raw": (idl.Image, SENSOR_DATA, "Image.rgb8"),
    "rt/interop/depth/image_raw": (idl.Image, SENSOR_DATA, "Image.depth"),
    "rt/interop/observation": (idl.Observation, RCLPY_DEFAULT, "Observation.special"),
}


def emit(**kw):
    print(json.dumps(kw), flush=True)


def receive(domain: int, seconds: float):
    dp = DomainParticipant(domain)
    cases = golden.cases()
    readers = {name: DataReader(dp, Topic(dp, name, cls), qos=qos) for name, (cls, qos, _) in RECEIVE.items()}
    got = {name: 0 for name in RECEIVE}
    deadline = time.monotonic() + seconds
    emit(event="ready")
    while time.monotonic() < deadline and min(got.values()) < 3:
        idle = True
        for name, reader in readers.items():
            for sample in reader.take(N=10):
                if not hasattr(sample, "__dataclass_fields__"):
                    continue  # an InvalidSample (state change), not data
                idle = False
                errors = []
                golden.same(cases[RECEIVE[name][2]], sample, name, errors)
                got[name] += 1
                emit(event="sample", topic=name, exact=not errors, errors=errors[:5])
        if idle:
            time.sleep(0.01)
    emit(event="done", counts=got)


def send(domain: int, seconds: float):
    dp = DomainParticipant(domain)
    writer = DataWriter(dp, Topic(dp, "rt/interop/gripper_cmd", idl.GripperCommand), qos=RCLPY_DEFAULT)
    cases = [golden.command_special(), golden.command_typical()]
    deadline = time.monotonic() + seconds
    n = 0
    while time.monotonic() < deadline and n < int(seconds * 20):
        writer.write(cases[n % 2])
        n += 1
        time.sleep(0.05)
    emit(event="sent", count=n)


@dataclass
class Truncated(IdlStruct, typename="equiarm_msgs::msg::dds_::GripperCommand_"):
    """One byte where a GripperCommand needs at least 45."""
    x: int8 = 0


@dataclass
class HugeString(IdlStruct, typename="equiarm_msgs::msg::dds_::GripperCommand_"):
    """A header whose frame_id claims 4 GB: the wrong layout for GripperCommand."""
    sec: int32 = 0
    nanosec: uint32 = 0
    frame_id_len: uint32 = 0xFFFFFF00


def send_bad(domain: int, seconds: float):
    """Bad payloads first (two kinds, separate participants since the types clash), then good ones."""
    bad = []
    for cls, value in ((Truncated, Truncated(x=7)), (HugeString, HugeString())):
        dp = DomainParticipant(domain)
        bad.append((DataWriter(dp, Topic(dp, "rt/interop/bad_cmd", cls), qos=RCLPY_DEFAULT), value))
    good_dp = DomainParticipant(domain)
    good = DataWriter(good_dp, Topic(good_dp, "rt/interop/bad_cmd", idl.GripperCommand), qos=RCLPY_DEFAULT)
    deadline = time.monotonic() + seconds
    # wait (bounded) until the Rust reader has matched every writer, so reliable delivery applies
    while time.monotonic() < deadline:
        if all(w.get_matched_subscriptions() for w, _ in bad) and good.get_matched_subscriptions():
            break
        time.sleep(0.05)
    time.sleep(0.3)
    n_bad = n_good = 0
    for _ in range(3):
        for w, v in bad:
            w.write(v)
            n_bad += 1
        time.sleep(0.05)
    while time.monotonic() < deadline and n_good < 20:
        good.write(golden.command_typical())
        n_good += 1
        time.sleep(0.05)
    emit(event="sent", bad=n_bad, good=n_good)


def clock(domain: int, seconds: float):
    """/clock as an rclpy node sees it, while this peer drives the sim in /clk with expert actions."""
    dp = DomainParticipant(domain)
    clock_reader = DataReader(dp, Topic(dp, "rt/clock", idl.Clock), qos=Qos(
        Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(100),
        Policy.DataRepresentation(use_cdrv0_representation=True)))
    obs_reader = DataReader(dp, Topic(dp, "rt/clk/observation", idl.Observation), qos=RCLPY_DEFAULT)
    episodes = DataReader(dp, Topic(dp, "rt/episodes", idl.EpisodeResult), qos=RCLPY_DEFAULT)
    cmd_writer = DataWriter(dp, Topic(dp, "rt/clk/gripper_cmd", idl.GripperCommand), qos=RCLPY_DEFAULT)
    # tf2's listener profiles: /tf_static reliable + transient local (late joiners get the camera), /tf
    # reliable keep-last 100
    tf_static = DataReader(dp, Topic(dp, "rt/tf_static", idl.TFMessage), qos=Qos(
        Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal, Policy.History.KeepLast(1),
        Policy.DataRepresentation(use_cdrv0_representation=True)))
    tf = DataReader(dp, Topic(dp, "rt/tf", idl.TFMessage), qos=Qos(
        Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(100),
        Policy.DataRepresentation(use_cdrv0_representation=True)))
    deadline = time.monotonic() + seconds
    answered, ended = set(), False
    emit(event="ready")
    # Answer nothing before every reader has matched the sim's writers: the sim re-publishes an
    # unanswered Observation (and /clock and /tf with it) every second, so no stamp is missed.
    readers = (clock_reader, obs_reader, tf_static, tf)
    while time.monotonic() < deadline and not all(r.get_matched_publications() for r in readers):
        time.sleep(0.02)

    def take_tf():
        for topic, reader in (("tf_static", tf_static), ("tf", tf)):
            for s in reader.take(N=100):
                if isinstance(s, idl.TFMessage):
                    for t in s.transforms:
                        v, q = t.transform.translation, t.transform.rotation
                        emit(event=topic, parent=t.header.frame_id, child=t.child_frame_id, sec=t.header.stamp.sec,
                             nanosec=t.header.stamp.nanosec, translation=[v.x, v.y, v.z], rotation=[q.x, q.y, q.z, q.w])

    while time.monotonic() < deadline and not ended:
        take_tf()
        idle = True
        for s in clock_reader.take(N=100):
            if isinstance(s, idl.Clock):
                idle = False
                emit(event="clock", sec=s.clock.sec, nanosec=s.clock.nanosec)
        for s in obs_reader.take(N=10):
            if isinstance(s, idl.Observation) and s.terminal and s.seq not in answered:
                idle = False
                answered.add(s.seq)  # the episode's last frame: no command answers it
                emit(event="terminal", seq=s.seq, sec=s.header.stamp.sec, nanosec=s.header.stamp.nanosec)
            elif isinstance(s, idl.Observation) and s.seq not in answered:
                idle = False
                answered.add(s.seq)
                emit(event="obs", seq=s.seq, sec=s.header.stamp.sec, nanosec=s.header.stamp.nanosec)
                cmd = s.expert_action
                cmd.obs_seq = s.seq
                cmd_writer.write(cmd)
        for s in episodes.take(N=10):
            if isinstance(s, idl.EpisodeResult) and s.env == "clk":
                ended = True
                emit(event="episode", steps=s.steps, sec=s.header.stamp.sec, nanosec=s.header.stamp.nanosec)
        if idle:
            time.sleep(0.005)
    time.sleep(0.3)  # the last /clock samples
    for s in clock_reader.take(N=100):
        if isinstance(s, idl.Clock):
            emit(event="clock", sec=s.clock.sec, nanosec=s.clock.nanosec)
    take_tf()
    emit(event="done", ended=ended)


def oversized(domain: int, seconds: float, topic: str = "rt/env0/observation", rate: str = "10"):
    import zstandard

    side = 8192
    zeros = bytes(side * side * 3)
    color = zstandard.ZstdCompressor(level=3).compress(zeros)
    depth = zstandard.ZstdCompressor(level=3).compress(zeros[: side * side * 2])
    del zeros
    dp = DomainParticipant(domain)
    writer = DataWriter(dp, Topic(dp, topic, idl.Observation), qos=RCLPY_DEFAULT)
    period = 1.0 / float(rate)
    emit(event="ready", bytes=len(color) + len(depth), decompressed=side * side * 5)
    deadline = time.monotonic() + seconds
    n = 0
    next_t = time.monotonic()
    while time.monotonic() < deadline:
        writer.write(idl.Observation(seq=(1 << 40) + n, env="env0", episode=1 << 20, height=side, width=side, color=color, depth=depth))
        n += 1
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    emit(event="sent", count=n, matched=len(writer.get_matched_subscriptions()))


# what the intruder's forged samples carry, so that a receiver can tell them from the real ones
FORGED_REWARD = 1234.5
FORGED_RUN = "intruder"
LATCHED = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
              Policy.History.KeepLast(1), Policy.DataRepresentation(use_cdrv0_representation=True))


def not_local(qos: Qos) -> Qos:
    """`qos`, ignoring this process's own endpoints (the intruder's readers must not count its writes)."""
    return Qos(*qos, Policy.IgnoreLocal.Process)


def intrude(domain: int, seconds: float):
    dp = DomainParticipant(domain)
    listen = {"rt/env0/observation": (idl.Observation, RCLPY_DEFAULT), "rt/transitions": (idl.Transition, RCLPY_DEFAULT),
              "rt/policy/weights": (idl.PolicyWeights, LATCHED)}
    topics = {}  # one Topic per name in this participant, shared by its reader and writer

    def topic(name, cls):
        return topics.setdefault(name, Topic(dp, name, cls))

    readers = {name: DataReader(dp, topic(name, cls), qos=not_local(qos)) for name, (cls, qos) in listen.items()}
    forged = {
        "rt/env0/gripper_cmd": (idl.GripperCommand, RCLPY_DEFAULT, golden.command_special()),
        "rt/transitions": (idl.Transition, RCLPY_DEFAULT,
                           idl.Transition(env="env0", episode=1, step=1, obs_seq=1, next_obs_seq=2,
                                          reward=FORGED_REWARD)),
        "rt/policy/weights": (idl.PolicyWeights, LATCHED,
                              idl.PolicyWeights(run_id=FORGED_RUN, version=10**6, updates=10**6, model="equi",
                                                format="safetensors", data=bytes(64))),
    }
    writers = {name: DataWriter(dp, topic(name, cls), qos=not_local(qos)) for name, (cls, qos, _) in forged.items()}
    got = {name: 0 for name in listen}
    sent = {name: 0 for name in forged}
    deadline = time.monotonic() + seconds
    emit(event="ready")
    while time.monotonic() < deadline:
        for name, (_, _, value) in forged.items():
            writers[name].write(value)
            sent[name] += 1
        for name, reader in readers.items():
            got[name] += sum(1 for s in reader.take(N=100) if hasattr(s, "__dataclass_fields__"))
        time.sleep(0.1)
    matched = {name: len(w.get_matched_subscriptions()) for name, w in writers.items()}
    emit(event="done", received=got, sent=sent, matched=matched)


if __name__ == "__main__":
    mode, domain, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    modes = {"receive": receive, "send": send, "send-bad": send_bad, "clock": clock, "oversized": oversized,
             "intrude": intrude}
    modes[mode](domain, seconds, *sys.argv[4:])
