"""Soak: a long real-time run of the four-process loop; memory of each node and completeness of the bag.

    python bench/soak.py [--steps 100000] [--rate 100] [--sample-s 5] [--out DIR]

Runs `rta-attitude launch --realtime RATE --duration STEPS` (paper-example; its command schedule
ends at 1000 s, the filter keeps running for the rest) and samples the resident memory (VmRSS in
/proc) of every node process meanwhile. Reports, per node, the RSS after warm-up (the median over
the first 10 % of the run after the first minute) and at the end (median over the last 10 %) and
their change; the issue's bar is "flat within 10 %". Then checks that nothing was lost: every topic's
message count in the bag equals what its publisher says it published (the nodes' exit lines
`published: ...`), and the plant's counts equal its final run_status.

Prints a table and writes `bench/results/soak.json` (with the machine's load).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results"
NODES = ("plant_node", "pd_controller_node", "asif_filter_node", "bag_recorder_node")


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            out += [int(c) for c in task.read_text().split()]
        except OSError:
            pass
    return out


def _rss_kb(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def _role(pid: int) -> str | None:
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return None
    for name, module in zip(NODES, ("plant_node", "controller_node", "filter_node", "recorder_node")):
        if f"rta_attitude.ros.{module}" in cmd:
            return name
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=100_000, help="real-time steps (default 100000)")
    parser.add_argument("--rate", type=float, default=100.0, help="steps per wall second (default 100)")
    parser.add_argument("--sample-s", type=float, default=5.0, help="RSS sampling period, s (default 5)")
    parser.add_argument("--out", type=Path, default=None, help="bag, logs and summary here (default: a temp dir)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="soak_"))
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID", str(random.SystemRandom().randint(40, 100))),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "PYTHONPATH": str(REPO)}
    bag = out / "soak.mcap"
    cmd = [sys.executable, "-m", "rta_attitude.cli", "launch", "--realtime", f"{args.rate:g}", "--duration",
           str(args.steps), "--bag", str(bag), "--out", str(out), "--overwrite", "-p", "deadline_fallback=zero"]
    print(f"soak: {args.steps} steps at {args.rate:g} steps/s (~{args.steps / args.rate / 60:.0f} min), "
          f"load {os.getloadavg()[0]:.1f}; {out}", flush=True)
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    samples: dict[str, list[tuple[float, int]]] = {n: [] for n in NODES}
    loads = []
    while proc.poll() is None:
        for pid in _children(proc.pid):
            role = _role(pid)
            rss = _rss_kb(pid) if role else None
            if role and rss:
                samples[role].append((time.monotonic() - t0, rss))
        loads.append(os.getloadavg()[0])
        time.sleep(args.sample_s)
    stdout, stderr = proc.communicate()
    wall = time.monotonic() - t0
    if proc.returncode != 0:
        print(stdout[-3000:], stderr[-3000:], sep="\n")
        print(f"soak: the launch failed (exit {proc.returncode})")
        return 1
    sys.path.insert(0, str(REPO))
    from rta_attitude.recording.bag import read_bag
    from rta_attitude.ros import convert

    contents = read_bag(bag, decode=False)
    counts = {t.rsplit("/", 1)[-1]: n for t, n in contents.counts.items()}  # topic leaf names, as the nodes log them
    published: dict[str, int] = {}
    for name in NODES[:3]:
        text = (out / "logs" / f"{name}.log").read_text(errors="replace")
        m = re.search(r"published: (.*?); counters", text)
        if m:
            items = (i.rsplit(" ", 1) for i in m.group(1).split(", "))
            published.update({t.rsplit("/", 1)[-1]: int(n) for t, n in items})
    status = read_bag(bag, topics=["/rta/run_status"]).messages
    state, values = convert.run_status_from_msg(status[-1].message)
    lost = {t: (published[t], counts.get(t, 0)) for t in published if counts.get(t, 0) != published[t]}
    rows = {}
    for name, series in samples.items():
        if len(series) < 10:
            continue
        after = [r for t, r in series if t > 60.0] or [r for _, r in series]
        k = max(1, len(after) // 10)
        start, end = statistics.median(after[:k]), statistics.median(after[-k:])
        rows[name] = {"rss_start_mb": start / 1024, "rss_end_mb": end / 1024, "rss_max_mb": max(after) / 1024,
                      "change": (end - start) / start, "samples": len(series)}
    print(f"\nrun {state}: {values.get('step')} steps in {wall:.0f} s, deadline misses "
          f"{values.get('deadline_misses')}, bag {bag.stat().st_size / 1e6:.0f} MB, "
          f"{'truncated' if contents.truncated else 'complete'}")
    print(f"{'node':<22}{'RSS start MB':>14}{'RSS end MB':>12}{'max MB':>10}{'change':>9}")
    for name, r in rows.items():
        print(f"{name:<22}{r['rss_start_mb']:>14.1f}{r['rss_end_mb']:>12.1f}{r['rss_max_mb']:>10.1f}"
              f"{r['change']:>+9.1%}")
    print("messages: " + ", ".join(f"{t} {n}" for t, n in sorted(counts.items())))
    print("lost: " + (", ".join(f"{t} published {a}, in bag {b}" for t, (a, b) in lost.items()) or "nothing"))
    flat = all(abs(r["change"]) <= 0.10 for r in rows.values())
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "soak.json").write_text(json.dumps({
        "steps": args.steps, "rate_steps_per_s": args.rate, "wall_s": wall, "run_state": state,
        "deadline_misses": values.get("deadline_misses"), "nodes": rows, "bag_counts": counts,
        "published": published, "lost": lost, "rss_flat_within_10_percent": flat,
        "load_1min_median": statistics.median(loads) if loads else None, "cpus": os.cpu_count(),
    }, indent=2) + "\n")
    print(f"wrote {RESULTS / 'soak.json'}")
    return 0 if flat and not lost and state == "done" else 1


if __name__ == "__main__":
    sys.exit(main())
