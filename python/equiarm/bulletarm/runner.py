"""BulletArm's runners over equiarm's envs, with BulletArm's return layouts.

- ``MultiRunner`` (``createEnvs(n > 0, ...)``): n envs stepped in parallel (Rust threads, not
  processes). ``reset()`` gives ``[states, in_hands, obs]``: ``states`` the holding flags (n,),
  ``in_hands`` NaN (n,) (close-loop envs have no in-hand image: BulletArm's ``None`` cast to float),
  ``obs`` (n, C, H, W) float64 with C = 4 for ``camera_side_rgbd`` (RGB / 255, then depth in metres)
  or 1 for ``camera_side`` (depth). ``step(actions, auto_reset)`` gives ``(that list, rewards (n,),
  dones (n,) float32)``; with ``auto_reset`` an ended env's observation is its next episode's first.
- ``SingleRunner`` (``createEnvs(0, ...)``): one env; ``reset()`` gives ``(holding, None, obs (C, H,
  W))``, ``step(action)`` gives ``((holding, None, obs), reward, done)``.

Actions are BulletArm's: (p, dx, dy, dz, dtheta) in physical units (p in [0, 1], metres, radians),
what ``getNextAction()`` returns.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from equiarm import _equiarm
from equiarm.bulletarm.config import VIEW_TYPES


def _images(obs: dict, view_type: str) -> np.ndarray:
    """BulletArm's observation images of equiarm's frames: channels first, float64."""
    depth = obs["depth"].astype(np.float64)[..., None, :, :]
    if VIEW_TYPES[view_type] == 1:
        return depth
    rgb = np.moveaxis(obs["color"], -1, -3).astype(np.float64) / 255.0
    return np.concatenate([rgb, depth], axis=-3)


def _unsupported(name: str):
    def method(self, *args, **kwargs):
        raise NotImplementedError(f"equiarm's BulletArm runner has no {name} (docs/python.md lists what is supported)")

    method.__name__ = name
    return method


class MultiRunner:
    """n envs of one task (BulletArm's ``MultiRunner`` API)."""

    def __init__(self, args: dict, num_envs: int):
        self._view = args["view_type"]
        self._sim = _equiarm.SimVecEnv(
            args["task"],
            num_envs,
            image_size=args.get("image_size", 152),
            max_steps=args.get("max_steps"),
            arm=args.get("arm", "visible"),
            seed=args.get("seed", 0),
            units="physical",
        )
        self.num_processes = num_envs
        self._pool = ThreadPoolExecutor(max_workers=1)
        self._pending = None
        self.waiting = False
        self.closed = False

    def _layout(self, obs: dict) -> list:
        states = obs["gripper"][:, 0].astype(np.float64)
        in_hands = np.full(states.shape[0], np.nan)
        return [states, in_hands, _images(obs, self._view)]

    def reset(self) -> list:
        """Resets every env: ``[states, in_hands, obs]``."""
        obs, _ = self._sim.reset(None)
        return self._layout(obs)

    def reset_envs(self, env_nums) -> list:
        """Resets the envs ``env_nums``: their ``[states, in_hands, obs]`` in that order."""
        obs, _ = self._sim.reset_envs([int(k) for k in env_nums])
        return self._layout(obs)

    def _step(self, actions, auto_reset: bool):
        obs, rest = self._sim.step(np.asarray(actions), "same_step" if auto_reset else "off")
        dones = (rest["terminated"] | rest["truncated"]).astype(np.float32)
        return self._layout(obs), rest["reward"].astype(np.float64), dones

    def step(self, actions, auto_reset: bool = False):
        """Steps env k with ``actions[k]``: ``([states, in_hands, obs], rewards, dones)``."""
        return self._step(actions, auto_reset)

    def stepAsync(self, actions, auto_reset: bool = False) -> None:
        """Starts a step (the envs run while Python goes on); ``stepWait`` returns its result."""
        if self.waiting:
            raise RuntimeError("stepAsync: the previous step has not been collected with stepWait")
        self._pending = self._pool.submit(self._step, np.array(actions, copy=True), auto_reset)
        self.waiting = True

    def stepWait(self):
        """The result of the step ``stepAsync`` started."""
        if not self.waiting:
            raise RuntimeError("stepWait: no step was started with stepAsync")
        self.waiting = False
        return self._pending.result()

    def getNextAction(self) -> np.ndarray:
        """The expert planners' actions for the envs' current states, (n, 5), physical units."""
        return self._sim.expert_actions().astype(np.float64)

    def getStepsLeft(self) -> np.ndarray:
        """Steps left before each env's episode limit, (n,)."""
        return np.asarray(self._sim.steps_left(), dtype=np.int64)

    def close(self) -> None:
        """Ends the runner (a step in flight is collected first)."""
        if self.waiting:
            self.stepWait()
        self._pool.shutdown(wait=True)
        self.closed = True

    save = _unsupported("save")
    restore = _unsupported("restore")
    saveToFile = _unsupported("saveToFile")
    loadFromFile = _unsupported("loadFromFile")
    simulate = _unsupported("simulate")
    canSimulate = _unsupported("canSimulate")
    resetSimPose = _unsupported("resetSimPose")
    gatherDeconstructTransitions = _unsupported("gatherDeconstructTransitions")


class SingleRunner:
    """One env (BulletArm's ``SingleRunner`` API)."""

    def __init__(self, args: dict):
        self._view = args["view_type"]
        self._sim = _equiarm.SimEnv(
            args["task"],
            image_size=args.get("image_size", 152),
            max_steps=args.get("max_steps"),
            arm=args.get("arm", "visible"),
            seed=args.get("seed", 0),
            units="physical",
        )

    def _layout(self, obs: dict):
        return bool(obs["gripper"][0] > 0.5), None, _images(obs, self._view)

    def reset(self):
        """Starts an episode: ``(holding, None, obs)``."""
        obs, _ = self._sim.reset(None)
        return self._layout(obs)

    def step(self, action, auto_reset: bool = True):
        """Applies ``action``: ``((holding, None, obs), reward, done)``. As in BulletArm,
        ``auto_reset`` is not used here: call ``reset()`` after ``done``."""
        obs, reward, terminated, truncated, _ = self._sim.step(np.asarray(action))
        return self._layout(obs), float(reward), bool(terminated or truncated)

    def getNextAction(self) -> np.ndarray:
        """The expert planner's action for the current state, (5,), physical units."""
        return self._sim.expert_action().astype(np.float64)

    def getStepsLeft(self) -> int:
        """Steps left before the episode limit."""
        return self._sim.steps_left()

    def close(self) -> None:
        """Nothing to release (BulletArm's ``SingleRunner.close`` does nothing either)."""

    save = _unsupported("save")
    restore = _unsupported("restore")
    saveToFile = _unsupported("saveToFile")
    loadFromFile = _unsupported("loadFromFile")
