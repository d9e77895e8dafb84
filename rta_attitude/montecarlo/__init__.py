"""The paper's Monte Carlo (SPEC sec. 5.2): sampled initial states, many runs of the closed loop,
classified failures, a report beside the paper's table.

    rta-attitude montecarlo --runs 5000 --duration 2000 --seed 1 [--preset robust|paper]
                            [--workers 2] [--backend local|dask --scheduler ADDRESS] --out DIR

- `sampling`: Latin-hypercube initial states inside the safe set;
- `runner`: a compiled loop over runs of the one-state closed-loop step, on local processes or Dask;
- `classify`: rules that prove a failure physically unavoidable;
- `report`: the table, the classification, summary.json / runs.csv / outcome.npz and the figure.

A run fails when a non-slacked constraint has h < 0 at a sample (the paper's criterion; also
reported including the RK4 substeps between samples). Slacked constraints are
reported apart.
"""

from __future__ import annotations

BACKENDS: tuple[str, ...] = ("local", "dask")
"""Where the runs go: worker processes on this machine, or a Dask cluster."""
DEFAULT_CHUNK_RUNS = 1250
"""Runs per chunk on the dask backend (the local backend gives each worker one chunk)."""

__all__ = ["BACKENDS", "DEFAULT_CHUNK_RUNS"]
