"""Reads an equiarm bag with two independent readers and checks it against what was recorded.

    bag_check.py BAG EXPECTED.json

EXPECTED.json: {"counts": {topic: n}, "types": {topic: type}, "values": "synthetic" | null,
                "t0": ns, "dt": ns}
With "values": "synthetic" every message must equal the value `synthetic(topic, k)` builds for the
k-th message of its topic (the Rust test writes the same values), floats bit for bit, with
log_time = t0 + k*dt and publish_time = log_time - 1000.

Readers: `mcap` + `mcap-ros2-support` decoding from the schemas embedded in each file, and
`rosbags`' AnyReader (which needs metadata.yaml and the `ros2` profile) decoding from the definitions
in the file. Prints one JSON line with the counts each reader saw; exits non-zero on any mismatch.
"""

import json
import pathlib
import sys
from collections import Counter

import equiarm_idl as idl
import golden

NAN32 = golden.NAN32


def synthetic(topic: str, k: int):
    if topic.endswith("gripper_cmd"):
        return idl.GripperCommand(header=golden.header(k, 7, "world"), obs_seq=k, open_ratio=k * 0.25,
                                  dx=k * -0.5, dy=0.125, dz=NAN32 if k == 0 else 0.0, dtheta=float(k),
                                  source=k % 4)
    if topic.endswith("observation"):
        return golden.observation(k, 64, k)
    if topic.endswith("episodes"):
        success = k % 3 == 0
        return idl.EpisodeResult(header=golden.header(k, 0, "world"), env=f"env{k % 2}", task="block_pulling",
                                 seed=k, episode=k, steps=10 + k, success=success, ret=1.0 if success else 0.0,
                                 discounted_return=0.5, expert=k % 2 == 0, eval=False)
    if topic.endswith("image_raw"):
        return golden.rgb8(8, 8, "camera")
    raise KeyError(topic)


def read_mcap(bag: pathlib.Path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    files = sorted(bag.glob("*.mcap"), key=lambda p: int(p.stem.rsplit("_", 1)[1])) if bag.is_dir() else [bag]
    for f in files:
        with open(f, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            header = reader.get_header()
            assert header.profile == "ros2", f"{f}: profile {header.profile!r}"
            for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
                assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
                assert "offered_qos_profiles" in channel.metadata and "topic_type_hash" in channel.metadata
                yield channel.topic, schema.name, message.log_time, message.publish_time, decoded


def read_rosbags(bag: pathlib.Path):
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        for conn, log_time, raw in reader.messages():
            yield conn.topic, conn.msgtype, log_time, None, reader.deserialize(raw, conn.msgtype)


def main():
    bag, expected = pathlib.Path(sys.argv[1]), json.loads(pathlib.Path(sys.argv[2]).read_text())
    errors, seen = [], {}
    for name, source in (("mcap", read_mcap), ("rosbags", read_rosbags)):
        counts = Counter()
        for topic, type_name, log_time, publish_time, msg in source(bag):
            k = counts[topic]
            counts[topic] += 1
            want_type = expected["types"].get(topic)
            if type_name != want_type:
                errors.append(f"{name}: {topic} has type {type_name}, expected {want_type}")
            if expected.get("values") == "synthetic":
                t = expected["t0"] + k * expected["dt"]
                if log_time != t:
                    errors.append(f"{name}: {topic}[{k}] log_time {log_time} != {t}")
                if publish_time is not None and publish_time != t - 1000:
                    errors.append(f"{name}: {topic}[{k}] publish_time {publish_time} != {t - 1000}")
                golden.same(synthetic(topic, k), msg, f"{name}: {topic}[{k}]", errors)
        seen[name] = dict(counts)
        if dict(counts) != expected["counts"]:
            errors.append(f"{name}: counts {dict(counts)} != expected {expected['counts']}")
    for e in errors[:30]:
        print("MISMATCH", e, file=sys.stderr)
    print(json.dumps({"counts": seen, "errors": len(errors)}))
    sys.exit(1 if errors else 0)


if __name__ == "__main__":
    main()
