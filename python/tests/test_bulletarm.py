"""BulletArm's API: a BulletArm-style collection script (python/examples/bulletarm_expert.py) gets the
experts' success rates through getNextAction, with BulletArm's return layouts."""

import importlib.util
import pathlib

import numpy as np
import pytest

from equiarm.bulletarm import env_factory

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "examples" / "bulletarm_expert.py"


def _example():
    spec = importlib.util.spec_from_file_location("bulletarm_expert", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("env_type", list(_example().TASKS))
def test_a_bulletarm_script_collects_100_expert_episodes(env_type):
    r = _example().collect(env_type, episodes=100, processes=5)
    assert r["episodes"] == 100
    assert r["success_rate"] >= 0.95, r
    assert r["obs_shape"] == [5, 4, 152, 152]


def test_multi_runner_layouts():
    envs = env_factory.createEnvs(2, "close_loop_block_pulling", {"obs_size": 32, "seed": 3, "max_steps": 3})
    states, in_hands, obs = envs.reset()
    assert states.shape == (2,) and states.dtype == np.float64 and not states.any()
    assert in_hands.shape == (2,) and np.isnan(in_hands).all()
    assert obs.shape == (2, 4, 32, 32) and obs.dtype == np.float64
    assert 0.0 <= obs[:, :3].min() and obs[:, :3].max() <= 1.0  # RGB / 255
    assert obs[:, 3].min() > 0.1  # depth, metres
    actions = envs.getNextAction()
    assert actions.shape == (2, 5) and actions.dtype == np.float64
    assert np.all(np.abs(actions[:, 1:4]) <= 0.05 + 1e-6)
    assert envs.getStepsLeft().tolist() == [3, 3]
    envs.stepAsync(actions, auto_reset=False)
    (s1, h1, o1), rewards, dones = envs.stepWait()
    assert rewards.shape == (2,) and dones.dtype == np.float32 and o1.shape == obs.shape
    assert envs.getStepsLeft().tolist() == [2, 2]
    for _ in range(2):
        (s1, h1, o1), rewards, dones = envs.step(envs.getNextAction(), auto_reset=True)
    assert dones.tolist() == [1.0, 1.0]  # the step limit
    assert envs.getStepsLeft().tolist() == [3, 3]  # auto_reset: new episodes started
    s2, h2, o2 = envs.reset_envs([1])
    assert o2.shape == (1, 4, 32, 32)
    with pytest.raises(NotImplementedError, match="saveToFile"):
        envs.saveToFile("x")
    envs.close()


def test_the_same_seed_gives_env_k_the_seed_plus_k():
    a = env_factory.createEnvs(2, "close_loop_block_pushing", {"obs_size": 24, "seed": 10})
    b = env_factory.createEnvs(0, "close_loop_block_pushing", {"obs_size": 24, "seed": 11})
    _, _, oa = a.reset()
    _, _, ob = b.reset()
    assert np.array_equal(oa[1], ob)


def test_single_runner_layouts_and_depth_only_view():
    env = env_factory.createEnvs(0, "close_loop_drawer_opening", {"obs_size": 24, "view_type": "camera_side", "seed": 1})
    holding, in_hand, obs = env.reset()
    assert holding is False and in_hand is None and obs.shape == (1, 24, 24)
    (holding, in_hand, obs), reward, done = env.step(env.getNextAction())
    assert isinstance(reward, float) and isinstance(done, bool) and obs.shape == (1, 24, 24)
    assert env.getStepsLeft() == 49


def test_trans_robot_hides_the_arm():
    def first_channel(trans):
        env = env_factory.createEnvs(0, "close_loop_block_picking", {"obs_size": 64, "seed": 2, "trans_robot": trans})
        return env.reset()[2][0]

    shown, hidden = first_channel(False), first_channel(True)
    changed = (shown != hidden).mean()
    assert 0.005 < changed < 0.5, changed  # the arm's pixels, in the top part of the image
    with pytest.raises(TypeError, match="trans_robot"):
        env_factory.createEnvs(0, "close_loop_block_picking", {"trans_robot": "yes"})
