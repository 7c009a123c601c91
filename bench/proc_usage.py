#!/usr/bin/env python3
"""CPU time and peak RSS of every equiarm process while a job runs (issue 59: what the suite's
sims, policies, recorder and trainer each cost per update).

    python3 bench/proc_usage.py OUT.csv [--every 5] [--until-gone] [--exe PATH]

Samples /proc every `--every` seconds: each process whose program is named `equiarm` (or
`equiarm-*`), its role (the subcommand and, for sims and policies, the namespace: `sim /env0`,
`policy /eval`, `train`, `record`; with `--exe`, only processes of that binary, so that other
equiarm processes on the machine are not counted), its CPU seconds (user + system) and its peak RSS (VmHWM). It stops on
SIGINT/SIGTERM or, with `--until-gone`, once processes were seen and none is left, and writes one
row per process: pid, role, cpu_s, peak_rss_mib, first_seen_s, last_seen_s (seconds since start).
CPU time after the last sample of a process is not counted (at most `--every` seconds of it).
"""
import argparse
import csv
import os
import signal
import time

TICK = os.sysconf("SC_CLK_TCK")


def role(argv):
    """`sim /env0`, `policy /eval`, `train`, ...: the subcommand and its namespace if any."""
    args = argv[1:]
    sub = next((a for a in args if not a.startswith("-")), "?")
    ns = ""
    if "--namespace" in args:
        i = args.index("--namespace")
        ns = args[i + 1] if i + 1 < len(args) else ""
    return f"{sub} {ns}".strip()


def sample(pid, exe=None):
    """(argv, cpu seconds, peak RSS MiB) of a process, or None if it is not ours or gone."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = [a.decode(errors="replace") for a in f.read().split(b"\0") if a]
        if not argv or not os.path.basename(argv[0]).startswith("equiarm"):
            return None
        if exe is not None and os.path.realpath(f"/proc/{pid}/exe") != exe:
            return None
        with open(f"/proc/{pid}/stat") as f:
            # the fields after the command name in parentheses; utime and stime are fields 14, 15
            rest = f.read().rsplit(")", 1)[1].split()
        cpu = (int(rest[11]) + int(rest[12])) / TICK
        hwm = 0
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    hwm = int(line.split()[1]) / 1024
        return argv, cpu, hwm
    except (OSError, IndexError, ValueError):
        return None


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--every", type=float, default=5.0)
    p.add_argument("--until-gone", action="store_true")
    p.add_argument("--exe", help="count only processes of this binary")
    a = p.parse_args()
    exe = os.path.realpath(a.exe) if a.exe else None
    stop = []
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, lambda *_: stop.append(1))
    t0 = time.monotonic()
    seen = {}
    while not stop:
        now = time.monotonic() - t0
        alive = 0
        for name in os.listdir("/proc"):
            if not name.isdigit() or int(name) == os.getpid():
                continue
            s = sample(name, exe)
            if s is None:
                continue
            alive += 1
            argv, cpu, hwm = s
            row = seen.setdefault(name, {"role": role(argv), "first": now})
            row.update(cpu=cpu, rss=max(hwm, row.get("rss", 0)), last=now)
        if a.until_gone and seen and not alive:
            break
        time.sleep(a.every)
    with open(a.out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pid", "role", "cpu_s", "peak_rss_mib", "first_seen_s", "last_seen_s"])
        for pid, r in sorted(seen.items(), key=lambda kv: (kv[1]["role"], int(kv[0]))):
            w.writerow([pid, r["role"], f"{r['cpu']:.1f}", f"{r['rss']:.1f}", f"{r['first']:.0f}", f"{r['last']:.0f}"])


if __name__ == "__main__":
    main()
