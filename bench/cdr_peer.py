"""Cyclone DDS Python side of msgs/benches/cdr.rs: decodes and re-encodes the Observation bytes given
as argv[1] and prints the median encode and decode throughput in MB/s."""

import pathlib
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "python"))
import equiarm_idl as idl  # noqa: E402

data = pathlib.Path(sys.argv[1]).read_bytes()
rounds = int(sys.argv[2])
iters = 50
msg = idl.Observation.deserialize(data)
assert bytes(msg.serialize()) == data, "Cyclone DDS re-encodes the Rust bytes differently"


def rate(f):
    for _ in range(iters // 4):
        f()
    out = []
    for _ in range(rounds):
        t = time.perf_counter()
        for _ in range(iters):
            f()
        out.append(len(data) * iters / (time.perf_counter() - t) / 1e6)
    return statistics.median(out)


enc = rate(lambda: msg.serialize())
dec = rate(lambda: idl.Observation.deserialize(data))
print(enc, dec)
