"""`equiarm bag export BAG --format lerobot OUT`, read back with Apache Arrow's own Parquet reader
(pyarrow) and checked against launch_scripts/bag_transitions.py's independent join of the same bag:
the LeRobotDataset v3.0 layout and column types, one row per joined transition, the normalised
action, reward, done, images and depth equal to the bag's. LeRobot's own loader is checked by
bench/lerobot_check.sh (torch from PyPI is several GB).

    EQUIARM_BIN=target/debug/equiarm python -m pytest tests/python/test_lerobot_export.py
"""

import io
import json
import os
import subprocess

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
Image = pytest.importorskip("PIL.Image")
from test_bag_transitions import RECORDS, color_pixels, depth_pixels, run, write_bag  # noqa: E402

BIN = os.environ.get("EQUIARM_BIN")
pytestmark = pytest.mark.skipif(not BIN, reason="EQUIARM_BIN is not set: point it at a built `equiarm`")
H, W = 3, 2


def export(bag, out):
    return subprocess.run([BIN, "bag", "export", str(bag), "--format", "lerobot", str(out)],
                          capture_output=True, text=True, timeout=120)


def normalised(a):
    """The agent's action from physical units (crates/types/src/action.rs), in float32 as there."""
    f = np.float32
    p = np.clip(a[:, 0], f(0), f(1)) * f(2) - f(1)
    d = np.clip(a[:, 1:4], f(-0.05), f(0.05)) / f(0.05)
    t = np.clip(a[:, 4], -f(np.pi / 4), f(np.pi / 4)) / f(np.pi / 4)
    return np.column_stack([p, d, t]).astype(np.float32)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lerobot")
    bag = tmp / "bag"
    write_bag(bag / "bag_0.mcap", RECORDS)
    npz = tmp / "t.npz"
    r = run(bag, "--npz", str(npz))
    assert r.returncode == 0, r.stderr
    out = tmp / "lerobot"
    r = export(bag, out)
    assert r.returncode == 0, r.stderr
    return out, dict(np.load(npz)), bag, r


def test_the_layout_and_info_are_lerobots(exported):
    out, *_ = exported
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0"
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    for default in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert default in info["features"]
    assert info["features"]["observation.image"] == {"dtype": "image", "shape": [H, W, 3],
                                                     "names": ["height", "width", "channels"]}
    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet")
    # exactly the non-video features, as LeRobot requires
    assert set(data.column_names) == set(info["features"])
    assert info["total_frames"] == data.num_rows
    episodes = pq.read_table(out / "meta" / "episodes" / "chunk-000" / "file-000.parquet")
    assert info["total_episodes"] == episodes.num_rows
    assert episodes.column("episode_index").to_pylist() == list(range(episodes.num_rows))
    stats = json.loads((out / "meta" / "stats.json").read_text())
    assert np.array(stats["observation.image"]["mean"]).shape == (3, 1, 1)
    assert np.array(stats["action"]["q50"]).shape == (5,)


def test_column_types(exported):
    out, *_ = exported
    s = pq.read_schema(out / "data" / "chunk-000" / "file-000.parquet")
    assert s.field("observation.image").type == pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    assert s.field("action").type == pa.list_(pa.float32(), 5)
    assert s.field("observation.depth").type == pa.list_(pa.list_(pa.float32(), W), H)
    assert s.field("next.reward").type == pa.float32()
    for b in ("next.done", "next.truncated", "next.success"):
        assert s.field(b).type == pa.bool_()
    for i in ("frame_index", "episode_index", "index", "task_index"):
        assert s.field(i).type == pa.int64()
    tasks = pq.read_table(out / "meta" / "tasks.parquet")
    # pandas reads the task names back as the index (LeRobot looks tasks up by it)
    assert json.loads(tasks.schema.metadata[b"pandas"])["index_columns"] == ["task"]


def test_rows_equal_the_independent_join(exported):
    out, t, *_ = exported
    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet").to_pydict()
    episodes = pq.read_table(out / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pydict()
    assert len(data["index"]) == len(t["reward"])
    assert data["index"] == list(range(len(data["index"])))
    # our rows keyed by (env, episode, k-th step), theirs too (sorted by env and obs_seq)
    env_of = dict(zip(episodes["episode_index"], episodes["env"]))
    ep_of = dict(zip(episodes["episode_index"], episodes["env_episode"]))
    ours = {(env_of[e], ep_of[e], k): i for i, (e, k) in enumerate(zip(data["episode_index"], data["frame_index"]))}
    theirs = {}
    for i, (env, ep) in enumerate(zip(t["env"], t["episode"])):
        k = sum(1 for j in range(i) if t["env"][j] == env and t["episode"][j] == ep)
        theirs[(str(env), int(ep), k)] = i
    assert set(ours) == set(theirs)
    want_actions = normalised(t["action"])
    for key, i in ours.items():
        j = theirs[key]
        assert np.array_equal(np.array(data["action"][i], dtype=np.float32), want_actions[j]), key
        assert np.float32(data["next.reward"][i]) == t["reward"][j]
        assert data["next.done"][i] == bool(t["done"][j]) and data["next.truncated"][i] == bool(t["timeout"][j])
        assert data["observation.state"][i] == float(t["obs_holding"][j])
        assert data["action_source"][i] == ("expert" if t["expert"][j] else "policy")
        png = Image.open(io.BytesIO(data["observation.image"][i]["bytes"]))
        assert np.array_equal(np.asarray(png), color_pixels(key[0], int(t["obs_seq"][j]))), key
        assert np.array_equal(np.array(data["observation.depth"][i], dtype=np.float32),
                              depth_pixels(key[0], int(t["obs_seq"][j]))), key
    # episodes are contiguous and their row ranges add up
    assert episodes["dataset_to_index"][-1] == len(data["index"])
    for e, (a, b) in enumerate(zip(episodes["dataset_from_index"], episodes["dataset_to_index"])):
        assert data["episode_index"][a:b] == [e] * (b - a)
        assert data["frame_index"][a:b] == list(range(b - a))


def test_a_truncated_bag_exports_what_is_readable_and_says_so(exported, tmp_path):
    _, _, bag, _ = exported
    whole = (bag / "bag_0.mcap").read_bytes()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "bag_0.mcap").write_bytes(whole[: len(whole) * 2 // 3])
    r = export(cut, tmp_path / "out")
    assert r.returncode == 0 and "ends early" in r.stderr, r.stderr


def test_bad_input_is_a_clear_error(exported, tmp_path):
    out, _, bag, _ = exported
    r = export(bag, out)  # not empty
    assert r.returncode == 1 and "not empty" in r.stderr and "panicked" not in r.stderr, r.stderr
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a bag")
    r = export(junk, tmp_path / "o1")
    assert r.returncode == 1 and "junk.mcap" in r.stderr and "panicked" not in r.stderr, r.stderr
    r = subprocess.run([BIN, "bag", "export", str(bag), "--format", "zarr", str(tmp_path / "o2")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "zarr" in r.stderr, r.stderr
