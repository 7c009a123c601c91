#!/usr/bin/env python3
"""Reads an equiarm bag (a rosbag2 directory of MCAP files, as `equiarm record` writes) with the
third-party `mcap` + `mcap-ros2-support` readers, independently of the equiarm program.

Prints the number of messages per topic (with its type), a table of the EpisodeResults on /episodes
(env, episode, seed, steps, success, return, discounted return, expert, eval) and the success rates
of the evaluation episodes and of the training episodes. An episode counts as evaluation when its
`eval` flag is set or its env is the evaluation pair's (`--eval-env`, default `eval`, i.e. the sim in
namespace /eval). Only /episodes is decoded (from the ros2msg schemas in the files); the other topics
are only counted, so large bags read quickly.

The files are those listed in metadata.yaml (`relative_file_paths`); a directory without
metadata.yaml (a recorder killed before closing; see `equiarm bag recover`) is read from its
`*.mcap` files in index order, and a single .mcap file can be given too.

Options:
    BAG              bag directory or .mcap file
    --eval-env ENV   env name of the evaluation pair (default: eval)
    --json           print one JSON object instead of tables

Example:
    python3 launch_scripts/read_bag.py runs/demo/bag
Needs: pip install mcap==1.6.0 mcap-ros2-support==0.6.0 (tests/python/requirements.txt pins them).
"""

import argparse
import json
import pathlib
import re
import sys
from collections import Counter


def bag_files(bag: pathlib.Path):
    """The .mcap files of a bag directory, in the order metadata.yaml lists them."""
    if bag.is_file():
        return [bag]
    meta = bag / "metadata.yaml"
    if meta.exists():
        names = relative_file_paths(meta.read_text())
        if names:
            return [bag / n for n in names]
    return sorted(bag.glob("*.mcap"), key=lambda p: [int(x) if x.isdigit() else x for x in re.split(r"(\d+)", p.stem)])


def relative_file_paths(text: str):
    """`rosbag2_bagfile_information.relative_file_paths` of a metadata.yaml (a YAML library when one is
    installed, else the few lines of that block list)."""
    for mod in ("yaml", "ruamel.yaml"):
        try:
            if mod == "yaml":
                import yaml
                doc = yaml.safe_load(text)
            else:
                from ruamel.yaml import YAML
                doc = YAML(typ="safe", pure=True).load(text)
            return list(doc["rosbag2_bagfile_information"]["relative_file_paths"])
        except ImportError:
            continue
    names, inside, indent = [], False, None
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("relative_file_paths:"):
            inside, indent = True, len(line) - len(line.lstrip())
            rest = stripped[len("relative_file_paths:"):].strip()
            if rest.startswith("["):  # flow style
                return [s.strip().strip("'\"") for s in rest.strip("[]").split(",") if s.strip()]
            continue
        if inside:
            if stripped.startswith("- "):
                names.append(stripped[2:].strip().strip("'\""))
            elif stripped and len(line) - len(line.lstrip()) <= indent:
                break
    return names


def read(bag: pathlib.Path):
    """(counts {topic: n}, types {topic: type}, episodes [dict]) of a bag."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    factory = DecoderFactory()
    counts, types, episodes, decoders = Counter(), {}, [], {}
    for path in bag_files(bag):
        with open(path, "rb") as fh:
            reader = make_reader(fh)
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                counts[channel.topic] += 1
                types[channel.topic] = schema.name if schema else "?"
                if channel.topic != "/episodes":
                    continue
                dec = decoders.get(schema.id)
                if dec is None:
                    dec = decoders[schema.id] = factory.decoder_for(channel.message_encoding, schema)
                r = dec(message.data)
                episodes.append(dict(env=r.env, task=r.task, seed=int(r.seed), episode=int(r.episode),
                                     steps=int(r.steps), success=bool(r.success), ret=float(r.ret),
                                     discounted_return=float(r.discounted_return), expert=bool(r.expert),
                                     eval=bool(r.eval), log_time=message.log_time))
    return dict(counts), types, episodes


def rate(eps):
    n = len(eps)
    ok = sum(e["success"] for e in eps)
    return {"episodes": n, "successes": ok, "success_rate": (ok / n) if n else None,
            "mean_discounted_return": (sum(e["discounted_return"] for e in eps) / n) if n else None}


def summarise(bag: pathlib.Path, eval_env: str = "eval"):
    counts, types, episodes = read(bag)
    for e in episodes:
        e["is_eval"] = e["eval"] or e["env"] == eval_env
    return {
        "bag": str(bag),
        "topics": {t: {"type": types[t], "count": counts[t]} for t in sorted(counts)},
        "episodes": episodes,
        "eval": rate([e for e in episodes if e["is_eval"]]),
        "train": rate([e for e in episodes if not e["is_eval"]]),
        "train_expert": rate([e for e in episodes if not e["is_eval"] and e["expert"]]),
    }


def fmt_rate(name, r):
    if not r["episodes"]:
        return f"{name:<14} no episodes"
    return (f"{name:<14} {r['successes']}/{r['episodes']} successful ({100 * r['success_rate']:.1f} %), "
            f"mean discounted return {r['mean_discounted_return']:.3f}")


def print_tables(s):
    print(f"bag: {s['bag']}")
    print(f"\n{'topic':<40} {'type':<40} {'count':>8}")
    for topic, t in s["topics"].items():
        print(f"{topic:<40} {t['type']:<40} {t['count']:>8}")
    print(f"\nepisodes ({len(s['episodes'])}):")
    print(f"{'env':<10} {'episode':>7} {'seed':>20} {'steps':>5} {'success':>7} {'return':>7} "
          f"{'disc.ret':>8} {'expert':>6} {'eval':>4}")
    for e in s["episodes"]:
        print(f"{e['env']:<10} {e['episode']:>7} {e['seed']:>20} {e['steps']:>5} {int(e['success']):>7} "
              f"{e['ret']:>7.2f} {e['discounted_return']:>8.3f} {int(e['expert']):>6} {int(e['is_eval']):>4}")
    print()
    print(fmt_rate("eval:", s["eval"]))
    print(fmt_rate("training:", s["train"]))
    if s["train_expert"]["episodes"]:
        print(fmt_rate("  of them expert:", s["train_expert"]))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=pathlib.Path)
    p.add_argument("--eval-env", default="eval")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not args.bag.exists():
        print(f"read_bag: {args.bag}: no such file or directory", file=sys.stderr)
        return 1
    s = summarise(args.bag, args.eval_env)
    if args.json:
        print(json.dumps(s))
    else:
        print_tables(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
