"""The recorder's live view (`train.sh --foxglove PORT` → `equiarm record --foxglove`), read by an
independent Foxglove WebSocket client (the `websockets` package speaking Foxglove's WebSocket
protocol v1 as its specification defines it): during a suite run it subscribes to /trainer/status
and /env0/camera/color/image_raw and receives messages byte-equal to what the bag records, on
channels whose schema is the bag's.

    EQUIARM_BIN=target/debug/equiarm python -m pytest tests/python/test_foxglove_live.py
"""

import asyncio
import json
import os
import pathlib
import random
import signal
import socket
import struct
import subprocess
import time

import pytest

websockets = pytest.importorskip("websockets")
mcap_reader = pytest.importorskip("mcap.reader")
from websockets.asyncio.client import connect  # noqa: E402

BIN = os.environ.get("EQUIARM_BIN")
pytestmark = pytest.mark.skipif(not BIN, reason="EQUIARM_BIN is not set: point it at a built `equiarm`")
ROOT = pathlib.Path(__file__).resolve().parents[2]
WANT = {"/trainer/status": 3, "/env0/camera/color/image_raw": 3}
# Foxglove's WebSocket protocol v1, by its original name and by the name Foxglove's SDK (whose server
# the recorder runs) now gives the same messages; the server picks the one it speaks.
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def watch(port, deadline):
    """Subscribes to the WANT topics as they are advertised; returns their schemas and payloads."""
    got = {t: [] for t in WANT}
    schemas = {}
    while True:  # the recorder starts its server a moment after train.sh starts it
        try:
            ws = await connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, max_size=None)
            break
        except OSError:
            assert time.monotonic() < deadline, "no Foxglove server came up"
            await asyncio.sleep(0.2)
    async with ws:
        assert ws.subprotocol in SUBPROTOCOLS
        subs = {}
        while any(len(got[t]) < n for t, n in WANT.items()):
            left = deadline - time.monotonic()
            assert left > 0, {t: len(v) for t, v in got.items()}
            msg = await asyncio.wait_for(ws.recv(), timeout=left)
            if isinstance(msg, str):
                m = json.loads(msg)
                if m["op"] == "advertise":
                    for ch in m["channels"]:
                        if ch["topic"] in WANT and ch["topic"] not in schemas:
                            schemas[ch["topic"]] = ch
                            sid = len(subs) + 1
                            subs[sid] = ch["topic"]
                            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sid, "channelId": ch["id"]}]}))
            elif msg[0] == 0x01:  # message data: subscription id, log time, payload
                sid, _log_time = struct.unpack_from("<IQ", msg, 1)
                topic = subs[sid]
                if len(got[topic]) < WANT[topic]:
                    got[topic].append(bytes(msg[13:]))
    return schemas, got


def test_a_websocket_client_gets_what_the_bag_records(tmp_path):
    port = free_port()
    run = tmp_path / "run"
    env = dict(os.environ, EQUIARM_BIN=BIN, ROS_DOMAIN_ID=str(random.randint(120, 200)))
    proc = subprocess.Popen(["bash", str(ROOT / "launch_scripts" / "train.sh"), "--preset", "reduced", "--num-envs", "1",
                             "--total-updates", "100000", "--run-dir", str(run), "--foxglove", str(port)],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        schemas, got = asyncio.run(watch(port, time.monotonic() + 240))
    finally:
        os.killpg(proc.pid, signal.SIGINT)  # train.sh stops every node and closes the bag
        proc.wait(timeout=120)
    bags = sorted((run / "bag").glob("*.mcap"))
    recorded = {t: set() for t in WANT}
    bag_schemas = {}
    for path in bags:
        with open(path, "rb") as f:
            for schema, channel, message in mcap_reader.make_reader(f).iter_messages(topics=list(WANT)):
                recorded[channel.topic].add(bytes(message.data))
                bag_schemas[channel.topic] = (schema.name, schema.encoding, schema.data.decode(), channel.message_encoding)
    for topic, payloads in got.items():
        ch = schemas[topic]
        assert (ch["schemaName"], ch["schemaEncoding"], ch["schema"], ch["encoding"]) == bag_schemas[topic], topic
        for p in payloads:
            assert p in recorded[topic], f"{topic}: a message the bag does not hold ({len(p)} bytes)"
