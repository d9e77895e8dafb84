"""Monte Carlo of the ASIF filter at the paper's scale (SPEC sec. 5.2): many runs, u_des = 0.

    rta-attitude montecarlo --runs 5000 --duration 2000 --seed 1 [--preset robust|paper]
                            [--workers 2] [--backend local|dask --scheduler ADDRESS] --out DIR

Initial states: Latin hypercube (scipy.stats.qmc) over 12 dimensions: q uniform on the unit
quaternions through Shoemake's map (3), omega (3), psi (3), T, E, theta_S, in the ranges below;
a state where any enabled constraint has h, Psi_0 or Psi_1 < 0 (under either filter preset) is
re-drawn (a fresh hypercube for the rejected ones, from the same seeded stream) until none is, so
one seed gives the same initial states for `robust` and `paper`.

Runs advance in lockstep (`rta_attitude.batch.BatchSimulator`), in chunks spread over worker
processes (`local`) or over a Dask cluster (`dask`); a run's numbers do not depend on the chunk it
is in, so both backends and any chunking give identical results.

A run fails when a non-slacked constraint has h < 0 at a sample (the paper's criterion; also
reported including the RK4 substeps between samples). Slacked constraints (communication) are
reported apart. Each failure is classified as physically unrecoverable from its initial state
(`classify`, bounds that no admissible command can beat) or as a shortfall of the filter.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import logging
import math
import multiprocessing as mp
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import config as config_module
from .batch import SOLVERS, BatchOutcome, BatchSimulator
from .constraints import ConstraintSet
from .errors import ConfigError, RtaError
from .files import atomic, output_dir, write_text
from .metrics import H_UNITS
from .params import CONSTRAINT_NAMES, PRESETS, Config
from .state import ENERGY, OMEGA, PSI, STATE_NAMES, STATE_SIZE, TEMP, THETA_S, Q

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

# ----------------------------------------------------------------------------- SPEC sec. 5.2 ranges
# [resolved] in SPEC.md; proposed as a `montecarlo:` section of config/rta_attitude.yaml (see docs).
OMEGA_FRACTION = 0.95
"""omega_i uniform in +-OMEGA_FRACTION omega_max (5 % buffer)."""
PSI_FRACTION = 0.95
"""psi_i uniform in +-PSI_FRACTION psi_max (5 % buffer)."""
TEMPERATURE_RANGE_DEGC = (-10.0, 9.5)
"""T uniform in this range, degC (9.5 = T_max minus 5 %)."""
ENERGY_MIN_FACTOR = 1.05
"""E from ENERGY_MIN_FACTOR E_min ..."""
ENERGY_MAX_J = 10_000.0
"""... to this, J."""
THETA_S_RANGE_RAD = (0.0, 2.0 * math.pi)
"""theta_S uniform in [0, 2 pi)."""
SAMPLE_DIMENSIONS = 12
"""Hypercube dimensions: 3 (Shoemake) + 3 omega + 3 psi + T + E + theta_S."""
MAX_REDRAW_ROUNDS = 10_000
"""Re-draw rounds before giving up (each re-draws every still-rejected state)."""
CELSIUS_OFFSET_K = 273.15

PAPER_RESULTS: dict[str, Any] = {
    "success_rate": 0.9832,
    "violations_per_failed_run": {"1": 0.4167, "2": 0.3452, "3": 0.2143, "4+": 0.0238},
    "by_constraint": {"exclusion_zone": 0.5119, "psi_y": 0.4762, "psi_z": 0.4048, "battery": 0.3810,
                      "psi_x": 0.0476, "temperature": 0.0238, "omega_x": 0.0, "omega_y": 0.0, "omega_z": 0.0},
}
"""McQuinn et al. 2024, sec. Monte-Carlo Analysis: shares of the failed runs."""

BACKENDS: tuple[str, ...] = ("local", "dask")
DEFAULT_CHUNK_RUNS = 1250
"""Runs per chunk on the dask backend (the local backend gives each worker one chunk)."""
COUNTED: tuple[str, ...] = tuple(n for n in CONSTRAINT_NAMES)


# ----------------------------------------------------------------------------- sampling
def _to_states(u: Array, cfg: Config) -> Array:
    """Unit-cube samples (n, 12) -> states (n, 19)."""
    L = cfg.limits
    n = u.shape[0]
    x = np.zeros((n, STATE_SIZE))
    u1, u2, u3 = u[:, 0], u[:, 1], u[:, 2]
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    # Shoemake (1992): uniform on S^3; order (vector, scalar) is immaterial for uniformity
    x[:, Q] = np.stack([a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                        b * np.sin(2 * np.pi * u3), b * np.cos(2 * np.pi * u3)], axis=1)
    x[:, Q] /= np.linalg.norm(x[:, Q], axis=1, keepdims=True)
    x[:, OMEGA] = (2.0 * u[:, 3:6] - 1.0) * OMEGA_FRACTION * L.omega_max_rad_s
    x[:, PSI] = (2.0 * u[:, 6:9] - 1.0) * PSI_FRACTION * L.psi_max_rad_s
    t_lo, t_hi = TEMPERATURE_RANGE_DEGC
    x[:, TEMP] = CELSIUS_OFFSET_K + t_lo + (t_hi - t_lo) * u[:, 9]
    e_lo = ENERGY_MIN_FACTOR * L.energy_min_J
    x[:, ENERGY] = e_lo + (ENERGY_MAX_J - e_lo) * u[:, 10]
    th_lo, th_hi = THETA_S_RANGE_RAD
    x[:, THETA_S] = th_lo + (th_hi - th_lo) * u[:, 11]
    return x


def rejected(x: Array, cfg: Config) -> NDArray[np.bool_]:
    """(n,) True where an enabled constraint has h, Psi_0 or Psi_1 < 0 at x (n, 19) under any filter
    preset (the robust preset may keep a sampled-data margin in Psi_0): one test for all presets, so
    a seed gives the same initial states whichever preset runs them."""
    out = np.zeros(len(x), dtype=bool)
    for preset in PRESETS:
        cs = ConstraintSet.from_config(cfg.with_preset(preset))
        t = cs.evaluate(x)
        on = cs.enabled.astype(bool)
        out |= np.any(((t.h < 0) | (t.psi0 < 0) | (t.psi1 < 0)) & on, axis=1)
    return out


def sample_initial_states(runs: int, seed: int, cfg: Config) -> tuple[Array, NDArray[np.int64]]:
    """Latin-hypercube initial states inside the safe set (SPEC sec. 5.2).

    Args:
        runs: number of states.
        seed: seed of the one random stream (hypercube and re-draws).
        cfg: limits and barrier gains (the filter preset is not used).

    Returns:
        (states (runs, 19), re-draws per state (runs,)).

    Raises:
        RtaError: states still rejected after MAX_REDRAW_ROUNDS rounds.
    """
    from scipy.stats import qmc

    if runs < 1:
        raise ConfigError(f"runs must be >= 1, got {runs}")
    rng = np.random.default_rng(seed)
    x = _to_states(qmc.LatinHypercube(d=SAMPLE_DIMENSIONS, seed=rng).random(runs), cfg)
    redraws = np.zeros(runs, dtype=np.int64)
    bad = rejected(x, cfg)
    for _ in range(MAX_REDRAW_ROUNDS):
        k = int(bad.sum())
        if k == 0:
            return x, redraws
        idx = np.flatnonzero(bad)
        cube = qmc.LatinHypercube(d=SAMPLE_DIMENSIONS, seed=rng).random(k) if k > 1 else rng.random((1, 12))
        x[idx] = _to_states(cube, cfg)
        redraws[idx] += 1
        bad[idx] = rejected(x[idx], cfg)
    raise RtaError(f"{int(bad.sum())} initial states still outside the safe set after {MAX_REDRAW_ROUNDS} re-draws")


# ----------------------------------------------------------------------------- running chunks
@dataclass(frozen=True)
class ChunkTask:
    """One chunk of runs for a worker (picklable)."""

    cfg: Config
    solver: str
    x0: Array
    duration_s: float
    start: int


def run_chunk(task: ChunkTask, progress: Callable[[int], None] | None = None) -> tuple[int, BatchOutcome]:
    """Simulate one chunk; returns (start index, outcome)."""
    sim = BatchSimulator(task.cfg, task.solver)
    return task.start, sim.run(task.x0, task.duration_s, progress=progress)


_COUNTER: Any = None


def _init_worker(counter: Any) -> None:
    global _COUNTER
    _COUNTER = counter
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _run_chunk_counted(task: ChunkTask) -> tuple[int, BatchOutcome]:
    runs = task.x0.shape[0]
    last = [0]

    def tick(steps: int) -> None:
        if steps - last[0] >= 20 or steps == round(task.duration_s / task.cfg.filter.sample_time_s):
            with _COUNTER.get_lock():
                _COUNTER.value += (steps - last[0]) * runs
            last[0] = steps

    return run_chunk(task, tick)


def _merge(parts: list[tuple[int, BatchOutcome]]) -> BatchOutcome:
    parts = sorted(parts, key=lambda p: p[0])
    outs = [p[1] for p in parts]
    fields = ("violated_samples", "violated_substeps", "first_violation_s", "min_h_samples", "qp_steps",
              "fallback_steps", "qp_failures", "max_comm_slack", "x_final")
    return BatchOutcome(**{f: np.concatenate([getattr(o, f) for o in outs]) for f in fields})  # type: ignore[arg-type]


def _split(runs: int, chunks: int) -> list[tuple[int, int]]:
    edges = np.linspace(0, runs, chunks + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges) if b > a]


def run_local(cfg: Config, x0: Array, duration_s: float, workers: int, solver: str = "active-set",
              chunk_runs: int | None = None, progress: bool = False) -> BatchOutcome:
    """Run every state on this machine: chunks over `workers` processes (1: in this process)."""
    runs = x0.shape[0]
    n_chunks = max(1, math.ceil(runs / chunk_runs)) if chunk_runs else max(1, min(workers, runs))
    tasks = [ChunkTask(cfg, solver, x0[a:b], duration_s, a) for a, b in _split(runs, n_chunks)]
    steps = round(duration_s / cfg.filter.sample_time_s)
    total = runs * steps
    bar = _progress_bar(total, progress)
    if workers <= 1:

        def tick_for(n: int) -> Callable[[int], None]:
            last = [0]

            def tick(k: int) -> None:
                bar.update((k - last[0]) * n)
                last[0] = k
            return tick

        parts = [run_chunk(t, tick_for(t.x0.shape[0])) for t in tasks]
        bar.close()
        return _merge(parts)
    from .asif import compile_kernels

    compile_kernels(cfg)  # once here, not in every worker (forked workers inherit the compiled code)
    ctx = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    counter = ctx.Value("q", 0)
    with ctx.Pool(processes=min(workers, len(tasks)), initializer=_init_worker, initargs=(counter,)) as pool:
        pending = pool.map_async(_run_chunk_counted, tasks, chunksize=1)
        seen = 0
        while not pending.ready():
            pending.wait(0.5)
            v = counter.value
            bar.update(v - seen)
            seen = v
        parts = pending.get()
        bar.update(total - seen)
    bar.close()
    return _merge(parts)


def run_dask(cfg: Config, x0: Array, duration_s: float, scheduler: str | Any, solver: str = "active-set",
             chunk_runs: int = DEFAULT_CHUNK_RUNS, progress: bool = False) -> BatchOutcome:
    """Run every state on a Dask cluster: one task per chunk of `chunk_runs` runs.

    Args:
        scheduler: the scheduler's address ('tcp://host:8786') or a distributed.Client.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover - dask is in requirements.txt
        raise RtaError("the dask backend needs the 'distributed' package (pip install 'dask[distributed]')") from None
    runs = x0.shape[0]
    chunks = _split(runs, max(1, math.ceil(runs / chunk_runs)))
    tasks = [ChunkTask(cfg, solver, x0[a:b], duration_s, a) for a, b in chunks]
    own = not isinstance(scheduler, Client)
    client: Client = Client(scheduler) if own else scheduler  # type: ignore[assignment]
    try:
        futures = client.map(run_chunk, tasks, pure=False)
        steps = round(duration_s / cfg.filter.sample_time_s)
        bar = _progress_bar(runs * steps, progress)
        parts = []
        for fut in as_completed(futures):
            start, out = fut.result()
            parts.append((start, out))
            bar.update(out.x_final.shape[0] * steps)
        bar.close()
    finally:
        if own:
            client.close()
    return _merge(parts)


