"""BulletArm's ``env_config`` and ``planner_config`` read into equiarm's env arguments. A key or value
equiarm does not support is refused with a ``ValueError`` naming it; unknown keys too (a typo must
not pass silently)."""

from __future__ import annotations

import math

import numpy as np

from equiarm import _equiarm

_NAMES = _equiarm.names()
_ACTION = _equiarm.action_facts()

#: BulletArm view types equiarm renders, and the channels of their observations.
VIEW_TYPES = {"camera_side_rgbd": 4, "camera_side": 1}

#: Keys accepted with any value because they change nothing in the close-loop tasks' side views,
#: with the reason (docs/python.md).
IGNORED = {
    "fast_mode": "equiarm has one physics setting",
    "hard_reset_freq": "every reset builds a fresh world",
    "view_scale": "used by BulletArm's top-down views only",
    "transparent_bin": "no bin without close_loop_tray",
}

#: Keys accepted with exactly this value (BulletArm's meaning of it is what equiarm does).
FIXED = {
    "action_sequence": "pxyzr",
    "obs_type": "pixel",
    "robot": "kuka",
    "physics_mode": "fast",
    "workspace_check": "point",
    "random_orientation": True,
    "close_loop_tray": False,
    "collision_penalty": False,
    "render": False,
}

_OWN = {"workspace", "max_steps", "obs_size", "view_type", "seed", "num_objects", "object_scale_range", "trans_robot"}
PLANNER_KEYS = {"dpos": _ACTION["max_dpos"], "drot": _ACTION["max_drot"], "random_orientation": True}


def task_of(env_type: str) -> str:
    """equiarm's task for a BulletArm environment name."""
    tasks = _NAMES["bulletarm"]
    if env_type not in tasks:
        raise ValueError(f"env_type: {env_type!r} is not one of equiarm's tasks: {', '.join(tasks)}")
    return tasks[env_type]


def _same(a, b) -> bool:
    if isinstance(b, bool) or isinstance(a, bool):
        return a is b or (isinstance(a, (bool, np.bool_)) and bool(a) == b)
    if isinstance(b, str):
        return a == b
    return math.isclose(float(a), float(b), rel_tol=1e-6)


def env_args(env_type: str, env_config: dict) -> dict:
    """Keyword arguments of equiarm's env for a BulletArm env_config (``seed`` included if given)."""
    task = task_of(env_type)
    cfg = dict(env_config or {})
    unknown = sorted(set(cfg) - _OWN - set(IGNORED) - set(FIXED))
    if unknown:
        raise ValueError(f"env_config: {', '.join(map(repr, unknown))} not supported by equiarm (docs/python.md lists the keys)")
    for key, want in FIXED.items():
        if key in cfg and not _same(cfg[key], want):
            raise ValueError(f"env_config[{key!r}]: {cfg[key]!r} is not supported; equiarm does {want!r}")
    if "workspace" in cfg:
        ws = np.asarray(cfg["workspace"], dtype=float)
        ours = np.asarray(_ACTION["workspace"], dtype=float)
        if ws.shape != ours.shape or not np.allclose(ws, ours, atol=1e-6):
            raise ValueError(f"env_config['workspace']: {ws.tolist()} is not equiarm's workspace {ours.tolist()} (the paper's; fixed)")
    if "object_scale_range" in cfg and not np.allclose(np.asarray(cfg["object_scale_range"], dtype=float), [1.0, 1.0]):
        raise ValueError(f"env_config['object_scale_range']: {cfg['object_scale_range']!r} is not supported; equiarm's objects have scale (1, 1)")
    objects = _NAMES["objects"][task]
    if "num_objects" in cfg and cfg["num_objects"] != objects:
        raise ValueError(f"env_config['num_objects']: {cfg['num_objects']!r}, but {env_type} has {objects}")
    view = cfg.get("view_type", "camera_side_rgbd")
    if view not in VIEW_TYPES:
        raise ValueError(f"env_config['view_type']: {view!r} is not supported; equiarm renders {', '.join(VIEW_TYPES)}")
    args = {"task": task, "view_type": view}
    if "obs_size" in cfg:
        args["image_size"] = _int(cfg["obs_size"], "obs_size")
    if "max_steps" in cfg:
        args["max_steps"] = _int(cfg["max_steps"], "max_steps")
    if "seed" in cfg:
        args["seed"] = _int(cfg["seed"], "seed")
    if "trans_robot" in cfg:
        # the authors' flag for a robot drawn transparent: the arm is hidden, the gripper stays
        if not isinstance(cfg["trans_robot"], (bool, np.bool_)):
            raise TypeError(f"env_config['trans_robot']: expected a bool, got {type(cfg['trans_robot']).__name__}")
        args["arm"] = "hidden" if cfg["trans_robot"] else "visible"
    return args


def _int(v, key: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"env_config[{key!r}]: expected an int, got {type(v).__name__} {v!r}")
    if v < 0:
        raise ValueError(f"env_config[{key!r}]: {v} is negative")
    return int(v)


def check_planner(planner_config: dict) -> None:
    """Refuses planner settings equiarm's experts do not have (they move at most 0.05 m and pi/4 a step)."""
    cfg = dict(planner_config or {})
    unknown = sorted(set(cfg) - set(PLANNER_KEYS))
    if unknown:
        raise ValueError(f"planner_config: {', '.join(map(repr, unknown))} not supported by equiarm")
    for key, want in PLANNER_KEYS.items():
        if key in cfg and not _same(cfg[key], want):
            raise ValueError(f"planner_config[{key!r}]: {cfg[key]!r} is not supported; equiarm's planners use {want!r}")
