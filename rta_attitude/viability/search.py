"""`find_witness`: rules, warm-start laws, one multiple-shooting solve, receding segments.

Order: (1) the proof rules (`rules.check_rules`) -> "unrecoverable" with the rule named; (2) every
warm-start law (`laws.LAWS`) simulated exactly over the horizon: the first one safe at every substep
is the witness; (3) horizons up to `direct_max_s`: one multiple-shooting NLP over the whole horizon,
seeded with the best law; (4) longer horizons, or a failed direct solve: receding segments. Every
candidate is re-simulated exactly (`model.simulate`) and checked at every substep before
"recoverable" is returned, so the verdict never rests on IPOPT's tolerances or status.

Receding segments: from the committed state, (a) if a law is safe to the end of the horizon, append
it and stop; (b) else solve a `window_s` NLP with the parking terminal cost, re-simulate its first
`commit_s` exactly and commit them if safe; repeat. Sound (only checked pieces are committed and the
whole sequence is re-simulated from x0 at the end) but incomplete (a greedy segment can end where no
window continues: then "no witness found").

The constraints are the configuration's groups (`params`); every state has a time, `start_s` (x0's) plus
dt i / substeps, by which a pointing constraint with time windows applies or not, in the laws' checks, the
NLP's rows and the final check alike.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.viability.laws import LAWS, simulate_law
from rta_attitude.viability.model import constraint_values, is_safe, min_margins, simulate, worst_normalised
from rta_attitude.viability.params import OracleModel, as_oracle_state, check_enforce, default_enforce, from_config
from rta_attitude.viability.result import NO_WITNESS, RECOVERABLE, UNRECOVERABLE, Result
from rta_attitude.viability.rules import check_rules
from rta_attitude.viability.transcription import solve_window

Array = NDArray[np.float64]
Candidate = tuple[str, Array, Array, dict[str, float]]


def find_witness(x0: Array | Sequence[float], horizon_s: float, cfg: Config, *,
                 enforce: Sequence[str] | None = None, margin: float = 1e-4, max_iter: int = 500,
                 time_limit_s: float = 900.0, use_warm_start: bool = True, direct_max_s: float = 300.0,
                 window_s: float = 150.0, commit_s: float = 75.0, apply_rules: bool = True,
                 compile: bool = True, start_s: float = 0.0) -> Result:
    """Search for a command sequence that keeps x0 safe over `horizon_s` (module docstring).

    Args:
        x0: the project's state (19,) or its first 13 entries (q, omega, psi, T, E, theta_S).
        horizon_s: horizon, s (whole holds of cfg.filter.sample_time_s).
        cfg: configuration: plant model (`spacecraft.model`), limits, U, thermal and power constants, the
            pointing constraints (`constraints.pointing`).
        enforce: constraint groups (`Config.groups`) a witness must keep (default: the hard ones, enabled and
            not slacked).
        margin: the optimiser keeps h >= margin * scale (the final exact check asks h >= 0).
        max_iter: IPOPT iteration cap per NLP.
        time_limit_s: wall-clock budget (IPOPT's max_wall_time gets what is left).
        use_warm_start: accept a safe law's trajectory as the witness (False: only as IPOPT's guess).
        direct_max_s: longest horizon solved as one NLP.
        window_s, commit_s: receding-segment lengths, s.
        apply_rules: run the proof rules first (False only to test the rules against the search).
        compile: compile the derivative blocks to C (cached; minutes on first use), else casadi's VM.
        start_s: the time of x0, s from the run's t = 0: a pointing constraint with time windows applies at the
            samples and substeps start_s + k dt inside them only.

    Returns:
        A Result; `verdict` is "recoverable" only after the exact re-simulation passed.

    Raises:
        ValueError: a malformed state or horizon. ConfigError: an unknown constraint name.
    """
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    m = from_config(cfg)
    groups = default_enforce(cfg) if enforce is None else check_enforce(enforce, cfg)
    x = as_oracle_state(x0)
    n_steps = round(horizon_s / m.dt_s)
    if not n_steps >= 1:
        raise ValueError(f"the horizon must be at least one hold ({m.dt_s} s), got {horizon_s!r}")
    start = float(start_s)
    if not math.isfinite(start):
        raise ValueError(f"start_s must be a finite time in s, got {start_s!r}")
    search = _Search(x, n_steps, m, groups, margin, max_iter, time_limit_s, t0, compile, start)
    if apply_rules:
        rule = check_rules(x, n_steps * m.dt_s, m, groups, start)
        if rule is not None:
            m0 = {g: float(v[0]) for g, v in constraint_values(x, m, start).items()}
            res = search.result(UNRECOVERABLE, None, None, m0, "not run", "rule", rule[1], rule=rule[0])
            return _finish(res, cpu0)
    res = search.run(use_warm_start, round(direct_max_s / m.dt_s), round(window_s / m.dt_s),
                     round(commit_s / m.dt_s))
    return _finish(res, cpu0)


def _finish(res: Result, cpu0: float) -> Result:
    res.cpu_time_s = time.process_time() - cpu0
    return res


class _Search:
    """One call's state: the model, the enforced set, the clock."""

    def __init__(self, x0: Array, n_steps: int, m: OracleModel, enforce: tuple[str, ...], margin: float,
                 max_iter: int, time_limit_s: float, t0: float, compiled: bool, start_s: float) -> None:
        self.x0, self.n, self.m, self.enforce = x0, n_steps, m, enforce
        self.margin, self.max_iter, self.time_limit_s, self.t0 = margin, max_iter, time_limit_s, t0
        self.compiled, self.start_s = compiled, start_s
        self.iterations = 0
        self.statuses: list[str] = []
        self.segments: list[dict[str, Any]] = []

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def result(self, verdict: str, u: Array | None, x: Array | None, margins: dict[str, float], status: str,
               method: str, detail: str, rule: str | None = None) -> Result:
        return Result(verdict, rule, u, x, margins, self.elapsed(), status, method, detail, self.iterations,
                      self.segments, horizon_s=self.n * self.m.dt_s, model=self.m.name, enforce=self.enforce,
                      scales={g: self.m.scale(g) for g in self.m.groups},
                      units={g: self.m.unit(g) for g in self.m.groups}, start_s=self.start_s)

    def time_of(self, step: int) -> float:
        """The time of sample `step` (s)."""
        return self.start_s + step * self.m.dt_s

    def laws(self, x: Array, steps: int, stop_early: bool, t_s: float) -> tuple[str | None, list[Candidate]]:
        """Simulate every law from x at time t_s for `steps`; (the first law safe at every substep or None,
        candidates best first by worst normalised margin). stop_early: stop a law at its first violation."""
        cands: list[Candidate] = []
        for law in LAWS:
            us, xs, subs = simulate_law(x, steps, self.m, law, self.enforce if stop_early else None, t_s)
            mm = min_margins(x, subs, self.m, t_s)
            if len(us) == steps and is_safe(mm, self.enforce):
                return law, [(law, us, xs, mm)]
            cands.append((law, us, xs, mm))
        cands.sort(key=lambda c: -worst_normalised(c[3], self.enforce, self.m))
        return None, cands

    def solve(self, x: Array, steps: int, cand: Candidate, terminal: bool, t_s: float) -> Array:
        law, u_g, x_g, _ = cand
        if len(u_g) < steps:  # a law stopped at its first violation: complete the guess
            u_g, x_g, _ = simulate_law(x, steps, self.m, law, None, t_s)
        u, status, iters = solve_window(x, steps, self.m, self.enforce, self.margin, u_g, x_g, self.max_iter,
                                        self.time_limit_s - self.elapsed(), terminal, self.compiled, t_s)
        self.iterations += iters
        self.statuses.append(status)
        return u

    def checked(self, u: Array, method: str, detail: str) -> Result | None:
        """The Result of u if its exact re-simulation from x0 is safe at every substep, else None."""
        xs, subs = simulate(self.x0, u, self.m)
        mm = min_margins(self.x0, subs, self.m, self.start_s)
        if not is_safe(mm, self.enforce):
            return None
        return self.result(RECOVERABLE, u, xs, mm, "; ".join(self.statuses) or "not needed", method, detail)

    def run(self, use_warm_start: bool, direct_max: int, window: int, commit: int) -> Result:
        safe_law, cands = self.laws(self.x0, self.n, use_warm_start, self.start_s)
        if safe_law is not None and use_warm_start:
            _, us, xs, mm = cands[0]
            return self.result(RECOVERABLE, us, xs, mm, "not needed", "warm_start",
                               f"warm-start law '{safe_law}' is safe at every substep")
        best = cands[0][3]
        if self.n <= direct_max:
            u = self.solve(self.x0, self.n, cands[0], False, self.start_s)
            res = self.checked(u, "direct", f"multiple shooting from the '{cands[0][0]}' guess; exact "
                                            "re-simulation safe")
            if res is not None:
                return res
            _, subs = simulate(self.x0, u, self.m)
            mm = min_margins(self.x0, subs, self.m, self.start_s)
            if worst_normalised(mm, self.enforce, self.m) > worst_normalised(best, self.enforce, self.m):
                best = mm
            if self.n <= window or self.elapsed() >= self.time_limit_s:
                return self.result(NO_WITNESS, None, None, best, "; ".join(self.statuses), "direct",
                                   "IPOPT's answer is not safe under the exact re-simulation")
        return self.segmented(window, commit)

    def segmented(self, window: int, commit: int) -> Result:
        m = self.m
        u_done = np.zeros((0, 3))
        x_cur = self.x0.copy()
        while True:
            done = len(u_done)
            rest = self.n - done
            if done > 0:
                law, cands = self.laws(x_cur, rest, True, self.time_of(done))
                if law is not None:
                    res = self.checked(np.vstack([u_done, cands[0][1]]), "segmented",
                                       f"{done * m.dt_s:.0f} s optimised in {len(self.segments)} segments, "
                                       f"then warm-start law '{law}' for {rest * m.dt_s:.0f} s")
                    if res is not None:
                        return res
            if self.elapsed() > self.time_limit_s:
                break
            w = min(window, rest)
            _, cands = self.laws(x_cur, w, False, self.time_of(done))
            u = self.solve(x_cur, w, cands[0], w < rest, self.time_of(done))
            c = w if w == rest else commit
            xs, subs = simulate(x_cur, u[:c], m)
            ok = is_safe(min_margins(x_cur, subs, m, self.time_of(done)), self.enforce)
            self.segments.append({"start_s": done * m.dt_s, "steps": w, "commit": c, "status": self.statuses[-1],
                                  "safe": ok, "guess": cands[0][0], "t_wall_s": round(self.elapsed(), 2)})
            if not ok:
                break
            u_done = np.vstack([u_done, u[:c]])
            x_cur = xs[-1]
            if len(u_done) == self.n:
                res = self.checked(u_done, "segmented", f"{len(self.segments)} optimised segments")
                if res is not None:
                    return res
                break
        _, subs = simulate(self.x0, u_done, m)
        return self.result(NO_WITNESS, None, None, min_margins(self.x0, subs, m, self.start_s),
                           "; ".join(self.statuses),
                           "segmented", f"stopped after {len(u_done) * m.dt_s:.0f} safe s of {self.n * m.dt_s:.0f} "
                           "(a segment failed or the time limit)")


__all__ = ["find_witness"]
