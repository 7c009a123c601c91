"""Golden CDR cases for every equiarm message type, encoded and checked by independent implementations.

The Rust test `tests/golden_cdr.rs` builds the same cases in Rust and drives this script:

    golden.py encode DIR   writes DIR/py/<case>.cdr with Cyclone DDS's serializer, after checking
                           that rosbags' CDR serializer writes the very same bytes;
    golden.py check DIR    decodes DIR/rs/<case>.cdr (written by our Rust encoder) with Cyclone DDS,
                           rosbags and mcap-ros2-support (from the definition text in
                           DIR/rs/<type>.msgdef, our rosbag2 schema), and asserts every field's value,
                           floats bit for bit.

The case values here are written out independently of the Rust ones; they must describe the same
messages. Standard types come from rosbags' Jazzy type store (upstream definitions), ours from
msgs/msg/*.msg, and the test also checks that msgs/ros_std/ declares the upstream field lists.
"""

import math
import pathlib
import struct
import sys

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import equiarm_idl as idl

ROOT = pathlib.Path(__file__).resolve().parents[2]


def f32(bits: int) -> float:
    return struct.unpack("<f", struct.pack("<I", bits))[0]


def f64(bits: int) -> float:
    return struct.unpack("<d", struct.pack("<Q", bits))[0]


NAN32 = f32(0x7FC00001)  # quiet NaN with a payload
SUB32 = f32(0x00000001)  # smallest subnormal
MAX32 = f32(0x7F7FFFFF)
NAN64 = f64(0x7FF8000000000001)
SUB64 = f64(0x0000000000000001)
MAX64 = f64(0x7FEFFFFFFFFFFFFF)
INF = math.inf
TEXT = "caméra_optique_深度_🤖"


def lowbias32(x: int) -> int:
    x &= 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x


def hash_words(n: int, seed: int) -> bytes:
    """n little-endian words, word i = lowbias32(i * 0x9E3779B1 ^ seed * 0x85EBCA77): as float32 this
    holds NaNs with payloads, infinities and subnormals."""
    i = np.arange(n, dtype=np.uint64)
    x = ((i * 0x9E3779B1) & 0xFFFFFFFF) ^ ((seed * 0x85EBCA77) & 0xFFFFFFFF)
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x.astype("<u4").tobytes()


def ramp(n: int, mul: int, add: int) -> bytes:
    return ((np.arange(n, dtype=np.uint64) * mul + add) % 256).astype(np.uint8).tobytes()


def header(sec, nanosec, frame):
    return idl.Header(stamp=idl.Time(sec=sec, nanosec=nanosec), frame_id=frame)


def rgb8(h, w, frame):
    return idl.Image(header=header(1, 2, frame), height=h, width=w, encoding="rgb8", is_bigendian=0,
                     step=w * 3, data=ramp(h * w * 3, 7, 3))


def depth(h, w, frame, seed):
    return idl.Image(header=header(1, 2, frame), height=h, width=w, encoding="32FC1", is_bigendian=0,
                     step=w * 4, data=hash_words(h * w, seed))


def command_special():
    return idl.GripperCommand(header=header(-1, 5, "world"), obs_seq=2**64 - 1, open_ratio=NAN32, dx=-0.0,
                              dy=INF, dz=-INF, dtheta=SUB32, source=idl.SOURCE_TELEOP)


def command_typical():
    return idl.GripperCommand(header=header(10, 500_000_000, "world"), obs_seq=42, open_ratio=1.0, dx=0.03125,
                              dy=-0.0625, dz=0.0, dtheta=MAX32, source=idl.SOURCE_EXPERT)


def observation(seq, size, seed):
    """terminal = True (the non-default value of the last field, so its place on the wire is checked)."""
    # planes of arbitrary bytes (the CDR layout is checked here, the compression by the Rust
    # obs_frame tests); colour of an odd length, so the depth's length needs alignment padding
    return idl.Observation(header=header(3, 4, "world"), seq=seq, env="env0", episode=3, step=49,
                           height=size, width=size, color=ramp(size * 3 + 1, 7, 3), depth=hash_words(size, seed),
                           holding=True, expert_action=command_typical(), terminal=True)