def _cpu_s() -> float:
    """User + system CPU seconds of this process and its reaped children."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(total: int, show: bool) -> Any:
    if not show:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, unit="state-step", unit_scale=True, desc="montecarlo", smoothing=0.1)


# ----------------------------------------------------------------------------- classification
UNRECOVERABLE_RULES: tuple[str, ...] = ("battery_energy", "temperature_heating", "exclusion_zone_escape",
                                        "wheel_momentum")


CLASSIFY_STEP_S = 0.05
"""Time step of the temperature lower-bound integration, s."""
CLASSIFY_MARGIN_K = 1e-3
"""The temperature bound must exceed T_max by this before a failure counts as unavoidable, K."""


def _angle(x0: Array, axis_body: Array, target: str, cfg: Config) -> Array:
    """Angle (n,) between a body axis and the sun ('sun') or Earth ('earth') direction at x0."""
    from . import model
    from . import quaternion as quat

    A = quat.attitude_matrix(x0[:, Q])
    d = model.sun_direction(x0[:, THETA_S]) if target == "sun" else model.EARTH_DIRECTION_HILL
    return np.arccos(np.clip(model.face_cosine(A, axis_body, d), -1.0, 1.0))


def unavoidable(x0: Array, cfg: Config, duration_s: float = math.inf) -> dict[str, NDArray[np.bool_]]:
    """Constraints that no admissible command sequence can keep from x0, by rule (n, m) each.

    Every rule bounds what the best possible trajectory could do, generously (it ignores the
    other constraints, the acceleration limits where stated, and the filter): if even that bound
    breaks a limit, the failure is physically unrecoverable. Any trajectory that keeps every
    constraint has |omega_i| <= omega_max, so a body axis turns relative to a direction at most at
    Omega = sqrt(3) omega_max (+ n for the moving sun).

    - battery_energy: the +k_B panel turns towards the sun at Omega from t = 0; E_dot <=
      P_peak max(0, cos theta_SI(t)) - P_out with theta_SI(t) >= theta_SI(0) - Omega t. E falls until
      cos theta_SI = P_out / P_peak; if the bound on E drops below E_min first, so does E.
    - temperature_heating: the -j_B face turns away from the sun and the Earth at Omega; the heat
      input is at least that of the bounding angles, so T >= the solution of
      T' = (Q_min(t) - sigma eps A T^4) / (m c_p) (comparison principle); a peak above T_max counts.
    - exclusion_zone_escape: theta_EZ(0) and its rate; |theta_ddot| <= a_max = sqrt(3) omega_dot_max
      + 2 Omega^2 / sin(limit) + n^2, so theta_EZ >= limit is lost if theta(0) - theta_dot(0)^2 /
      (2 a_max) < limit while approaching.
    - wheel_momentum: about body axis i, J_i omega_i - sign D psi_i changes only through the
      gyroscopic torque, so stopping the body about i moves the wheel to psi_i(0) - sign J_i omega_i(0)
      / D; where that lies beyond psi_max, and keeping omega_i inside its limit needs the rate
      stopped (|omega_i(0)| > omega_max: not in the sampled set), psi_i is lost.

    Args:
        x0: initial states (n, 19).
        cfg: configuration.
        duration_s: run length; a bound that needs longer is not used.

    Returns:
        rule name -> (n, m) bool, columns in CONSTRAINT_NAMES order.
    """
    from . import model

    n = len(x0)
    m = len(CONSTRAINT_NAMES)
    L, env, th, pw = cfg.limits, cfg.environment, cfg.thermal, cfg.power
    Omega = math.sqrt(3.0) * L.omega_max_rad_s
    n_orb = env.mean_motion_rad_s
    out = {r: np.zeros((n, m), dtype=bool) for r in UNRECOVERABLE_RULES}
    col = {name: i for i, name in enumerate(CONSTRAINT_NAMES)}

    # battery: energy lost before the panel can face the sun
    rate = Omega + n_orb
    theta0 = _angle(x0, model.PANEL_NORMAL_BODY, "sun", cfg)
    P, P_out = pw.peak_W, pw.load_W
    if P <= P_out:
        loss = np.full(n, P_out - P) * duration_s if math.isfinite(duration_s) else np.full(n, np.inf)
    else:
        th_star = math.acos(P_out / P)
        th_b = np.minimum(theta0, np.pi / 2)
        dark = np.maximum(theta0 - np.pi / 2, 0.0)
        lit = np.where(th_b > th_star, P_out * (th_b - th_star) - P * (np.sin(th_b) - math.sin(th_star)), 0.0)
        loss = (P_out * dark + lit) / rate
        t_star = np.maximum(theta0 - th_star, 0.0) / rate
        loss = np.where(t_star <= duration_s, loss, 0.0)
    out["battery_energy"][:, col["battery"]] = x0[:, ENERGY] - loss < L.energy_min_J

    # temperature: lower bound of T while the face turns away at the largest rate
    th_s0 = _angle(x0, model.THERMAL_FACE_NORMAL_BODY, "sun", cfg)
    th_e0 = _angle(x0, model.THERMAL_FACE_NORMAL_BODY, "earth", cfg)
    solar = th.absorptivity * th.area_m2 * env.solar_constant_W_m2
    earth_coeff = (solar * env.albedo_factor
                   + env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * env.earth_temperature_K**4)
    heat_capacity = th.mass_kg * th.specific_heat_J_kgK
    sea = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2
    T = x0[:, TEMP].copy()
    T_peak = T.copy()
    horizon = min(math.pi / min(rate, Omega), duration_s)
    for k in range(math.ceil(horizon / CLASSIFY_STEP_S)):
        t = k * CLASSIFY_STEP_S
        q_min = (solar * np.maximum(0.0, np.cos(np.minimum(th_s0 + rate * t, np.pi)))
                 + earth_coeff * env.earth_view_factor * np.maximum(0.0, np.cos(np.minimum(th_e0 + Omega * t, np.pi))))
        T = T + CLASSIFY_STEP_S * (q_min - sea * T**4) / heat_capacity
        np.maximum(T_peak, T, out=T_peak)
    out["temperature_heating"][:, col["temperature"]] = T_peak > L.temperature_max_K + CLASSIFY_MARGIN_K

    # exclusion zone: stopping distance of the approach
    from .constraints import ConstraintSet

    table = ConstraintSet.from_config(cfg).evaluate(x0)
    h_ez = table.h[:, col["exclusion_zone"]]
    k1_ez = cfg.barriers["exclusion_zone"].k1
    theta_dot = table.psi1[:, col["exclusion_zone"]] - k1_ez * table.psi0[:, col["exclusion_zone"]]
    a_max = (math.sqrt(3.0) * L.omega_dot_max_rad_s2 + 2.0 * rate**2 / math.sin(L.exclusion_angle_rad)
             + n_orb**2)
    reach = h_ez - np.where(theta_dot < 0, theta_dot**2 / (2.0 * a_max), 0.0)
    out["exclusion_zone_escape"][:, col["exclusion_zone"]] = reach < 0

    # wheels: momentum exchanged in stopping the body about each axis
    J = cfg.spacecraft.J
    D = cfg.spacecraft.wheel_inertia_kgm2
    sign = cfg.spacecraft.torque_sign
    w0 = x0[:, OMEGA]
    psi_stop = x0[:, PSI] - sign * J * w0 / D
    must_stop = np.abs(w0) > L.omega_max_rad_s
    for a, name in enumerate(("psi_x", "psi_y", "psi_z")):
        out["wheel_momentum"][:, col[name]] = must_stop[:, a] & (np.abs(psi_stop[:, a]) > L.psi_max_rad_s)
    return out


def classify(x0: Array, violated: NDArray[np.bool_], cfg: Config,
             duration_s: float = math.inf) -> tuple[NDArray[np.bool_], list[str]]:
    """Which failures no admissible command could have avoided (see docs/montecarlo.md).

    Args:
        x0: initial states (n, 19).
        violated: (n, m) constraints violated in each run (CONSTRAINT_NAMES order).
        cfg: configuration.

    Returns:
        (unrecoverable (n,) bool, the rules that proved it per run ('' if none, ';'-joined)).
    """
    proofs = unavoidable(x0, cfg, duration_s)  # name -> (n, m) bool
    rules: list[str] = []
    out = np.zeros(len(x0), dtype=bool)
    for k in range(len(x0)):
        hit = [name for name, mask in proofs.items() if np.any(mask[k] & violated[k])]
        rules.append(";".join(hit))
        out[k] = bool(hit)
    return out, rules


# ----------------------------------------------------------------------------- results
@dataclass
class MonteCarloResult:
    """Everything a Monte Carlo produced (arrays over runs)."""

    cfg: Config
    seed: int
    duration_s: float
    x0: Array
    redraws: NDArray[np.int64]
    outcome: BatchOutcome
    slacked: tuple[str, ...]
    wall_s: float
    backend: str
    workers: int
    solver: str
    cpu_s: float = math.nan
    """CPU time of this process and its finished worker processes during the runs (local backend), s."""
    unrecoverable: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    rules: list[str] = field(default_factory=list)

    @property
    def counted(self) -> NDArray[np.bool_]:
        """(m,) constraints that decide success (enabled, not slacked)."""
        cs = ConstraintSet.from_config(self.cfg)
        return cs.enabled & (cs.slack_weights == 0)

    def failed(self, substeps: bool = False) -> NDArray[np.bool_]:
        v = self.outcome.violated_substeps if substeps else self.outcome.violated_samples
        return np.any(v & self.counted, axis=1)


def _shares(result: MonteCarloResult, substeps: bool) -> dict[str, Any]:
    v = (result.outcome.violated_substeps if substeps else result.outcome.violated_samples) & result.counted
    failed = np.asarray(v.any(axis=1), dtype=bool)
    nf = int(failed.sum())
    n = len(failed)
    per_run = v[failed].sum(axis=1)
    counts = {"1": int(np.sum(per_run == 1)), "2": int(np.sum(per_run == 2)), "3": int(np.sum(per_run == 3)),
              "4+": int(np.sum(per_run >= 4))}
    by = {name: int(v[failed, i].sum()) for i, name in enumerate(CONSTRAINT_NAMES) if result.counted[i]}
    return {
        "runs": n, "failed": nf, "success_rate": (n - nf) / n if n else math.nan,
        "violations_per_failed_run": {k: (c / nf if nf else 0.0) for k, c in counts.items()},
        "violations_per_failed_run_counts": counts,
        "by_constraint": {k: (c / nf if nf else 0.0) for k, c in by.items()},
        "by_constraint_counts": by,
    }


def summary(result: MonteCarloResult) -> dict[str, Any]:
    """The JSON-ready summary: paper-style tables at samples and incl. substeps, counts, timing."""
    o = result.outcome
    failed = result.failed()
    cs = ConstraintSet.from_config(result.cfg)
    slacked = {}
    for i, name in enumerate(CONSTRAINT_NAMES):
        if name in result.slacked:
            slacked[name] = {"violated_runs_samples": int(o.violated_samples[:, i].sum()),
                             "violated_runs_incl_substeps": int(o.violated_substeps[:, i].sum()),
                             "max_slack_rad": float(o.max_comm_slack.max()) if len(o.max_comm_slack) else 0.0}
    unrec = result.unrecoverable & failed
    short = failed & ~result.unrecoverable
    steps = round(result.duration_s / result.cfg.filter.sample_time_s)
    return {
        "paper": PAPER_RESULTS,
        "at_samples": _shares(result, False),
        "incl_substeps": _shares(result, True),
        "slacked_constraints": slacked,
        "classification": {
            "failed": int(failed.sum()),
            "physically_unrecoverable": int(unrec.sum()),
            "filter_shortfall": int(short.sum()),
            "shortfall_with_qp_failure": int((short & (o.fallback_steps > 0)).sum()),
            "shortfall_without_qp_failure": int((short & (o.fallback_steps == 0)).sum()),
            "worst_violation_without_qp_failure": {
                name: float(o.min_h_samples[short & (o.fallback_steps == 0), i].min())
                for i, name in enumerate(CONSTRAINT_NAMES)
                if result.counted[i] and np.any(o.violated_samples[short & (o.fallback_steps == 0), i])},
            "worst_violation_units": {name: H_UNITS[name] for name in CONSTRAINT_NAMES},
            "by_rule": {r: int(sum(1 for k in np.flatnonzero(failed) if r in result.rules[k].split(";")))
                        for r in UNRECOVERABLE_RULES},
        },
        "filter": {
            "qp_state_steps": int(o.qp_steps.sum()),
            "qp_share": float(o.qp_steps.sum() / (len(failed) * steps)) if len(failed) else 0.0,
            "fallback_state_steps": int(o.fallback_steps.sum()),
            "runs_with_fallback": int((o.fallback_steps > 0).sum()),
            "qp_failures": int(o.qp_failures.sum()),
            "runs_with_qp_failure": int((o.qp_failures > 0).sum()),
            "fallback_policy": result.cfg.filter.fallback,
            "solver": result.solver,
        },
        "setup": {
            "runs": len(failed), "duration_s": result.duration_s, "seed": result.seed,
            "preset": result.cfg.filter.preset, "dt_s": result.cfg.filter.sample_time_s,
            "substeps": result.cfg.substeps, "config": result.cfg.source, "backend": result.backend,
            "workers": result.workers, "wall_s": result.wall_s,
            "cpu_s": None if math.isnan(result.cpu_s) else result.cpu_s,
            "redraws_total": int(result.redraws.sum()),
            "constraints_counted": [n for i, n in enumerate(cs.names) if result.counted[i]],
            "slacked": list(result.slacked),
        },
    }


def format_table(s: dict[str, Any]) -> str:
    """The paper's table beside ours (shares of failed runs), for a terminal."""
    a, b, p = s["at_samples"], s["incl_substeps"], s["paper"]
    setup = s["setup"]
    cpu = f", {setup['cpu_s']:.0f} s CPU" if setup.get("cpu_s") is not None else ""
    lines = [f"Monte Carlo: {setup['runs']} runs x {setup['duration_s']:.0f} s, preset {setup['preset']}, "
             f"seed {setup['seed']}, {setup['wall_s']:.1f} s wall{cpu} "
             f"({setup['backend']}, {setup['workers']} workers)",
             f"{'':<28}{'paper':>10}{'at samples':>14}{'incl. substeps':>16}",
             f"{'success rate':<28}{p['success_rate']:>10.2%}{a['success_rate']:>14.2%}{b['success_rate']:>16.2%}",
             f"{'failed runs':<28}{'84':>10}{a['failed']:>14d}{b['failed']:>16d}",
             "of the failed runs, violating"]
    for k in ("1", "2", "3", "4+"):
        lines.append(f"  {k + ' constraint(s)':<26}{p['violations_per_failed_run'][k]:>10.2%}"
                     f"{a['violations_per_failed_run'][k]:>14.2%}{b['violations_per_failed_run'][k]:>16.2%}")
    lines.append("of the failed runs, violating")
    for name in CONSTRAINT_NAMES:
        if name not in a["by_constraint"]:
            continue
        pv = p["by_constraint"].get(name)
        ps = f"{pv:>10.2%}" if pv is not None else f"{'-':>10}"
        lines.append(f"  {name:<26}{ps}{a['by_constraint'][name]:>14.2%}{b['by_constraint'][name]:>16.2%}")
    for name, c in s["slacked_constraints"].items():
        lines.append(f"{name + ' (slacked)':<28}{'-':>10}{c['violated_runs_samples']:>14d}"
                     f"{c['violated_runs_incl_substeps']:>16d}  runs, max slack {c['max_slack_rad']:.3g} rad")
    c, f = s["classification"], s["filter"]
    lines.append(f"failed runs (at samples): {c['failed']} = {c['physically_unrecoverable']} physically unrecoverable "
                 f"+ {c['filter_shortfall']} filter shortfall  (rules: "
                 + ", ".join(f"{k} {v}" for k, v in c["by_rule"].items()) + ")")
    worst = ", ".join(f"{k} {v:.3g} {c['worst_violation_units'][k]}"
                      for k, v in c["worst_violation_without_qp_failure"].items())
    lines.append(f"  shortfalls: {c['shortfall_with_qp_failure']} with an infeasible QP (fallback), "
                 f"{c['shortfall_without_qp_failure']} with every QP feasible (sampled data; worst h: {worst or '-'})")
    lines.append(f"filter: QP in {f['qp_share']:.1%} of state-steps, {f['qp_failures']} QP failures in "
                 f"{f['runs_with_qp_failure']} runs, {f['fallback_state_steps']} fallback steps "
                 f"({f['fallback_policy']}) in {f['runs_with_fallback']} runs; solver {f['solver']}")
    return "\n".join(lines)


