"""The oracle over many states: a Monte Carlo's runs.csv in, a verdict table and JSON / CSV out."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.state import STATE_NAMES
from rta_attitude.errors import ConfigError
from rta_attitude.files import atomic, output_dir, write_text
from rta_attitude.viability.params import N_X
from rta_attitude.viability.result import VERDICTS, Result
from rta_attitude.viability.search import find_witness

Array = NDArray[np.float64]
SELECTIONS: tuple[str, ...] = ("failed", "failed_incl_substeps", "all")
"""Which runs of a runs.csv to check: failed at samples (the Monte Carlo's criterion), failed including
the substeps, or every run."""


def read_runs(path: Path, select: str = "failed") -> list[tuple[str, Array]]:
    """(label "run <k>", initial state (13,)) of the selected runs of a Monte Carlo's runs.csv.

    Raises:
        ConfigError: unknown selection, missing file or columns, or a non-numeric entry.
    """
    if select not in SELECTIONS:
        raise ConfigError(f"selection must be one of {', '.join(SELECTIONS)}, got {select!r}")
    if not path.is_file():
        raise ConfigError(f"runs file {path} does not exist")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        need = ["run", *STATE_NAMES[:N_X], *([] if select == "all" else [select])]
        missing = [c for c in need if c not in (reader.fieldnames or [])]
        if missing:
            raise ConfigError(f"{path} is not a Monte Carlo runs.csv: no column(s) {', '.join(missing)}")
        out: list[tuple[str, Array]] = []
        for line, row in enumerate(reader, start=2):
            try:
                if select != "all" and int(row[select]) == 0:
                    continue
                out.append((f"run {int(row['run'])}", np.array([float(row[c]) for c in STATE_NAMES[:N_X]])))
            except (TypeError, ValueError):
                raise ConfigError(f"{path}:{line}: a run's state or flag is not a number") from None
    return out


def horizon_of_runs(path: Path) -> float | None:
    """The run length (s) from the summary.json beside a runs.csv, if there is one."""
    summary = path.with_name("summary.json")
    try:
        return float(json.loads(summary.read_text())["setup"]["duration_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def check_states(items: Sequence[tuple[str, Array]], horizon_s: float, cfg: Config, progress: bool = False,
                 **options: Any) -> list[tuple[str, Result]]:
    """`find_witness` of every (label, state), in order, with a tqdm bar when `progress`."""
    seq: Any = items
    if progress:
        from tqdm import tqdm

        seq = tqdm(items, total=len(items), unit="state", desc="viability")
    return [(label, find_witness(x0, horizon_s, cfg, **options)) for label, x0 in seq]


def counts(results: Sequence[tuple[str, Result]]) -> dict[str, Any]:
    """How many states got each verdict, and each rule."""
    rules: dict[str, int] = {}
    for _, r in results:
        if r.rule:
            rules[r.rule] = rules.get(r.rule, 0) + 1
    return {"states": len(results), **{v: sum(r.verdict == v for _, r in results) for v in VERDICTS},
            "by_rule": rules}


def write_report(out: Path, results: Sequence[tuple[str, Result]], setup: dict[str, Any],
                 with_trajectory: bool = True) -> dict[str, Path]:
    """viability.json (setup, counts, every result) and viability.csv (one line per state) in out."""
    output_dir(out)
    paths = {"json": out / "viability.json", "csv": out / "viability.csv"}
    doc = {"setup": setup, "counts": counts(results),
           "results": [{"state": label, **r.to_json(with_trajectory)} for label, r in results]}
    write_text(paths["json"], json.dumps(doc, indent=1, allow_nan=False) + "\n")
    groups = sorted({g for _, r in results for g in r.min_margins})
    with atomic(paths["csv"]) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["state", "verdict", "rule", "method", "ipopt_status", "iterations", "solve_time_s", "cpu_time_s",
                    *[f"min_h_{g}" for g in groups]])
        for label, r in results:
            w.writerow([label, r.verdict, r.rule or "", r.method, r.ipopt_status, r.iterations,
                        f"{r.solve_time_s:.3f}", f"{r.cpu_time_s:.3f}",
                        *[repr(r.min_margins[g]) if g in r.min_margins and math.isfinite(r.min_margins[g]) else ""
                          for g in groups]])
    return paths


__all__ = ["SELECTIONS", "check_states", "counts", "horizon_of_runs", "read_runs", "write_report"]
