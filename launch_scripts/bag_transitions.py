#!/usr/bin/env python3
"""Rebuilds the training transitions (env, episode, step, obs, action, reward, next_obs, done, timeout,
expert) of an equiarm bag, with the third-party `mcap` + `mcap-ros2-support` readers, independently
of the equiarm program.

A Transition on /transitions carries no images: it names its two observations by `obs_seq` and
`next_obs_seq`, the `seq` of Observations of the same `env` (on that env's `<ns>/observation` topic,
which the recorder must have recorded: launch_scripts/lib.sh and equiarm.launch.py name them). This
script joins each Transition with its two Observations on (env, seq):

- an Observation may be in the bag more than once (the sim re-publishes an unanswered one): the
  copies are counted as duplicates and ignored;
- the order of /transitions and the observation topics in the bag is not relied on (an Observation
  may come after the Transition that names it, Transitions may be out of order within `--window`);
- the memory is bounded: per env only the Observations not consumed yet are kept (a frame is consumed
  once it served as obs, unless it is an episode's `terminal` frame, and as next_obs, unless it is an
  episode's first frame), and those more than `--window` frames below the newest seq seen in that env
  are dropped (so are Transitions still waiting for them: they count as unmatched).

Each joined transition is checked: both observations of its env and episode, obs at its step and
next_obs at step + 1, action.obs_seq = obs_seq, next_obs_seq = obs_seq + 1; a failed check counts as
inconsistent (the transition is still kept).

Prints a summary: transitions joined, unmatched, inconsistent, duplicate and unused observations, and
per env the joined transitions, episodes, done and timeout ends. With `--npz OUT` it also writes the
joined transitions as numpy arrays (numpy.savez_compressed), sorted by env and obs_seq (so within an
env, row k's next_obs is row k+1's obs unless row k ends an episode):

    env (N,) str, episode (N,) uint32, step (N,) uint32, obs_seq / next_obs_seq (N,) uint64,
    obs_color / next_obs_color (N, H, W, 3) uint8 (rgb8), obs_depth / next_obs_depth (N, H, W) float32
    (metres, each exactly the half float the Observation carries), obs_holding / next_obs_holding (N,) bool, action (N, 5) float32 (open_ratio, dx, dy, dz,
    dtheta: physical units, as commanded), action_source (N,) uint8, reward (N,) float32,
    done / timeout / expert (N,) bool

(all observations must then have the same image size; the arrays are held in memory until written).

Usage:
    python3 launch_scripts/bag_transitions.py BAG [--npz OUT.npz] [--json] [--window N]

    BAG          a bag directory (the .mcap files metadata.yaml lists, else its *.mcap in index order)
                 or one .mcap file
    --npz OUT    also write the joined transitions to OUT (a .npz file)
    --json       print the summary as one JSON object instead of text
    --window N   how many frames below the newest seq seen in an env are still waited for
                 (default 200)

Example:
    bash launch_scripts/demo.sh --num-envs 2 --episodes 3 --out runs/demo
    python3 launch_scripts/bag_transitions.py runs/demo/bag --npz runs/demo/transitions.npz
Needs: pip install mcap==1.6.0 mcap-ros2-support==0.6.0 numpy zstandard (tests/python/requirements.txt
pins them; mcap needs zstandard already).
Exit status: 0, or 1 when the bag holds Transitions of which none could be joined.
"""

import argparse
import importlib.util
import json
import pathlib
import sys
from collections import defaultdict

OBSERVATION = "equiarm_msgs/msg/Observation"
TRANSITION = "equiarm_msgs/msg/Transition"
ACTION_FIELDS = ("open_ratio", "dx", "dy", "dz", "dtheta")