def write_outputs(result: MonteCarloResult, out: Path, plot: bool = True) -> dict[str, Path]:
    """summary.json, runs.csv and (optionally) initial_conditions.png in out. Returns the paths."""
    output_dir(out)
    s = summary(result)
    paths = {"json": out / "summary.json", "csv": out / "runs.csv", "npz": out / "outcome.npz"}
    write_text(paths["json"], json.dumps(s, indent=2) + "\n")
    o = result.outcome
    with atomic(paths["npz"]) as tmp:
        np.savez_compressed(tmp, x0=result.x0, redraws=result.redraws, unrecoverable=result.unrecoverable,
                            constraint_names=np.array(CONSTRAINT_NAMES), state_names=np.array(STATE_NAMES),
                            **{k: getattr(o, k) for k in ("violated_samples", "violated_substeps",
                                                          "first_violation_s", "min_h_samples", "qp_steps",
                                                          "fallback_steps", "qp_failures", "max_comm_slack",
                                                          "x_final")})
    failed = result.failed()
    failed_sub = result.failed(substeps=True)
    with atomic(paths["csv"]) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", *STATE_NAMES[:13], "redraws", "failed", "failed_incl_substeps", "unrecoverable",
                    "unrecoverable_rules", "violated", "violated_incl_substeps", "first_violation_s", "qp_steps",
                    "fallback_steps", "qp_failures", "max_comm_slack_rad",
                    *[f"min_h_{n}" for n in CONSTRAINT_NAMES]])
        for k in range(len(failed)):
            vs = [n for i, n in enumerate(CONSTRAINT_NAMES) if o.violated_samples[k, i]]
            vb = [n for i, n in enumerate(CONSTRAINT_NAMES) if o.violated_substeps[k, i]]
            fv = o.first_violation_s[k][result.counted]
            first = float(np.nanmin(fv)) if np.any(~np.isnan(fv)) else ""
            rules = result.rules[k] if failed[k] else ""
            w.writerow([k, *[repr(float(v)) for v in result.x0[k, :13]], int(result.redraws[k]), int(failed[k]),
                        int(failed_sub[k]), int(result.unrecoverable[k] and failed[k]), rules,
                        ";".join(vs), ";".join(vb), first, int(o.qp_steps[k]), int(o.fallback_steps[k]),
                        int(o.qp_failures[k]), repr(float(o.max_comm_slack[k])),
                        *[repr(float(v)) for v in o.min_h_samples[k]]])
    if plot:
        from .mc_plots import plot_initial_conditions

        paths["png"] = plot_initial_conditions(result.x0, failed, result.cfg, out / "initial_conditions.png",
                                               title=f"{len(failed)} runs, preset {result.cfg.filter.preset}")
    return paths


