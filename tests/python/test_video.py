"""`equiarm bag video BAG --out DIR`, decoded by an independent decoder (PyAV: ffmpeg's H.264): one file
per episode, one frame per step plus the episode's last frame, at the simulated rate, and frame 0's
colour panel equal to the Observation's colours within the codec's error (stated in docs/nodes.md).

    EQUIARM_BIN=target/debug/equiarm python -m pytest tests/python/test_video.py
"""

import json
import os
import subprocess

import numpy as np
import pytest

av = pytest.importorskip("av")
from test_bag_transitions import RECORDS, color_pixels, write_bag  # noqa: E402

BIN = os.environ.get("EQUIARM_BIN")
pytestmark = pytest.mark.skipif(not BIN, reason="EQUIARM_BIN is not set: point it at a built `equiarm`")
H, W = 3, 2
MIN_SIDE = 152  # crates/export/src/video.rs
# What H.264 at QP 12 in 4:2:0 (and the RGB <-> YUV conversions) may change of a flat block's colour,
# per channel (the largest error measured on these frames is printed by the test).
TOLERANCE = 6


def video(bag, out, *extra):
    return subprocess.run([BIN, "bag", "video", str(bag), "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=120)


def frames(path):
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        return [f.to_ndarray(format="rgb24") for f in c.decode(s)], s


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("video")
    bag = tmp / "bag"
    write_bag(bag / "bag_0.mcap", RECORDS)
    out = tmp / "videos"
    r = video(bag, out)
    assert r.returncode == 0, r.stderr
    return bag, out, r


def test_one_file_per_episode_one_frame_per_step_and_the_last(videos):
    _, out, _ = videos
    names = sorted(p.name for p in out.iterdir())
    # env0 episode 1 lost its second step (frame 6 never recorded): its video holds the first step only
    assert names == ["env0_ep0000.mp4", "env0_ep0001.mp4", "env1_ep0000.mp4"]
    f, s = frames(out / "env0_ep0000.mp4")
    assert len(f) == 3 + 1  # three steps, then the terminal frame
    assert s.codec_context.name == "h264"
    k = -(-MIN_SIDE // H)
    assert f[0].shape == (H * k + 20 + (H * k) % 2, 2 * W * k, 3)
    f, _ = frames(out / "env1_ep0000.mp4")
    assert len(f) == 1 + 1


def test_frame_rate_is_the_simulated_one(videos):
    _, out, _ = videos
    # the synthetic stamps are 1 ns apart: clamped to 1000 fps
    _, s = frames(out / "env0_ep0000.mp4")
    assert s.average_rate == 1000


def test_frame_0_is_the_observation_within_the_codec_error(videos):
    _, out, _ = videos
    f, _ = frames(out / "env0_ep0000.mp4")
    k = -(-MIN_SIDE // H)
    # the centre of each enlarged pixel of the colour panel (left half)
    centres = f[0][k // 2:H * k:k, k // 2:W * k:k].astype(int)
    want = color_pixels("env0", 0).astype(int)
    err = np.abs(centres - want).max()
    print(f"frame 0: largest error {err} of 255 per channel")
    assert err <= TOLERANCE, err


def test_selecting_episodes(videos, tmp_path):
    bag, _, _ = videos
    r = video(bag, tmp_path / "some", "--episodes", "env0:1")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "some").iterdir()) == ["env0_ep0001.mp4"]
    r = video(bag, tmp_path / "bad", "--episodes", "env0:x")
    assert r.returncode == 2 and "whole number" in r.stderr, r.stderr


def test_in_process_training_films_every_nth_evaluation(tmp_path):
    run = tmp_path / "run"
    r = subprocess.run([BIN, "train", "--in-process", "--image", "19:16", "--hidden", "8", "--batch-size", "8",
                        "--num-envs", "1", "--demo-episodes", "0", "--training-starts", "8", "--eval-every", "5",
                        "--eval-episodes", "2", "--checkpoint-every", "0", "-q", "--total-updates", "10",
                        "--video-every", "2", "--run-dir", str(run)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    # evaluations at updates 5 and 10: the second is filmed
    assert sorted(p.name for p in (run / "videos").iterdir()) == ["update_0000010"]
    files = sorted((run / "videos" / "update_0000010").iterdir())
    assert [f.name for f in files] == ["episode_00.mp4", "episode_01.mp4"]
    last = json.loads((run / "evals.json").read_text())[-1]
    counts = []
    for f in files:
        fr, s = frames(f)
        assert s.average_rate == 6  # the default physics: a step of 20 / 120 s
        counts.append(len(fr))
    # one frame per step plus the last of each episode
    assert sum(counts) == round(last["mean_length"] * 2) + 2, (counts, last)