def cases():
    """name -> IDL value. Names are `<Type>.<case>`; the Rust test builds the same set."""
    c = {}
    for cls in idl.ALL:
        c[f"{cls.__name__}.default"] = cls()
    c["Time.special"] = idl.Time(sec=-(2**31), nanosec=999_999_999)
    c["Clock.special"] = idl.Clock(clock=idl.Time(sec=2**31 - 1, nanosec=166_666_667))
    c["Header.special"] = header(1_700_000_000, 123_456_789, TEXT)
    c["Image.rgb8"] = rgb8(152, 152, "camera_color_optical_frame")
    c["Image.depth"] = depth(152, 152, TEXT, 1)
    c["RegionOfInterest.special"] = idl.RegionOfInterest(x_offset=2**32 - 1, y_offset=0, height=7, width=8,
                                                         do_rectify=True)
    c["CameraInfo.special"] = idl.CameraInfo(
        header=header(5, 6, "camera"), height=152, width=152, distortion_model="plumb_bob",
        d=[NAN64, -0.0, INF, -INF, SUB64],
        k=[0.5 * i - 2.0 for i in range(9)],
        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=[MAX64, -MAX64, SUB64, -0.0, NAN64, INF, -INF, 1.0, 2.0, 3.0, 0.25, -0.125],
        binning_x=2**32 - 1, binning_y=0,
        roi=idl.RegionOfInterest(x_offset=1, y_offset=2, height=3, width=4, do_rectify=True))
    c["GripperCommand.special"] = command_special()
    c["GripperCommand.typical"] = command_typical()
    c["Observation.special"] = observation(2**64 - 2, 152, 2)
    # env = TEXT: a multi-byte string, after which obs_seq needs 4 bytes of alignment padding
    c["Transition.special"] = idl.Transition(header=header(7, 8, "world"), env=TEXT, episode=2**32 - 1, step=49,
                                             obs_seq=2**64 - 2, next_obs_seq=2**64 - 1, action=command_special(),
                                             reward=1.0, done=True, timeout=False, expert=True)
    c["EpisodeResult.special"] = idl.EpisodeResult(header=header(9, 10, "world"), env="环境1",
                                                   task="block_picking", seed=2**64 - 1, episode=7, steps=50,
                                                   success=True, ret=1.0, discounted_return=NAN32, expert=False,
                                                   eval=True)
    c["PolicyWeights.special"] = idl.PolicyWeights(header=header(11, 12, ""), run_id="run-7f3a", version=1,
                                                   updates=2**40,
                                                   model="equi_d4", format="safetensors",
                                                   data=ramp(1 << 20, 31, 17))
    c["TrainerStatus.special"] = idl.TrainerStatus(header=header(13, 14, ""), updates=5000, transitions=2**33,
                                                   buffer_size=100_000, expert_transitions=0, critic_loss=NAN32,
                                                   actor_loss=-0.0, alpha=INF, updates_per_s=-INF,
                                                   transitions_per_s=SUB32, last_eval_return=MAX32,
                                                   last_eval_success_rate=0.75, last_eval_episodes=2**32 - 1)
    return c


# ---------------------------------------------------------------------------------------------------
# rosbags: an independent CDR implementation driven by .msg definitions


def typestore():
    ts = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for p in sorted((ROOT / "msgs" / "msg").glob("*.msg")):
        types.update(get_types_from_msg(p.read_text(), f"equiarm_msgs/msg/{p.stem}"))
    ts.register(types)
    return ts


def check_std_msgs_match_upstream(ts):
    """msgs/ros_std/*.msg must declare exactly the upstream (Jazzy) field lists."""
    n = 0
    for p in sorted((ROOT / "msgs" / "ros_std").glob("*/msg/*.msg")):
        name = f"{p.parts[-3]}/msg/{p.stem}"
        ours = get_types_from_msg(p.read_text(), name)[name]
        assert ours == ts.fielddefs[name], f"{p}: fields differ from upstream {name}"
        n += 1
    assert n == 11, n


