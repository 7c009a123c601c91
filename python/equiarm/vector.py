"""n envs of one task as a Gymnasium ``VectorEnv`` (``equiarm.make_vec``), stepped in parallel in
Rust threads with the GIL released; observations come back as arrays with a leading env axis.

Autoreset: Gymnasium's default, next-step (an env whose episode ended is reset by the following
``step``, its action ignored, with reward 0). ``infos`` holds ``success``, ``invalid``,
``expert_action`` (n, 5), ``seed`` and ``step``, each with its ``_``-prefixed mask (all True).
"""

from __future__ import annotations

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from equiarm import _equiarm
from equiarm.envs import action_space, observation_space


class EquiArmVectorEnv(VectorEnv):
    """``num_envs`` envs of ``task``; the keyword arguments as :class:`equiarm.EquiArmEnv`'s. Env k's
    episodes are seeded from ``seed + k``."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"]}

    def __init__(
        self,
        task: str,
        num_envs: int,
        *,
        image_size: int = 152,
        view: str = "side",
        corruption: str = "none",
        arm: str = "visible",
        max_steps: int | None = None,
        seed: int = 0,
        render_mode: str | None = None,
    ):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: {render_mode!r}: use None or 'rgb_array'")
        self._sim = _equiarm.SimVecEnv(
            task,
            num_envs,
            image_size=image_size,
            view=view,
            corruption=corruption,
            arm=arm,
            max_steps=max_steps,
            seed=seed,
            units="normalized",
        )
        self.num_envs = num_envs
        self.task = self._sim.facts["task"]
        self.render_mode = render_mode
        self.single_observation_space = observation_space(self._sim.facts["image_size"], self._sim.facts["far"])
        self.single_action_space = action_space()
        self.observation_space = observation_space(self._sim.facts["image_size"], self._sim.facts["far"], batch=num_envs)
        self.action_space = action_space(batch=num_envs)
        self._frames = None

    def _infos(self, rest: dict) -> dict:
        infos = {}
        for key in ("success", "expert_action", "seed", "step"):
            infos[key] = rest[key]
            infos["_" + key] = np.ones(self.num_envs, dtype=bool)
        infos["invalid"] = rest["terminated"] & ~rest["success"]
        infos["_invalid"] = np.ones(self.num_envs, dtype=bool)
        return infos

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None and not isinstance(seed, (int, np.integer)):
            raise TypeError(f"seed: {type(seed).__name__}: give one int (env k then uses seed + k) or None")
        if seed is not None:
            self._np_random_seed = int(seed)
        obs, rest = self._sim.reset(None if seed is None else int(seed))
        self._frames = obs["color"]
        return obs, self._infos(rest)

    def step(self, actions):
        obs, rest = self._sim.step(np.asarray(actions), "next_step")
        self._frames = obs["color"]
        return obs, rest["reward"], rest["terminated"], rest["truncated"], self._infos(rest)

    def render(self):
        """The envs' last colour frames (uint8, n x H x W x 3), in ``rgb_array`` mode."""
        if self.render_mode == "rgb_array":
            return self._frames
        return None

    def expert_actions(self) -> np.ndarray:
        """The expert planner's actions for the envs' current states, (n, 5), normalised."""
        return self._sim.expert_actions()


def make_vec(task: str, num_envs: int, **kwargs) -> EquiArmVectorEnv:
    """An :class:`EquiArmVectorEnv` of ``num_envs`` envs of ``task``."""
    return EquiArmVectorEnv(task, num_envs, **kwargs)
