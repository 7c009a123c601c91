"""equiarm from Python: the simulator's five tasks, their expert planners and trained policies,
in-process (no DDS, no ROS).

- ``equiarm.make(task, ...)`` / ``gymnasium.make("equiarm/BlockPulling-v0", ...)``: a Gymnasium env;
- ``equiarm.make_vec(task, n, ...)``: a Gymnasium ``VectorEnv`` stepping n envs in Rust threads;
- ``equiarm.bulletarm.env_factory.createEnvs(...)``: BulletArm's runner API;
- ``equiarm.load_policy(checkpoint)``: a trained actor, acting as the policy node does.

The task, view and corruption names come from the Rust crates (``equiarm.TASKS`` ...); docs/python.md
is the manual.
"""

from equiarm import _equiarm
from equiarm._equiarm import ResetNeeded, __version__
from equiarm.envs import CORRUPTIONS, TASKS, VIEWS, EquiArmEnv, env_id, make, register_envs
from equiarm.policy import Policy, load_policy
from equiarm.vector import EquiArmVectorEnv, make_vec

__all__ = [
    "CORRUPTIONS",
    "TASKS",
    "VIEWS",
    "EquiArmEnv",
    "EquiArmVectorEnv",
    "Policy",
    "ResetNeeded",
    "__version__",
    "env_id",
    "load_policy",
    "make",
    "make_vec",
]

register_envs()