def to_rosbags(ts, value):
    """Converts an IDL value to the rosbags message object of the same type."""
    cls = ts.types[idl.ros_name(type(value))]
    _, fields = ts.fielddefs[idl.ros_name(type(value))]
    kwargs = {}
    for fname, (kind, detail) in fields:
        v = getattr(value, fname)
        if kind.name == "NAME":
            kwargs[fname] = to_rosbags(ts, v)
        elif kind.name in ("ARRAY", "SEQUENCE"):
            (ekind, edetail), _ = detail
            if ekind.name == "BASE":
                dtype = {"uint8": np.uint8, "float64": np.float64, "float32": np.float32}[edetail[0]]
                kwargs[fname] = np.frombuffer(v, dtype=np.uint8).copy() if dtype is np.uint8 else np.array(v, dtype=dtype)
            else:
                kwargs[fname] = [to_rosbags(ts, e) for e in v]
        else:
            kwargs[fname] = v
    return cls(**kwargs)


# ---------------------------------------------------------------------------------------------------
# field-by-field comparison, floats bit for bit


def as_bytes(v):
    if isinstance(v, np.ndarray):
        return v.tobytes()
    if isinstance(v, (bytes, bytearray, memoryview)):
        return bytes(v)
    return None


def same(expected, got, path, errors):
    eb = as_bytes(expected)
    if eb is not None or as_bytes(got) is not None:
        gb = as_bytes(got) if as_bytes(got) is not None else np.asarray(got, dtype=np.uint8).tobytes()
        if eb is None:
            eb = np.asarray(expected, dtype=np.uint8).tobytes()
        if eb != gb:
            errors.append(f"{path}: {len(gb)} bytes differ from the expected {len(eb)}")
        return
    if hasattr(expected, "__dataclass_fields__"):
        for name in expected.__dataclass_fields__:
            if name.startswith("__"):
                continue
            same(getattr(expected, name), getattr(got, name), f"{path}.{name}", errors)
        return
    if isinstance(expected, (list, tuple)):
        got = list(got)
        if len(expected) != len(got):
            errors.append(f"{path}: length {len(got)}, expected {len(expected)}")
            return
        for i, (e, g) in enumerate(zip(expected, got)):
            same(e, g, f"{path}[{i}]", errors)
        return
    if isinstance(expected, float) or isinstance(got, (float, np.floating)):
        if struct.pack("<d", float(expected)) != struct.pack("<d", float(got)):
            errors.append(f"{path}: {float(got)!r} ({struct.pack('<d', float(got)).hex()}) != expected "
                          f"{expected!r} ({struct.pack('<d', float(expected)).hex()})")
        return
    if expected != got or type(expected) is bool and type(got) is not bool and not isinstance(got, np.bool_):
        errors.append(f"{path}: {got!r} != expected {expected!r}")


def encode(out: pathlib.Path):
    ts = typestore()
    check_std_msgs_match_upstream(ts)
    (out / "py").mkdir(parents=True, exist_ok=True)
    for name, value in cases().items():
        cyc = bytes(value.serialize())
        rb = bytes(ts.serialize_cdr(to_rosbags(ts, value), idl.ros_name(type(value))))
        assert cyc == rb, f"{name}: Cyclone DDS and rosbags disagree ({len(cyc)} vs {len(rb)} bytes)"
        (out / "py" / f"{name}.cdr").write_bytes(cyc)
    print(f"golden encode: {len(cases())} cases written, Cyclone DDS == rosbags for each")


def check(out: pathlib.Path):
    from mcap_ros2._dynamic import generate_dynamic

    ts = typestore()
    errors = []
    n = 0
    for name, expected in cases().items():
        data = (out / "rs" / f"{name}.cdr").read_bytes()
        cls = type(expected)
        tname = idl.ros_name(cls)
        same(expected, cls.deserialize(data), f"{name} (cyclonedds)", errors)
        same(to_rosbags(ts, expected), ts.deserialize_cdr(data, tname), f"{name} (rosbags)", errors)
        definition = (out / "rs" / f"{cls.__name__}.msgdef").read_text()
        decoder = generate_dynamic(tname, definition)[tname]
        got = decoder(data)
        same(expected, got, f"{name} (mcap-ros2-support)", errors)
        n += 1
    for e in errors[:40]:
        print("MISMATCH", e)
    print(f"golden check: {n} cases, {len(errors)} mismatches")
    return 1 if errors else 0


if __name__ == "__main__":
    mode, out = sys.argv[1], pathlib.Path(sys.argv[2])
    if mode == "encode":
        encode(out)
    elif mode == "check":
        sys.exit(check(out))
    else:
        sys.exit(f"unknown mode {mode!r}: use encode or check")
