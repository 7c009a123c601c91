"""Trained policies (``equiarm.load_policy``): a checkpoint's actor acting as the policy node does,
on the same network input (the replay's frame: colour bytes and depth in float16, centre-cropped to
the network's input size)."""

from __future__ import annotations

import os

import numpy as np

from equiarm import _equiarm


class Policy:
    """The actor of a checkpoint or run directory; ``seed`` seeds the sampling noise."""

    def __init__(self, checkpoint: str | os.PathLike, *, seed: int = 0):
        self._actor = _equiarm.Policy(os.fspath(checkpoint), seed=seed)

    def act(self, obs: dict, deterministic: bool = True) -> np.ndarray:
        """The normalised action (float32, (5,)) for one observation of an equiarm env (a dict with
        ``color``, ``depth`` and ``gripper``): tanh of the mean when ``deterministic`` (the node's
        ``greedy`` mode), else a sample (``sample`` mode)."""
        if not isinstance(obs, dict):
            raise TypeError(f"obs: expected the env's observation dict, got {type(obs).__name__}")
        missing = [k for k in ("color", "depth", "gripper") if k not in obs]
        if missing:
            raise ValueError(f"obs: missing {', '.join(missing)} (an equiarm env's observation has color, depth, gripper)")
        color = np.ascontiguousarray(obs["color"], dtype=np.uint8)
        depth = np.ascontiguousarray(obs["depth"], dtype=np.float32)
        holding = bool(np.asarray(obs["gripper"]).reshape(-1)[0] > 0.5)
        return self._actor.act(color, depth, holding, deterministic)

    @property
    def image_size(self) -> int:
        """Side of the frames the actor was trained on, pixels."""
        return self._actor.image_size

    @property
    def input_size(self) -> int:
        """Side of the network input (the centre crop), pixels."""
        return self._actor.input_size

    @property
    def model(self) -> str:
        """The network family."""
        return self._actor.model


def load_policy(checkpoint: str | os.PathLike, *, seed: int = 0) -> Policy:
    """The trained actor of ``checkpoint`` (a checkpoint directory, a run directory: its latest
    checkpoint, or a ``checkpoints/latest`` pointer)."""
    return Policy(checkpoint, seed=seed)
