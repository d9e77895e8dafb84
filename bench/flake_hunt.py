"""Flake hunt: run every DDS test file N times while CPU burners keep every core busy.

    python bench/flake_hunt.py [--runs 20] [--burners N] [--workers N] [--files test/test_x.py ...] [-k EXPR]
                               [--out DIR] [--domains LO-HI]

A test that can fail by timing is a bug (in the test or in the product); this script looks for
them where they hide: under load. Each pass is one `pytest -m dds` process over the DDS test files
(every test marked `dds`: real rclpy over real Fast DDS, node processes, the launcher), with its own
random ROS_DOMAIN_ID (the conftest picks one), while `--burners` processes (default: one per core)
spin at full speed. `--workers 2` runs each pass as the README's test command does (pytest-xdist,
`-n 2 --dist loadfile`, each worker its own domain). Per-test outcomes are read from each pass's JUnit
XML; the table at the end gives failures per test and the first line of the first failure. Exit status
1 if anything failed.

Not part of CI (it takes ~20 x the DDS suite; about an hour on a 2-core machine).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import random
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _burn(stop: mp.synchronize.Event) -> None:  # type: ignore[name-defined]
    """Keep one core busy until `stop` is set (checks it every ~10 ms of work)."""
    x = 0
    while not stop.is_set():
        for _ in range(200_000):
            x = (x * 1103515245 + 12345) & 0xFFFFFFFF


def _outcomes(junit: Path) -> dict[str, tuple[str, str]]:
    """test id -> (outcome, first line of the failure message) from a JUnit XML file."""
    out: dict[str, tuple[str, str]] = {}
    if not junit.exists():
        return out
    for case in ET.parse(junit).getroot().iter("testcase"):
        name = f"{case.get('classname', '')}::{case.get('name', '')}"
        outcome, message = "passed", ""
        for tag in ("failure", "error"):
            node = case.find(tag)
            if node is not None:
                outcome = tag
                message = (node.get("message") or node.text or "").strip().splitlines()[0][:160] if (
                    node.get("message") or node.text) else ""
        if case.find("skipped") is not None:
            outcome = "skipped"
        out[name] = (outcome, message)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="passes over the DDS tests (default 20)")
    parser.add_argument("--burners", type=int, default=os.cpu_count() or 2,
                        help="busy processes while the tests run (default: one per core; 0 = quiet machine)")
    parser.add_argument("--files", nargs="*", default=None, help="test files (default: every file with dds tests)")
    parser.add_argument("-k", default=None, help="pytest -k expression, to hunt in fewer tests")
    parser.add_argument("--out", type=Path, default=None, help="keep each pass's JUnit XML and log here")
    parser.add_argument("--domains", default=None, metavar="LO-HI",
                        help="draw each pass's ROS_DOMAIN_ID from LO..HI (default: the conftest's 40..100); two hunts "
                             "at once (each the other's load) need disjoint ranges")
    parser.add_argument("--workers", type=int, default=0,
                        help="pytest-xdist workers per pass (-n N --dist loadfile, as the README's test command; "
                             "default 0: one process)")
    args = parser.parse_args(argv)
    domains = None
    if args.domains is not None:
        try:
            lo, hi = (int(v) for v in args.domains.split("-"))
            if not 0 <= lo <= hi <= 101:
                raise ValueError
        except ValueError:
            print(f"ERROR: --domains must be LO-HI within 0..101, got {args.domains!r}", file=sys.stderr)
            return 1
        domains = (lo, hi)
    if args.runs < 1 or args.burners < 0 or args.workers < 0:
        print("ERROR: --runs must be >= 1, --burners and --workers >= 0", file=sys.stderr)
        return 1
    if domains is not None and domains[1] - domains[0] + 1 < max(args.workers, 1):
        print(f"ERROR: --domains {args.domains} has fewer domains than --workers {args.workers}", file=sys.stderr)
        return 1
    out_dir = args.out or Path(tempfile.mkdtemp(prefix="flake_hunt_"))
    out_dir.mkdir(parents=True, exist_ok=True)
    files = args.files or ["test"]
    stop = mp.Event()
    burners = [mp.Process(target=_burn, args=(stop,), daemon=True) for _ in range(args.burners)]
    for b in burners:
        b.start()
    results: dict[str, list[tuple[str, str]]] = defaultdict(list)
    t0 = time.monotonic()
    try:
        for k in range(args.runs):
            junit = out_dir / f"pass{k:02d}.xml"
            cmd = [sys.executable, "-m", "pytest", "-q", "-m", "dds", "-p", "no:cacheprovider", f"--junitxml={junit}",
                   *files]
            if args.k:
                cmd += ["-k", args.k]
            if args.workers:
                cmd += ["-n", str(args.workers), "--dist", "loadfile"]
            env = {k_: v for k_, v in os.environ.items() if k_ != "RTA_TEST_DOMAIN_ID"}
            if domains is not None:
                # the workers take base .. base + workers - 1 (test/conftest.py): all inside LO..HI
                env["RTA_TEST_DOMAIN_ID"] = str(random.SystemRandom().randint(domains[0],
                                                                              domains[1] - max(args.workers, 1) + 1))
            start = time.monotonic()
            with (out_dir / f"pass{k:02d}.log").open("w") as log:
                code = subprocess.run(cmd, cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT).returncode
            outcomes = _outcomes(junit)
            for name, outcome in outcomes.items():
                results[name].append(outcome)
            failed = [n for n, (o, _) in outcomes.items() if o in ("failure", "error")]
            load = os.getloadavg()[0]
            print(f"pass {k + 1}/{args.runs}: {len(outcomes)} tests, {len(failed)} failed, exit {code}, "
                  f"{time.monotonic() - start:.0f} s, load {load:.1f}" + (f": {', '.join(failed)}" if failed else ""),
                  flush=True)
            if not outcomes:
                print(f"  no results (see {out_dir / f'pass{k:02d}.log'})", flush=True)
                results["<collection>"].append(("error", f"pytest exit {code}, no JUnit results"))
    finally:
        stop.set()
        for b in burners:
            b.join(timeout=5)
    total_fail = 0
    width = max([len(n) for n in results] + [4])
    print(f"\n{'test':<{width}}  fail  runs  first failure")
    for name in sorted(results):
        runs = results[name]
        fails = [m for o, m in runs if o in ("failure", "error")]
        total_fail += len(fails)
        if fails or len(results) <= 60:
            print(f"{name:<{width}}  {len(fails):>4}  {len(runs):>4}  {fails[0] if fails else ''}")
    print(f"\n{total_fail} failures in {args.runs} passes with {args.burners} burners, {args.workers} workers, "
          f"{time.monotonic() - t0:.0f} s; logs and JUnit XML in {out_dir}")
    return 1 if total_fail else 0


if __name__ == "__main__":
    sys.exit(main())
