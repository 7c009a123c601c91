"""The Gymnasium environments: Gymnasium's own checker for every task, the spaces and semantics the
docs promise, and the vector env against Gymnasium's reference SyncVectorEnv of the same envs."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import SyncVectorEnv

import equiarm


@pytest.mark.parametrize("task", equiarm.TASKS)
def test_gymnasium_check_env_passes(task):
    env = gymnasium.make(equiarm.env_id(task), image_size=64)
    with np.errstate(all="raise"):
        check_env(env.unwrapped, skip_render_check=False)


def test_the_registered_ids_follow_the_task_names():
    assert equiarm.env_id("block_pulling") == "equiarm/BlockPulling-v0"
    assert equiarm.env_id("block_in_bowl") == "equiarm/BlockInBowl-v0"
    for task in equiarm.TASKS:
        assert equiarm.env_id(task) in gymnasium.registry


def test_observation_layout_and_an_expert_episode():
    env = equiarm.make("block_pulling", render_mode="rgb_array")
    obs, info = env.reset(seed=1)
    assert obs["color"].shape == (152, 152, 3) and obs["color"].dtype == np.uint8
    assert obs["depth"].shape == (152, 152) and obs["depth"].dtype == np.float32
    assert obs["gripper"].tolist() == [0.0, pytest.approx(1.0, abs=0.05)]
    assert 0.5 < float(obs["depth"].min()) and float(obs["depth"].max()) <= 3.0
    assert info["step"] == 0 and not info["success"]
    assert env.observation_space.contains(obs)
    steps, done = 0, False
    while not done:
        action = info["expert_action"]
        assert env.action_space.contains(action)
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        done = terminated or truncated
        assert np.array_equal(env.render(), obs["color"])
    assert terminated and not truncated and reward == 1.0 and info["success"] and info["step"] == steps


def test_the_step_limit_truncates():
    env = equiarm.make("block_picking", max_steps=3, image_size=32)
    env.reset(seed=0)
    flags = [env.step(np.zeros(5, np.float32))[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]


def test_same_seed_same_frames_and_episode_seed_replays_an_episode():
    a, b = equiarm.make("block_pushing", image_size=48), equiarm.make("block_pushing", image_size=48)
    oa, ia = a.reset(seed=7)
    ob, _ = b.reset(seed=7)
    assert np.array_equal(oa["color"], ob["color"]) and np.array_equal(oa["depth"], ob["depth"])
    a.reset()
    oc, ic = a.reset(options={"episode_seed": ia["seed"]})
    assert ic["seed"] == ia["seed"] and np.array_equal(oc["color"], oa["color"])


def test_views_and_corruptions_come_from_the_rust_types():
    assert "side" in equiarm.VIEWS and "angle90" in equiarm.VIEWS
    assert set(equiarm.CORRUPTIONS) == {"random_reflection", "occlusion_projection", "gripper_only"}
    env = equiarm.make("block_pulling", image_size=32, view="angle90", corruption="random_reflection,gripper_only")
    obs, _ = env.reset(seed=0)
    assert obs["color"].shape == (32, 32, 3)


def test_the_arm_is_drawn_unless_hidden():
    shown, _ = equiarm.make("block_picking", image_size=64).reset(seed=0)
    hidden, _ = equiarm.make("block_picking", image_size=64, arm="hidden").reset(seed=0)
    changed = np.any(shown["color"] != hidden["color"], axis=-1)
    assert 0.005 < changed.mean() < 0.5, changed.mean()
    assert changed[:32].sum() > changed[32:].sum(), "the arm comes in from the top of the image"
    with pytest.raises(ValueError, match="arm: "):
        equiarm.make("block_picking", arm="transparent")


def _reference(task, n, seed, **kw):
    # Gymnasium's own vector env of single equiarm envs with the seeds make_vec gives env k.
    return SyncVectorEnv([lambda k=k: equiarm.make(task, seed=seed + k, **kw) for k in range(n)])


def test_the_vector_env_equals_gymnasiums_sync_vector_env():
    n, kw = 3, dict(image_size=40, max_steps=4)
    ours = equiarm.make_vec("block_picking", n, seed=5, **kw)
    ref = _reference("block_picking", n, 5, **kw)
    assert ours.single_observation_space == ref.single_observation_space
    assert ours.single_action_space == ref.single_action_space
    assert ours.observation_space == ref.observation_space and ours.action_space == ref.action_space
    assert ours.metadata["autoreset_mode"] == ref.metadata["autoreset_mode"]
    o1, _ = ours.reset()
    o2, _ = ref.reset()
    rng = np.random.default_rng(0)
    for step in range(11):  # episodes of 4 steps: autoresets at steps 4 and 9
        for key in o1:
            assert np.array_equal(o1[key], o2[key]), (step, key)
        assert ours.observation_space.contains(o1)
        actions = rng.uniform(-1, 1, (n, 5)).astype(np.float32)
        o1, r1, t1, u1, i1 = ours.step(actions)
        o2, r2, t2, u2, _ = ref.step(actions)
        assert np.array_equal(r1, r2) and np.array_equal(t1, t2) and np.array_equal(u1, u2), step
        assert i1["expert_action"].shape == (n, 5) and i1["_success"].all()
    ours.close()
    ref.close()


def test_the_vector_env_is_deterministic_per_seed():
    a, b = equiarm.make_vec("drawer_opening", 2, image_size=32), equiarm.make_vec("drawer_opening", 2, image_size=32)
    oa, ia = a.reset(seed=11)
    ob, ib = b.reset(seed=11)
    assert np.array_equal(oa["color"], ob["color"]) and np.array_equal(ia["seed"], ib["seed"])
    assert ia["seed"][0] != ia["seed"][1]
    act = np.stack([a.expert_actions()[0], np.zeros(5, np.float32)])
    assert np.array_equal(a.step(act)[0]["depth"], b.step(act)[0]["depth"])


def test_frames_are_fresh_arrays_owned_by_numpy():
    env = equiarm.make("block_pulling", image_size=32)
    o1, _ = env.reset(seed=0)
    o2, *_ = env.step(np.zeros(5, np.float32))
    assert o1["color"] is not o2["color"]
    assert o1["color"].flags["C_CONTIGUOUS"] and o1["depth"].flags["C_CONTIGUOUS"]
    o1["color"][:] = 0  # writable, and changing it changes nothing in the env
    assert o2["color"].any()