def bag_files(bag: pathlib.Path):
    """read_bag.py's bag_files (the files of a bag directory in metadata.yaml order), imported by path."""
    spec = importlib.util.spec_from_file_location("read_bag", pathlib.Path(__file__).resolve().parent / "read_bag.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.bag_files(bag)


def read_messages(bag: pathlib.Path):
    """(schema name, decoded message) of every Observation and Transition in the bag, in file order;
    other topics are skipped undecoded."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    factory, decoders = DecoderFactory(), {}
    for path in bag_files(bag):
        with open(path, "rb") as fh:
            for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
                if schema is None or schema.name not in (OBSERVATION, TRANSITION):
                    continue
                dec = decoders.get((path, schema.id))
                if dec is None:
                    dec = decoders[(path, schema.id)] = factory.decoder_for(channel.message_encoding, schema)
                yield schema.name, dec(message.data)


class EnvJoin:
    """The join state of one env: Observations not consumed yet, Transitions waiting for theirs.

    Everything more than `window` frames below the newest seq seen in the env (an Observation's seq or
    a Transition's obs_seq) is dropped: memory stays bounded whatever the bag holds."""

    def __init__(self, window):
        self.window = window
        self.frames = {}  # seq -> Observation, not consumed in every role it has
        self.used = {}  # seq -> roles it served so far ("obs", "next"), for the frames
        self.consumed = set()  # seqs consumed in every role (to recognise later copies)
        self.waiting = {}  # obs_seq -> Transition whose observations are not both here yet
        self.top = -1  # the newest seq seen
        self.pruned_at = -1
        self.joined = self.unmatched = self.duplicates = self.dropped = 0

    def _stale(self, seq):
        return seq < self.top - self.window

    def _see(self, seq):
        if seq > self.top:
            self.top = seq
            if self.top - self.pruned_at >= 16:
                self._prune()

    def add_observation(self, o):
        """The transitions `o` completes."""
        seq = int(o.seq)
        self._see(seq)
        if seq in self.frames or seq in self.consumed:
            self.duplicates += 1  # a re-published copy
            return []
        if self._stale(seq):
            self.dropped += 1  # too late: the transitions naming it were given up already
            return []
        self.frames[seq] = o
        out = []
        for obs_seq in (seq, seq - 1):  # o as obs, o as next_obs
            t = self.waiting.get(obs_seq)
            if t is not None and self._ready(t):
                del self.waiting[obs_seq]
                out.append(self._join(t))
        return out

    def add_transition(self, t):
        """[the joined transition] when both observations are here, else [] (it waits)."""
        self._see(int(t.obs_seq))
        if self._ready(t):
            return [self._join(t)]
        if self._stale(int(t.obs_seq)) or int(t.obs_seq) in self.waiting:
            self.unmatched += 1  # its observations were dropped already, or a second one for that seq
        else:
            self.waiting[int(t.obs_seq)] = t
        return []

    def _ready(self, t):
        return int(t.obs_seq) in self.frames and int(t.next_obs_seq) in self.frames

    def _join(self, t):
        obs, nxt = self.frames[int(t.obs_seq)], self.frames[int(t.next_obs_seq)]
        self._use(int(t.obs_seq), "obs")
        self._use(int(t.next_obs_seq), "next")
        self.joined += 1
        return t, obs, nxt

    def _use(self, seq, role):
        o = self.frames[seq]
        used = self.used.setdefault(seq, set())
        used.add(role)
        needed = set()
        if not getattr(o, "terminal", False):
            needed.add("obs")  # a terminal frame is answered by no command: it is no Transition's obs
        if o.step > 0:
            needed.add("next")  # an episode's first frame follows no step
        if needed <= used:
            del self.frames[seq], self.used[seq]
            self.consumed.add(seq)

    def _prune(self):
        self.pruned_at = self.top
        for seq in [s for s in self.frames if self._stale(s)]:
            del self.frames[seq]
            self.used.pop(seq, None)
            self.dropped += 1
        self.consumed = {s for s in self.consumed if not self._stale(s)}
        for seq in [s for s in self.waiting if self._stale(s)]:
            del self.waiting[seq]
            self.unmatched += 1

    def finish(self):
        """Transitions still waiting count as unmatched; returns the count of unused observations
        (dropped ones included)."""
        self.unmatched += len(self.waiting)
        self.waiting = {}
        return len(self.frames) + self.dropped


def check(t, obs, nxt):
    """The reasons a joined transition is inconsistent ([] when it is not)."""
    bad = []
    if not (obs.env == nxt.env == t.env):
        bad.append("env")
    if not (obs.episode == nxt.episode == t.episode):
        bad.append("episode")
    if obs.step != t.step or nxt.step != t.step + 1:
        bad.append("step")
    if int(t.next_obs_seq) != int(t.obs_seq) + 1 or int(t.action.obs_seq) != int(t.obs_seq):
        bad.append("seq")
    if getattr(obs, "terminal", False):
        bad.append("obs is terminal")
    if bool(t.done or t.timeout) != bool(getattr(nxt, "terminal", False)):
        bad.append("terminal")
    return bad


def join(messages, window=200, on_transition=None):
    """Joins (schema name, message) pairs; calls on_transition(t, obs, next_obs) for each joined
    transition and returns the summary dict."""
    envs = {}
    per_env = defaultdict(lambda: {"joined": 0, "unmatched": 0, "episodes": set(), "done": 0, "timeout": 0,
                                   "inconsistent": 0, "duplicate_observations": 0})
    n_tr = n_obs = 0
    inconsistent = []
    for name, m in messages:
        j = envs.get(m.env)
        if j is None:
            j = envs[m.env] = EnvJoin(window)
        if name == TRANSITION and not hasattr(m, "obs_seq"):
            raise SystemExit("this bag's Transitions carry their observations (the layout before "
                             "obs_seq/next_obs_seq): nothing to join")
        if name == OBSERVATION:
            n_obs += 1
            joined = j.add_observation(m)
        else:
            n_tr += 1
            joined = j.add_transition(m)
        for t, obs, nxt in joined:
            e = per_env[t.env]
            e["joined"] += 1
            e["episodes"].add(int(t.episode))
            e["done"] += bool(t.done)
            e["timeout"] += bool(t.timeout)
            bad = check(t, obs, nxt)
            if bad:
                e["inconsistent"] += 1
                if len(inconsistent) < 10:
                    inconsistent.append({"env": t.env, "obs_seq": int(t.obs_seq), "failed": bad})
            if on_transition is not None:
                on_transition(t, obs, nxt)
    unused = 0
    for env, j in envs.items():
        unused += j.finish()
        e = per_env[env]
        e["unmatched"] = j.unmatched
        e["duplicate_observations"] = j.duplicates
    for e in per_env.values():
        e["episodes"] = len(e["episodes"])
    return {
        "transitions": n_tr,
        "observations": n_obs,
        "joined": sum(e["joined"] for e in per_env.values()),
        "unmatched": sum(e["unmatched"] for e in per_env.values()),
        "inconsistent": sum(e["inconsistent"] for e in per_env.values()),
        "duplicate_observations": sum(e["duplicate_observations"] for e in per_env.values()),
        "unused_observations": unused,
        "inconsistent_examples": inconsistent,
        "envs": {env: per_env[env] for env in sorted(per_env)},
    }


# --- images ---------------------------------------------------------------------------------------
# An Observation carries its frame as `height`, `width` and two zstd frames (msgs/msg/Observation.msg):
# `color`, rgb8 pixels, and `depth`, metres as little-endian half floats, both row-major.

MAX_SIDE = 8192


def plane(obs, name, itemsize):
    """The decompressed bytes of one plane, checked against the frame's sides."""
    import zstandard

    h, w = int(obs.height), int(obs.width)
    if h > MAX_SIDE or w > MAX_SIDE:
        raise ValueError(f"frame of {h} x {w} pixels: each side must be at most {MAX_SIDE}")
    n = h * w * itemsize
    data = bytes(getattr(obs, name))
    params = zstandard.get_frame_parameters(data)
    if params.content_size != n:
        raise ValueError(f"{name}: a zstd frame of {params.content_size} bytes, expected {n} ({h} x {w} pixels)")
    raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=n)
    if len(raw) != n:
        raise ValueError(f"{name}: {len(raw)} bytes once decompressed, expected {n}")
    return raw


def color_array(obs):
    """(H, W, 3) uint8 RGB of an Observation."""
    import numpy as np

    return np.frombuffer(plane(obs, "color", 3), dtype=np.uint8).reshape(int(obs.height), int(obs.width), 3).copy()


def depth_array(obs):
    """(H, W) float32 metres of an Observation (each value exactly the half float sent)."""
    import numpy as np

    d = np.frombuffer(plane(obs, "depth", 2), dtype="<f2")
    return d.reshape(int(obs.height), int(obs.width)).astype(np.float32)


class Arrays:
    """Collects joined transitions as numpy-ready columns."""

    def __init__(self):
        self.cols = defaultdict(list)

    def __call__(self, t, obs, nxt):
        c = self.cols
        c["env"].append(t.env)
        c["episode"].append(int(t.episode))
        c["step"].append(int(t.step))
        c["obs_seq"].append(int(t.obs_seq))
        c["next_obs_seq"].append(int(t.next_obs_seq))
        for prefix, o in (("obs", obs), ("next_obs", nxt)):
            c[f"{prefix}_color"].append(color_array(o))
            c[f"{prefix}_depth"].append(depth_array(o))
            c[f"{prefix}_holding"].append(bool(o.holding))
        c["action"].append([float(getattr(t.action, f)) for f in ACTION_FIELDS])
        c["action_source"].append(int(t.action.source))
        c["reward"].append(float(t.reward))
        c["done"].append(bool(t.done))
        c["timeout"].append(bool(t.timeout))
        c["expert"].append(bool(t.expert))

    def save(self, path):
        import numpy as np

        dtypes = {"env": str, "episode": np.uint32, "step": np.uint32, "obs_seq": np.uint64,
                  "next_obs_seq": np.uint64, "obs_color": np.uint8, "next_obs_color": np.uint8,
                  "obs_depth": np.float32, "next_obs_depth": np.float32, "obs_holding": bool,
                  "next_obs_holding": bool, "action": np.float32, "action_source": np.uint8,
                  "reward": np.float32, "done": bool, "timeout": bool, "expert": bool}
        order = sorted(range(len(self.cols["env"])), key=lambda i: (self.cols["env"][i], self.cols["obs_seq"][i]))
        out = {}
        for name, dtype in dtypes.items():
            col = [self.cols[name][i] for i in order]
            if name.endswith(("_color", "_depth")):
                shapes = {a.shape for a in col}
                if len(shapes) > 1:
                    raise ValueError(f"{name}: observations of different sizes {sorted(shapes)}")
                empty = (0, 0, 0, 3) if name.endswith("_color") else (0, 0, 0)
                out[name] = np.stack(col).astype(dtype) if col else np.zeros(empty, dtype=dtype)
            elif name == "action":
                out[name] = np.asarray(col, dtype=dtype).reshape(-1, len(ACTION_FIELDS))
            else:
                out[name] = np.asarray(col, dtype=dtype)
        out["action_fields"] = np.asarray(ACTION_FIELDS)
        with open(path, "wb") as f:
            np.savez_compressed(f, **out)


def print_summary(s):
    print(f"transitions: {s['transitions']} in the bag, {s['joined']} joined, {s['unmatched']} unmatched, "
          f"{s['inconsistent']} inconsistent")
    print(f"observations: {s['observations']} in the bag, {s['duplicate_observations']} duplicates, "
          f"{s['unused_observations']} unused")
    print(f"\n{'env':<12} {'joined':>8} {'unmatched':>9} {'episodes':>8} {'done':>6} {'timeout':>7} {'dup.obs':>7}")
    for env, e in s["envs"].items():
        print(f"{env:<12} {e['joined']:>8} {e['unmatched']:>9} {e['episodes']:>8} {e['done']:>6} "
              f"{e['timeout']:>7} {e['duplicate_observations']:>7}")
    for x in s["inconsistent_examples"]:
        print(f"inconsistent: env {x['env']} obs_seq {x['obs_seq']}: {', '.join(x['failed'])}")
    if "npz" in s:
        print(f"\nwrote {s['npz']}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", type=pathlib.Path)
    p.add_argument("--npz", type=pathlib.Path)
    p.add_argument("--json", action="store_true")
    p.add_argument("--window", type=int, default=200)
    args = p.parse_args(argv)
    if not args.bag.exists():
        p.error(f"{args.bag} does not exist")
    arrays = Arrays() if args.npz else None
    s = join(read_messages(args.bag), window=args.window, on_transition=arrays)
    if arrays is not None:
        arrays.save(args.npz)
        s["npz"] = str(args.npz)
    if args.json:
        print(json.dumps(s))
    else:
        print_summary(s)
    return 1 if s["transitions"] and not s["joined"] else 0


if __name__ == "__main__":
    sys.exit(main())
