"""The gatekeeper's plans over the filter's own answers (they need the QP: `filter.qp.answer`), and its call.

- `plan_nominal`: the filter's next answers for nominal_steps samples, then the backup law, verified once and
  reused while the plant follows it bit for bit;
- `plan_filtered`: where nothing else verifies, the backup law through the filter's answers;
- `gate_call`: the gatekeeper of one filter call (a plan's sample, a new nominal plan, `gate.gate`, the
  filtered search with its back-off).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import MAX_NOMINAL_STEPS
from rta_attitude.constraints.base import (
    MAX_ROWS,
)
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter.gatekeeper.gate import commit, gate, predict, predicted, same_answer, variant_at, verify
from rta_attitude.filter.gatekeeper.law import SUN_SAFE_VARIANT, VARIANTS, large_momentum, settled, sun_safe_command
from rta_attitude.filter.gatekeeper.records import NO_LAW
from rta_attitude.filter.gatekeeper.rollout import FAILED, HORIZON, SETTLED, backup_tail, energy_reserve, hold_sample
from rta_attitude.filter.outcome import (
    GATE_BACKUP,
    GATE_FILTERED_BACKUP,
    GATE_OFF,
    GATE_TOWARD_BACKUP,
    GATE_UNVERIFIED,
    GATE_VERIFIED,
)
from rta_attitude.filter.qp import answer
from rta_attitude.jit import JIT

Array = NDArray[np.float64]
M = MAX_ROWS


@numba.njit(**JIT)
def plan_nominal(x: Array, u: Array, u_des: Array, N: int, f: np.void, wsa: NDArray[np.void]) -> bool:
    """The gatekeeper's nominal plan from the state x (19,): u (3,) held for a sample, then for N - 1
    samples the filter's own answer (`answer`, u_des held) at each predicted state, then the backup law
    (the committed plan's variant, the momentum mode only with a large momentum) until it settles (small
    momentum) or to the horizon (large), every sample checked at every substep (`backup.hold_sample`).
    On success the plan is committed: its states and answers at the samples go to the gate's plan_x,
    plan_u (later calls at those states with those answers are applied without a rollout: `gate_call`),
    its state after them to next_x. Returns False (nothing committed) at the first violation or invalid
    state."""
    b = f.backup
    g, inner = wsa[0].gate, wsa[1]
    large = large_momentum(x, f.plant, b)
    g.law = g.plan_law if (g.plan_law == SUN_SAFE_VARIANT or large) else SUN_SAFE_VARIANT
    for i in range(STATE_SIZE):
        g.x[i] = x[i]
    g.checked = 0
    g.t = g.t_call
    g.candidate = 1  # the filter's own answers: a candidate's margins
    for j in range(N):
        if j == 0:
            for i in range(STATE_SIZE):
                g.plan_x[0, i] = g.x[i]
            for a in range(3):
                g.plan_u[0, a] = u[a]
        else:  # the filter's answer to the predicted state as it will receive it
            predict(g.x, b, g, g.plan_x[j])
            if not answer(g.plan_x[j], u_des, g.t, f, inner, inner.result):
                return False
            for a in range(3):
                g.plan_u[j, a] = inner.result.u[a]
        if not hold_sample(g.plan_u[j], f, g, g.subs, False):
            return False
    for i in range(STATE_SIZE):
        g.first_x[i] = g.x[i]
    found = backup_tail(f, g, g.subs, False)
    if not (found == SETTLED or (found == HORIZON and large and energy_reserve(g.x, f.plant, f.constraints, b, g))):
        return False
    commit(g.first_x, g.law, found == SETTLED, False, b, g)
    g.plan_steps = b.horizon_steps + N - 1  # the nominal samples, then the backup law's horizon
    g.plan_n = N
    g.plan_at = 1
    return True


@numba.njit(**JIT)
def _filtered_rollout(x: Array, law: int, n: int, f: np.void, wsa: NDArray[np.void], xr: Array, ul: Array
                      ) -> tuple[int, int]:
    """One rollout of `plan_filtered` for the variant law from x: (FAILED, HORIZON or SETTLED; how many
    samples went to plan_x, plan_u: its first n samples' states as received and commands); g.x its last
    state."""
    b = f.backup
    g, inner = wsa[0].gate, wsa[1]
    g.law = law
    g.candidate = 0
    g.checked = 0
    g.t = g.t_call
    for i in range(STATE_SIZE):
        g.x[i] = x[i]
    for j in range(b.horizon_steps + 1):
        if j > 0 and settled(g.x, b, g):
            return SETTLED, min(j, n)
        if j == 0:
            for i in range(STATE_SIZE):
                xr[i] = x[i]
        else:
            predict(g.x, b, g, xr)
        sun_safe_command(xr, f.constraints, b, g, ul)
        if not answer(xr, ul, g.t, f, inner, inner.result):
            return FAILED, min(j, n)
        if j < n:
            for i in range(STATE_SIZE):
                g.plan_x[j, i] = xr[i]
            for a in range(3):
                g.plan_u[j, a] = inner.result.u[a]
        if not hold_sample(inner.result.u, f, g, g.subs, False):
            return FAILED, min(j + 1, n)
    return HORIZON, min(b.horizon_steps + 1, n)


@numba.njit(**JIT)
def plan_filtered(x: Array, f: np.void, wsa: NDArray[np.void], u: Array) -> bool:
    """The backup law filtered by the ASIF: for each variant in `verify`'s order, a rollout from the state x
    (19,) as received whose every sample holds the filter's answer (`answer`) to the law's command, both at
    the state as the filter will receive it (`predict`), checked at every substep (`hold_sample`), to the
    terminal set or (large momentum) to the horizon with the energy reserve; failing that, the first variant
    safe to the horizon without the reserve (as `backup.commit_weak` for the law's own plans). The law knows
    nothing of the keep-out cone and the other rows; the ASIF's rows steer its slew round them. On success
    the first nominal_steps samples are committed as a plan (plan_x, plan_u: later calls at those states
    apply its commands, `gate_call`) and u := its first command."""
    b = f.backup
    p = f.plant
    g = wsa[0].gate
    large = large_momentum(x, p, b)
    n = min(max(b.nominal_steps, 1), MAX_NOMINAL_STEPS)
    xr = np.empty(STATE_SIZE)
    ul = np.empty(3)
    weak = -1
    chosen = -1
    recorded = 0
    for t in range(len(VARIANTS)):
        law = variant_at(t, g.plan_law, large)
        if law < 0:
            continue
        found, recorded = _filtered_rollout(x, law, n, f, wsa, xr, ul)
        if found == SETTLED:
            chosen = law
            break
        if found == HORIZON and large:
            if energy_reserve(g.x, p, f.constraints, b, g):
                chosen = law
                break
            if weak < 0:
                weak = law
    if chosen < 0 and weak >= 0:
        chosen = weak
        _, recorded = _filtered_rollout(x, weak, n, f, wsa, xr, ul)  # its plan again (a later one overwrote it)
    if chosen < 0:
        return False
    for a in range(3):
        u[a] = g.plan_u[0, a]
    g.plan_n = recorded  # (a plan that settles within n samples holds fewer)
    g.plan_at = 1
    g.plan_steps = 0
    g.has_next = 0
    g.plan_law = chosen
    return True


FILTERED_BACKOFF_MAX = 16
"""Where nothing verifies call after call, the backup law through the filter (`plan_filtered`: up to 5 x 300
QPs a call) is tried at the first such call, then after waits of 1, 2, 4, 8, then 16 calls between tries
(reset when `backup.gate` finds a way out, the candidate, the law's own command or the committed plan's, or a
filtered plan is found; calls answered from a nominal plan, or by a new one, return before and leave it)."""


UNIT_TOLERANCE = 1e-12
"""The gatekeeper's rollouts start from the state as received where its quaternion's norm is within this of
1 (the plant's always is: it renormalises at every substep), so that they predict the plant bit for bit;
from the normalised state otherwise."""


@numba.njit(**JIT)
def gate_call(x: Array, u_des: Array, t_s: float, f: np.void, wsa: NDArray[np.void], r: np.void) -> int:
    """The gatekeeper at the state x (19,) as received at time t_s with the filter's answer r.u (replaced in
    place by the command to apply); returns its GATE_NAMES code. Its rollouts start at t_s (g.t_call): a cone's
    windows apply at the times they reach. In order:

    - on a committed nominal plan (x and r.u are the state and answer it predicted for this sample:
      `backup.predicted`, `backup.same_answer`, bit for bit but for the interface's roundings) -> apply the
      plan's answer, verified by that plan's rollout;
    - a new nominal plan (`plan_nominal`, nominal_steps samples; after one fails, or after a call that was
      not the one its plan predicted (sensor noise, another u_des), not tried again for nominal_steps
      calls: halving the plan after a failure saved 10 % of the CPU and lost one more of 1,000 runs);
    - on the plan's state but with another answer (u_des changed) -> that answer alone (`backup.verify`),
      else the plan's own answer for this sample, and the plan goes on;
    - otherwise `backup.gate` (the answer held a sample then the backup law); where that finds nothing
      verified (`unverified`, `toward_backup`), the backup law through the filter (`plan_filtered`) ->
      its first command (`filtered_backup`); tried at the first such call, then after growing waits while
      nothing verifies (FILTERED_BACKOFF_MAX)."""
    b = f.backup
    if b.law == NO_LAW:
        return GATE_OFF
    ws = wsa[0]
    g = ws.gate
    g.t_call = t_s
    n2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]
    raw = abs(n2 - 1.0) <= UNIT_TOLERANCE  # where the rollouts start (UNIT_TOLERANCE)
    xs = g.x0  # (a copy: numba cannot pick between the two arrays, x read-only and ws.x)
    for i in range(STATE_SIZE):
        xs[i] = x[i] if raw else ws.x[i]
    at = g.plan_at
    on_plan = at < g.plan_n and predicted(x, g.plan_x[at])
    if on_plan:
        if same_answer(r.u, g.plan_u[at], f.constraints.u_max_rad_s2):  # the plan's, verified, answer
            for a in range(3):
                r.u[a] = g.plan_u[at, a]
            g.plan_at += 1
            g.plan_steps -= 1
            g.reused += 1
            return GATE_VERIFIED
        # u_des is not the one the plan held: no new nominal plan for a while; the answer alone, else the
        # plan's own answer (its rows are intact: no nominal plan was tried)
        g.nominal_wait = max(g.nominal_wait, b.nominal_steps)
        if verify(xs, r.u, True, f, g):
            g.plan_n = g.plan_at = 0
            return GATE_VERIFIED
        for a in range(3):
            r.u[a] = g.plan_u[at, a]
        g.plan_at += 1
        g.plan_steps -= 1
        return GATE_BACKUP
    if at < g.plan_n:  # off the plan's state (noise, another model): no new nominal plan for a while
        g.nominal_wait = max(g.nominal_wait, b.nominal_steps)
    g.plan_n = g.plan_at = 0
    if b.nominal_steps > 1:
        if g.nominal_wait > 0:
            g.nominal_wait -= 1
        elif plan_nominal(xs, r.u, u_des, b.nominal_steps, f, wsa):
            return GATE_VERIFIED
        else:
            g.nominal_wait = b.nominal_steps
    code = gate(xs, f, g, r.u)
    if not (code == GATE_UNVERIFIED or code == GATE_TOWARD_BACKUP):
        g.filtered_wait = g.filtered_backoff = 0  # gate found a way out: the next search starts afresh
        return code
    if g.filtered_wait > 0:  # the last tries found nothing (FILTERED_BACKOFF_MAX)
        g.filtered_wait -= 1
        return code
    g.filtered_tries += 1
    if plan_filtered(xs, f, wsa, r.u):
        g.filtered_backoff = 0
        return GATE_FILTERED_BACKUP
    g.filtered_wait = g.filtered_backoff
    g.filtered_backoff = min(max(2 * g.filtered_backoff, 1), FILTERED_BACKOFF_MAX)
    return code
