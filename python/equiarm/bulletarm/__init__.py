"""BulletArm's API over equiarm's simulator: ``from equiarm.bulletarm import env_factory`` in place
of ``from bulletarm import env_factory``, then ``env_factory.createEnvs(num_processes, env_type,
env_config, planner_config)`` as in BulletArm, for its five close-loop tasks. docs/python.md lists
every ``env_config`` and ``planner_config`` key: supported, mapped, or refused."""

from equiarm.bulletarm import env_factory
from equiarm.bulletarm.runner import MultiRunner, SingleRunner

__all__ = ["MultiRunner", "SingleRunner", "env_factory"]
