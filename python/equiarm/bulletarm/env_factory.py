"""BulletArm's ``env_factory`` over equiarm: ``createEnvs(num_processes, env_type, env_config,
planner_config)`` for ``close_loop_block_pulling``, ``close_loop_block_pushing``,
``close_loop_block_picking``, ``close_loop_drawer_opening`` and ``close_loop_block_in_bowl``.

As in BulletArm: ``num_processes == 0`` gives a ``SingleRunner``, otherwise a ``MultiRunner`` of that
many envs; without ``env_config['seed']`` a seed is drawn from numpy's global generator
(``numpy.random.randint(1000)``); env k of a ``MultiRunner`` is seeded ``seed + k``.
"""

from __future__ import annotations

import numpy as np

from equiarm.bulletarm.config import check_planner, env_args
from equiarm.bulletarm.runner import MultiRunner, SingleRunner


def createEnvs(num_processes, env_type, env_config=None, planner_config=None):
    """A runner of ``env_type`` (see the module's docstring)."""
    if isinstance(num_processes, bool) or not isinstance(num_processes, (int, np.integer)) or num_processes < 0:
        raise ValueError(f"num_processes: {num_processes!r} must be an int >= 0")
    args = env_args(env_type, env_config or {})
    check_planner(planner_config or {})
    if "seed" not in args:
        args["seed"] = int(np.random.randint(1000))
    if num_processes == 0:
        return SingleRunner(args)
    return MultiRunner(args, int(num_processes))


def createSingleProcessEnv(env_type, env_config=None, planner_config=None):
    """One env (BulletArm's function of the same name)."""
    return createEnvs(0, env_type, env_config, planner_config)


def createMultiprocessEnvs(num_processes, env_type, env_config=None, planner_config=None):
    """``num_processes`` envs (BulletArm's function of the same name)."""
    if num_processes < 1:
        raise ValueError(f"num_processes: {num_processes!r} must be at least 1")
    return createEnvs(num_processes, env_type, env_config, planner_config)
