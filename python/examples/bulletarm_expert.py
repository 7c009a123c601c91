"""Collects expert episodes the way BulletArm scripts do (written from BulletArm's documented API:
``env_factory.createEnvs``, ``getNextAction``, ``step(actions, auto_reset=True)``); only the import
line names equiarm. Prints one JSON line per task: episodes, successes, success rate, env steps per
second.

    python python/examples/bulletarm_expert.py [--episodes 100] [--processes 5] [--tasks close_loop_block_pulling ...]
"""

import argparse
import json
import time

import numpy as np

from equiarm.bulletarm import env_factory  # BulletArm: from bulletarm import env_factory

TASKS = {
    "close_loop_block_pulling": 2,
    "close_loop_block_pushing": 1,
    "close_loop_block_picking": 1,
    "close_loop_drawer_opening": 1,
    "close_loop_block_in_bowl": 2,
}


def collect(env_type: str, episodes: int, processes: int, seed: int = 0) -> dict:
    """Runs the planner in ``processes`` envs until ``episodes`` episodes have ended."""
    workspace = np.asarray([[0.25, 0.65], [-0.2, 0.2], [0.01, 0.25]])
    env_config = {
        "workspace": workspace,
        "max_steps": 50,
        "obs_size": 152,
        "fast_mode": True,
        "action_sequence": "pxyzr",
        "render": False,
        "num_objects": TASKS[env_type],
        "random_orientation": True,
        "robot": "kuka",
        "workspace_check": "point",
        "object_scale_range": (1, 1),
        "hard_reset_freq": 1000,
        "physics_mode": "fast",
        "view_type": "camera_side_rgbd",
        "obs_type": "pixel",
        "view_scale": 1.5,
        "transparent_bin": True,
        "seed": seed,
    }
    planner_config = {"random_orientation": True, "dpos": 0.05, "drot": np.pi / 4}
    envs = env_factory.createEnvs(processes, env_type, env_config, planner_config)
    states, in_hands, obs = envs.reset()
    ended, successes, steps = 0, 0, 0
    start = time.perf_counter()
    while ended < episodes:
        actions = envs.getNextAction()
        (states, in_hands, obs), rewards, dones = envs.step(actions, auto_reset=True)
        steps += processes
        for i in np.nonzero(dones)[0]:
            if ended < episodes:
                ended += 1
                successes += int(rewards[i] > 0)
    seconds = time.perf_counter() - start
    envs.close()
    return {
        "env_type": env_type,
        "episodes": ended,
        "successes": successes,
        "success_rate": successes / ended,
        "env_steps_per_s": steps / seconds,
        "obs_shape": list(obs.shape),
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--processes", type=int, default=5)
    p.add_argument("--tasks", nargs="*", default=list(TASKS))
    args = p.parse_args(argv)
    results = [collect(t, args.episodes, args.processes) for t in args.tasks]
    for r in results:
        print(json.dumps(r))
    return results


if __name__ == "__main__":
    main()
