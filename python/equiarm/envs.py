"""The Gymnasium environment of one task (``equiarm.make``; registered as ``equiarm/<Task>-v0``).

Observation: a ``Dict`` of ``color`` (uint8, H x W x 3), ``depth`` (float32, H x W, planar depth in
metres, the background at the camera's far distance) and ``gripper`` (float32, 2: the holding flag
and the jaw opening in [0, 1]). Action: ``Box(-1, 1, (5,))``, the policy node's normalisation of
(p, dx, dy, dz, dtheta). ``info``: ``success``, ``invalid`` (an object left the workspace),
``expert_action`` (the planner's action for the new state, in the action space's units), ``seed``
and ``step`` of the episode. An episode ends ``terminated`` on success or an invalid state and
``truncated`` at its step limit.
"""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium import spaces

from equiarm import _equiarm

_NAMES = _equiarm.names()
#: The task names (from the Rust crates).
TASKS: tuple = tuple(_NAMES["tasks"])
#: The camera view presets.
VIEWS: tuple = tuple(_NAMES["views"])
#: The symmetry corruptions (combine with commas: ``"random_reflection,gripper_only"``).
CORRUPTIONS: tuple = tuple(_NAMES["corruptions"])
_ACTION = _equiarm.action_facts()


def env_id(task: str) -> str:
    """The Gymnasium id of a task: ``block_pulling`` -> ``equiarm/BlockPulling-v0``."""
    return "equiarm/" + "".join(w.capitalize() for w in task.split("_")) + "-v0"


def observation_space(image_size: int, far: float, batch: int | None = None) -> spaces.Dict:
    """The observation space of an env with frames of ``image_size`` pixels (with ``batch``: of a
    vector env of that many envs)."""
    lead = () if batch is None else (batch,)
    s = image_size
    return spaces.Dict(
        {
            "color": spaces.Box(0, 255, lead + (s, s, 3), np.uint8),
            "depth": spaces.Box(0.0, float(far), lead + (s, s), np.float32),
            "gripper": spaces.Box(0.0, 1.0, lead + (2,), np.float32),
        }
    )


def action_space(batch: int | None = None) -> spaces.Box:
    """The normalised action space, ``Box(-1, 1, (5,))`` (with ``batch``: ``(batch, 5)``)."""
    lead = () if batch is None else (batch,)
    return spaces.Box(-1.0, 1.0, lead + (_ACTION["dim"],), np.float32)


class EquiArmEnv(gymnasium.Env):
    """One simulated env of ``task`` (see the module's docstring for the spaces).

    Arguments: ``image_size`` (pixels of the square frames, 152 in the paper), ``view`` (a camera
    preset, ``equiarm.VIEWS``), ``corruption`` (``"none"`` or a comma-separated set of
    ``equiarm.CORRUPTIONS``), ``arm`` (``"visible"``: the arm carrying the gripper is drawn, as in
    the paper; ``"hidden"``: the gripper floats), ``max_steps`` (the episode limit; the task's, 50, by default),
    ``seed`` (the episodes' seeds until ``reset(seed=...)`` gives another), ``render_mode``
    (``None`` or ``"rgb_array"``: ``render()`` returns the last colour frame).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        task: str = "block_pulling",
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
        self._sim = _equiarm.SimEnv(
            task,
            image_size=image_size,
            view=view,
            corruption=corruption,
            arm=arm,
            max_steps=max_steps,
            seed=seed,
            units="normalized",
        )
        self.task = self._sim.facts["task"]
        self.render_mode = render_mode
        self.observation_space = observation_space(self._sim.facts["image_size"], self._sim.facts["far"])
        self.action_space = action_space()
        self._frame = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Starts an episode. ``seed``: the episodes' seeds come from it from now on.
        ``options={"episode_seed": s}``: this episode is reset with exactly ``s`` (an
        ``info["seed"]`` or an ``EpisodeResult``'s seed: the same scene again)."""
        super().reset(seed=seed)
        options = dict(options or {})
        episode_seed = options.pop("episode_seed", None)
        if options:
            raise ValueError(f"options: {', '.join(map(repr, options))} not supported (only 'episode_seed')")
        obs, info = self._sim.reset(seed, episode_seed)
        self._frame = obs["color"]
        return obs, _numpy_seed(info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self._sim.step(np.asarray(action))
        self._frame = obs["color"]
        return obs, float(reward), terminated, truncated, _numpy_seed(info)

    def render(self):
        """The last observation's colour frame (uint8, H x W x 3), in ``rgb_array`` mode."""
        if self.render_mode == "rgb_array":
            return self._frame
        return None

    def expert_action(self) -> np.ndarray:
        """The expert planner's action for the current state (normalised, like the action space)."""
        return self._sim.expert_action()

    @property
    def max_steps(self) -> int:
        """The episode step limit."""
        return self._sim.facts["max_steps"]


def _numpy_seed(info: dict) -> dict:
    # Seeds use all 64 bits: as numpy.uint64 they batch into arrays (a Python int above 2**63 - 1
    # would not fit Gymnasium's int64 info arrays).
    info["seed"] = np.uint64(info["seed"])
    return info


def make(task: str, **kwargs) -> EquiArmEnv:
    """An :class:`EquiArmEnv` of ``task`` (its keyword arguments as there)."""
    return EquiArmEnv(task, **kwargs)


def register_envs() -> None:
    """Registers ``equiarm/<Task>-v0`` with Gymnasium for every task (done on import)."""
    for task in TASKS:
        if env_id(task) not in gymnasium.registry:
            gymnasium.register(id=env_id(task), entry_point="equiarm.envs:EquiArmEnv", kwargs={"task": task})