def montecarlo(cfg: Config, runs: int, duration_s: float, seed: int, workers: int = 1, backend: str = "local",
               scheduler: str | Any | None = None, solver: str = "active-set", chunk_runs: int | None = None,
               progress: bool = False) -> MonteCarloResult:
    """Sample, run and classify (the library entry point of the CLI).

    Raises:
        ConfigError: bad arguments.
    """
    if backend not in BACKENDS:
        raise ConfigError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if solver not in SOLVERS:
        raise ConfigError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise ConfigError(f"duration must be > 0 s, got {duration_s!r}")
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if backend == "dask" and not scheduler:
        raise ConfigError("the dask backend needs --scheduler ADDRESS (e.g. tcp://127.0.0.1:8786)")
    x0, redraws = sample_initial_states(runs, seed, cfg)
    t0 = time.perf_counter()
    cpu0 = _cpu_s()
    if backend == "local":
        outcome = run_local(cfg, x0, duration_s, workers, solver, chunk_runs, progress)
    else:
        outcome = run_dask(cfg, x0, duration_s, scheduler, solver, chunk_runs or DEFAULT_CHUNK_RUNS, progress)
    wall = time.perf_counter() - t0
    cpu = _cpu_s() - cpu0
    cs = ConstraintSet.from_config(cfg)
    slacked = tuple(n for i, n in enumerate(cs.names) if cs.enabled[i] and cs.slack_weights[i] > 0)
    result = MonteCarloResult(cfg, seed, duration_s, x0, redraws, outcome, slacked, wall, backend, workers, solver,
                              cpu_s=cpu if backend == "local" else math.nan)
    result.unrecoverable, result.rules = classify(x0, outcome.violated_samples & result.counted, cfg, duration_s)
    return result


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser, command: str = "montecarlo") -> None:
    """Options of `rta-attitude montecarlo`."""
    parser.add_argument("--runs", type=int, default=5000, help="number of runs (default 5000)")
    parser.add_argument("--duration", type=float, default=2000.0, help="run length, s (default 2000)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the initial states (default 1)")
    parser.add_argument("--preset", choices=PRESETS, default=None, help="filter preset (default: the config's)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="local worker processes (default: the machine's cores)")
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="local processes or a Dask cluster")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address for --backend dask")
    parser.add_argument("--chunk-runs", type=int, default=None,
                        help=f"runs per chunk (default: one chunk per local worker; {DEFAULT_CHUNK_RUNS} on dask)")
    parser.add_argument("--solver", choices=SOLVERS, default="active-set",
                        help="QP solver: the vectorised exact active-set method (default) or proxsuite per state "
                             "(bit-identical with `simulate`, several times slower)")
    parser.add_argument("--out", type=Path, default=Path("out/montecarlo"), help="output directory")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG figure")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    if not any(a.dest == "config" for a in parser._actions):
        parser.add_argument("--config", type=Path, default=None, help="parameter YAML (default: the package's)")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude montecarlo`: returns the exit status (errors raise RtaError for the CLI to print)."""
    if args.runs < 1:
        raise ConfigError(f"--runs must be >= 1, got {args.runs}")
    if args.chunk_runs is not None and args.chunk_runs < 1:
        raise ConfigError(f"--chunk-runs must be >= 1, got {args.chunk_runs}")
    cfg = config_module.load(args.config, preset=args.preset)
    output_dir(args.out)  # before hours of work, not after
    result = montecarlo(cfg, args.runs, args.duration, args.seed, args.workers, args.backend, args.scheduler,
                        args.solver, args.chunk_runs, progress=not args.no_progress and sys.stderr.isatty())
    paths = write_outputs(result, args.out, plot=not args.no_plot)
    print(format_table(summary(result)))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m rta_attitude.montecarlo ...` until the CLI wires the subcommand."""
    parser = argparse.ArgumentParser(prog="rta-attitude montecarlo", description=__doc__.split("\n")[0])
    add_arguments(parser)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(args)
    except RtaError as exc:
        print(f"ERROR: {exc}", file=sys.stderr)
        return 1


__all__ = [
    "BACKENDS", "PAPER_RESULTS", "MonteCarloResult", "add_arguments", "classify", "format_table", "montecarlo",
    "rejected", "run", "run_dask", "run_local", "sample_initial_states", "summary", "write_outputs",
]  # fmt: skip

if __name__ == "__main__":
    sys.exit(main())
