"""What every benchmark records beside its numbers: the machine, its load, the code's revision; and
where the results go (bench/results/<name>.json, a list that each run appends to)."""

from __future__ import annotations

import json
import os
import platform
import random
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results"


def isolate_ros() -> None:
    """The ROS environment of a DDS benchmark and its children, where not set already: a ROS_DOMAIN_ID of its
    own (random, 40-100), localhost-only discovery, and this environment's prefix as AMENT_PREFIX_PATH."""
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(40, 100)))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)


def describe() -> dict[str, Any]:
    """Cores, load average (1, 5, 15 min), git revision, versions, date."""
    import numba
    import numpy as np

    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                             check=False).stdout.strip()
        dirty = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                                    capture_output=True, text=True, check=False).stdout.strip())
    except OSError:
        rev, dirty = "", False
    return {
        "cores": os.cpu_count(), "load_average": [round(v, 2) for v in os.getloadavg()],
        "git": rev + ("+changes" if dirty else ""), "python": platform.python_version(),
        "numpy": np.__version__, "numba": numba.__version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }  # fmt: skip


def append(name: str, record: dict[str, Any], out: Path = RESULTS) -> Path:
    """Append one record to out/<name>.json; returns the path."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.json"
    old = json.loads(path.read_text()) if path.is_file() else []
    path.write_text(json.dumps([*old, record], indent=2) + "\n")
    return path


def median_ratio(slow: list[float], fast: list[float]) -> float:
    """median(slow) / median(fast)."""
    import numpy as np

    return float(np.median(slow) / np.median(fast))


__all__ = ["REPO", "RESULTS", "append", "describe", "median_ratio"]
