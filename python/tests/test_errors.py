"""Bad input from Python: an exception naming the argument, never a crash; a Rust panic arrives as a
RuntimeError."""

import numpy as np
import pytest

import equiarm
import equiarm._equiarm as native
from equiarm.bulletarm import env_factory


@pytest.fixture
def env():
    e = equiarm.make("block_pulling", image_size=32, max_steps=2)
    e.reset(seed=0)
    return e


def test_wrong_action_shape(env):
    with pytest.raises(ValueError, match=r"action: shape \[4\], expected \[5\]"):
        env.step(np.zeros(4, np.float32))


def test_wrong_action_dtype(env):
    with pytest.raises(TypeError, match="action: dtype int64 is not a float dtype"):
        env.step(np.zeros(5, np.int64))
    with pytest.raises(TypeError, match="action: expected a numpy array"):
        native.SimEnv("block_pulling").step([0.0] * 5)


def test_nan_action(env):
    with pytest.raises(ValueError, match=r"action: component 2 \(dy\) is NaN"):
        env.step(np.array([0, 0, np.nan, 0, 0], np.float32))


def test_a_list_action_is_read_like_an_array(env):
    env.step([0.0, 0.1, 0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(task="block_stacking"), r"task: unknown task `block_stacking`: use block_pulling, "),
        (dict(task="block_pulling", view="top"), r"view: unknown view `top`"),
        (dict(task="block_pulling", corruption="blur"), r"corruption: "),
        (dict(task="block_pulling", image_size=0), r"image_size: 0 must be 1..="),
        (dict(task="block_pulling", max_steps=0), r"max_steps: 0 must be 1..="),
        (dict(task="block_pulling", render_mode="human"), r"render_mode: 'human'"),
    ],
)
def test_bad_arguments_name_themselves(kwargs, message):
    with pytest.raises(ValueError, match=message):
        equiarm.make(**kwargs)


def test_a_step_after_the_end_needs_a_reset(env):
    env.step(np.zeros(5, np.float32))
    env.step(np.zeros(5, np.float32))
    with pytest.raises(equiarm.ResetNeeded, match="reset the environment"):
        env.step(np.zeros(5, np.float32))
    assert issubclass(equiarm.ResetNeeded, ValueError)
    env.reset()
    env.step(np.zeros(5, np.float32))


def test_a_step_before_any_reset():
    with pytest.raises(equiarm.ResetNeeded, match="must be reset"):
        equiarm.make("block_pulling", image_size=16).step(np.zeros(5, np.float32))


def test_vector_env_bad_actions():
    v = equiarm.make_vec("block_pulling", 2, image_size=16)
    v.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions: shape \[5\], expected \[2, 5\]"):
        v.step(np.zeros(5, np.float32))
    bad = np.zeros((2, 5), np.float32)
    bad[1, 4] = np.inf
    with pytest.raises(ValueError, match=r"actions\[1\]: component 4 \(dtheta\) is inf"):
        v.step(bad)
    with pytest.raises(TypeError, match="seed: list"):
        v.reset(seed=[1, 2])


def test_missing_and_wrong_checkpoints(tmp_path):
    with pytest.raises(ValueError, match="checkpoint: .*nope does not exist"):
        equiarm.load_policy(tmp_path / "nope")
    f = tmp_path / "actor.safetensors"
    f.write_bytes(b"not a tensor file")
    with pytest.raises(ValueError, match="checkpoint: .* is a file: give the checkpoint or run directory"):
        equiarm.load_policy(f)
    with pytest.raises(ValueError, match="checkpoint: "):
        equiarm.load_policy(tmp_path)


def test_a_rust_panic_becomes_a_runtime_error():
    with pytest.raises(RuntimeError, match=r"internal error in equiarm \(a bug.*forced by _panic_for_test"):
        native._panic_for_test()
    # the interpreter is fine afterwards
    equiarm.make("block_pulling", image_size=16).reset(seed=0)


@pytest.mark.parametrize(
    "env_type, config, planner, message",
    [
        ("close_loop_block_stacking", {}, {}, "env_type: 'close_loop_block_stacking' is not one of equiarm's tasks"),
        ("close_loop_block_pulling", {"view_type": "camera_center_xyz"}, {}, r"env_config\['view_type'\]: 'camera_center_xyz'"),
        ("close_loop_block_pulling", {"robot": "panda"}, {}, r"env_config\['robot'\]: 'panda' is not supported"),
        ("close_loop_block_pulling", {"obs_type": "state"}, {}, r"env_config\['obs_type'\]"),
        ("close_loop_block_pulling", {"num_objects": 3}, {}, r"env_config\['num_objects'\]: 3, but close_loop_block_pulling has 2"),
        ("close_loop_block_pulling", {"workspace": [[0.3, 0.6], [-0.15, 0.15], [0.01, 0.25]]}, {}, r"env_config\['workspace'\]"),
        ("close_loop_block_pulling", {"random_orientation": False}, {}, r"env_config\['random_orientation'\]: False"),
        ("close_loop_block_pulling", {"colour": "red"}, {}, r"env_config: 'colour' not supported"),
        ("close_loop_block_pulling", {"obs_size": 12.5}, {}, r"env_config\['obs_size'\]: expected an int"),
        ("close_loop_block_pulling", {}, {"dpos": 0.02}, r"planner_config\['dpos'\]: 0.02 is not supported"),
        ("close_loop_block_pulling", {}, {"pick_offset": 0.1}, r"planner_config: 'pick_offset' not supported"),
    ],
)
def test_bulletarm_keys_equiarm_does_not_support_are_refused(env_type, config, planner, message):
    with pytest.raises((ValueError, TypeError), match=message):
        env_factory.createEnvs(1, env_type, config, planner)
