"""The gate: the filter applies its answer only while a verified way out exists (recursive feasibility), after
Agrawal & Panagou 2023 ("gatekeeper") and the backup-CBF idea.

At each filter call with a backup law (`gate`): the candidate (the ASIF's answer) passes `verify` -> apply it,
commit its plan; else, if the backup law's own command passes -> apply it, commit; else, if a committed plan
remains -> apply its variant's command (the plan's next command: verified at an earlier sample); else the
candidate unverified. `verify` tries the committed plan's variant of the law first, then the others in
VARIANTS order. The plan is the only memory of the filter (`records.GATE_DTYPE`).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import MAX_ROWS
from rta_attitude.dynamics.sensors import (
    ENERGY_RELATIVE_ERROR,
    deliver,
)
from rta_attitude.dynamics.state import ENERGY, STATE_SIZE, TEMP, THETA_S
from rta_attitude.filter.gatekeeper.law import SUN_SAFE_VARIANT, VARIANTS, large_momentum, settled, sun_safe_command
from rta_attitude.filter.gatekeeper.records import NO_LAW
from rta_attitude.filter.gatekeeper.rollout import FAILED, HORIZON, SETTLED, energy_reserve, hold_sample, rollout
from rta_attitude.filter.outcome import GATE_BACKUP, GATE_OFF, GATE_TOWARD_BACKUP, GATE_UNVERIFIED, GATE_VERIFIED
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]
M = MAX_ROWS


@numba.njit(**LEAF)
def reset(g: np.void) -> None:
    """Forget the committed plan, the drive's state and the command in flight (a new run starts: the wheels'
    drive at rest): the filter's only memory."""
    g.plan_steps = 0
    for a in range(3):
        g.drive[a] = 0.0
        g.inflight[a] = 0.0
    g.plan_law = SUN_SAFE_VARIANT
    g.plan_n = g.plan_at = 0
    g.nominal_wait = 0
    g.filtered_wait = g.filtered_backoff = g.filtered_tries = 0
    g.has_next = g.plan_settled = g.plan_weak = g.in_terminal = 0
    g.reused = 0
    g.weak_law = -1


@numba.njit(**LEAF)
def commit(first_x: Array, law: int, settled_: bool, weak: bool, b: np.void, g: np.void) -> None:
    """Commit a verified plan of variant law whose state after its first sample is first_x: next_x is that
    state as the filter will receive it, the plan runs horizon_steps samples (`verify`, `commit_weak`; the
    nominal plan adds its own)."""
    predict(first_x, b, g, g.next_x)
    g.has_next = 1
    g.plan_settled = settled_
    g.in_terminal = 0
    g.plan_weak = weak
    g.plan_law = law
    g.plan_steps = b.horizon_steps


@numba.njit(**LEAF)
def variant_at(t: int, plan_law: int, large: bool) -> int:
    """The t-th variant (0 <= t < len(VARIANTS)) the gate tries: the committed plan's first, then the others in
    VARIANTS order; -1 for one it does not try (all but the sun-safe one only with a large momentum: the
    sun-safe attitude holds a small momentum, and the panel charges there)."""
    law = plan_law if t == 0 else (t - 1 if t - 1 < plan_law else t)
    return law if (law == SUN_SAFE_VARIANT or large) else -1


@numba.njit(**LEAF)
def verify(x: Array, u: Array, candidate: bool, f: np.void, g: np.void) -> bool:
    """Roll out from x with each variant of the backup law in turn, the committed plan's first, then the
    others in VARIANTS order (all but the sun-safe one only with a momentum |H| / D above psi_max - max
    J_a w_max / D: below it the sun-safe attitude holds H and the panel charges there, where the
    momentum mode may drain the battery into a dead end): the candidate u (candidate True) or the
    variant's own command at x (into u). With a small momentum the rollout must reach the terminal set
    (SETTLED: invariant, so the plan holds for good); with a large one, where the sun-safe attitude may not
    hold H, a horizon safe to its end with the battery's reserve at its end (`energy_reserve`) is accepted
    (HORIZON: the plan holds for the horizon only). On success the plan is committed (plan_law, plan_steps)
    and u holds the command to apply. The first variant safe to the horizon but short of the reserve is kept
    (weak_law, weak_u, weak_x: `commit_weak` commits it)."""
    b = f.backup
    p = f.plant
    large = large_momentum(x, p, b)
    g.weak_law = -1
    g.candidate = candidate
    for t in range(len(VARIANTS)):
        law = variant_at(t, g.plan_law, large)
        if law < 0:
            continue
        g.law = law
        if not candidate:
            g.t = g.t_call
            sun_safe_command(x, f.constraints, b, g, u)
        found = rollout(x, u, f, g, g.subs, False)
        if found == FAILED:  # how long it stayed safe (`gate`: where nothing verifies)
            if candidate:
                g.answer_lasted = max(g.answer_lasted, g.checked)
            elif g.checked > g.backup_lasted:
                g.backup_lasted = g.checked
                for a in range(3):
                    g.longest_u[a] = u[a]
        if found == SETTLED or (found == HORIZON and large):
            if found == HORIZON and not energy_reserve(g.x, p, f.constraints, b, g):
                if g.weak_law < 0:
                    g.weak_law = g.law
                    for i in range(STATE_SIZE):
                        g.weak_x[i] = g.first_x[i]
                    for a in range(3):
                        g.weak_u[a] = u[a]
                continue
            commit(g.first_x, g.law, found == SETTLED, False, b, g)
            return True
    return False


@numba.njit(**LEAF)
def commit_weak(g: np.void, b: np.void, u: Array) -> bool:
    """Commit the last `verify`'s plan that is safe to its horizon but short of the energy reserve, if it
    found one (its command into u); False if it found none."""
    if g.weak_law < 0:
        return False
    commit(g.weak_x, g.weak_law, False, True, b, g)
    for a in range(3):
        u[a] = g.weak_u[a]
    return True


@numba.njit(**LEAF)
def predict(x: Array, b: np.void, g: np.void, out: Array) -> None:
    """A predicted state x (19,) as the filter will receive it (`sensors.deliver`) into out: what a later
    call's state is compared with (`predicted`)."""
    deliver(x, b.interface, g.A, g.fields, out)


PREDICTION_RTOL = 1e-13
"""How far a received T, theta_S or CW entry may be from the plan's prediction (relative; theta_S: rad, modulo
2 pi) and still be on the plan: the interface's roundings (theta_S through atan2, a few ulps; the CW velocity
through A(q) and back) reach the prediction, which starts from a received state, and the true state's
reading, by different paths; measured differences are ulps (1e-16 relative), this is 1,000x that and far
below anything a barrier resolves. The attitude, rates and wheel speeds cross exactly and must match bit for
bit; E within two float32 ulps (`predicted`)."""


ANSWER_RTOL = 1e-12
"""How far (relative to the actuator limit) the filter's answer may be from the plan's answer for the same
sample and still be the plan's: the same ulp-level roundings reach the answer through the rows of the sun's
and the battery's constraints. The plan's own, verified answer is then applied (`pipeline.gate_call`)."""


@numba.njit(**LEAF)
def predicted(x: Array, pred: Array) -> bool:
    """The received state x (19,) is the plan's prediction pred (`predict`): the attitude, rates and wheel
    speeds bit for bit; the energy, which crosses the interface as a float32 (`sensors.encode`), the same
    float32 or the next one either side; T, theta_S (modulo 2 pi) and CW to PREDICTION_RTOL. A prediction
    starts from a received state, so it carries that reading's roundings (E: at most `interface_energy_error`
    where it matters, which the rollouts keep as the battery's margin; E's dynamics do not depend on E, so the
    offset stays what it was), and a reading on the other side of a rounding boundary is no departure from
    the plan."""
    for i in range(STATE_SIZE):
        d = x[i] - pred[i]
        if i == ENERGY:
            if not abs(d) <= 2.0 * ENERGY_RELATIVE_ERROR * abs(pred[i]):
                return False
        elif i == THETA_S:
            if not abs(d - 2.0 * math.pi * round(d / (2.0 * math.pi))) <= PREDICTION_RTOL:
                return False
        elif i >= TEMP:
            if not abs(d) <= PREDICTION_RTOL * (1.0 + abs(pred[i])):
                return False
        elif not (x[i] == pred[i] and math.copysign(1.0, x[i]) == math.copysign(1.0, pred[i])):
            return False
    return True


@numba.njit(**LEAF)
def same_answer(u: Array, v: Array, u_max: Array) -> bool:
    """u and v (3,) are the same answer to ANSWER_RTOL of the box u_max (3,) (NaN never)."""
    for a in range(3):
        if not abs(u[a] - v[a]) <= ANSWER_RTOL * u_max[a]:
            return False
    return True


@numba.njit(**LEAF)
def _follow_plan(x: Array, f: np.void, g: np.void, u: Array) -> None:
    """The committed plan's next command at x (its backup law) into u, and next_x := one sample of it from x
    (the state the plan predicts at the next call)."""
    g.law = g.plan_law
    g.t = g.t_call
    sun_safe_command(x, f.constraints, f.backup, g, g.u_backup)
    for i in range(STATE_SIZE):
        g.x[i] = x[i]
    g.checked = 0
    g.candidate = 0
    g.has_next = hold_sample(g.u_backup, f, g, g.subs, False)
    predict(g.x, f.backup, g, g.next_x)
    g.plan_steps -= 1
    for a in range(3):
        u[a] = g.u_backup[a]


@numba.njit(**LEAF)
def gate(x: Array, f: np.void, g: np.void, u: Array) -> int:
    """The gatekeeper at the state x (19,) with the candidate u (3,) (the ASIF's answer, replaced in place
    by the command to apply). Returns the GATE_NAMES code of what it did; g (GATE_DTYPE) carries the
    committed plan from call to call. Where the candidate fails at x, the committed plan reaches the
    terminal set and x is its predicted state (`predicted`, next_x: the filter's model is the plant's),
    the plan's next command (its backup law at x) is applied without a new rollout: its rollout verified
    it; next_x then becomes one sample of it from x. With a large momentum, plans safe to the horizon but
    short of the energy reserve (`energy_reserve`) come after those with it, in order: the backup law's
    (committed, `plan_weak`), the candidate's; at its predicted states a weak plan is followed without a
    rollout for nominal_steps samples (docs/backup.md, "The energy reserve"). Where nothing verifies and
    GATE_TOWARD_BACKUP is returned, u is left as it was: the caller answers g.longest_u (`_weak_candidate`)."""
    b = f.backup
    if b.law == NO_LAW:
        return GATE_OFF
    g.answer_lasted = g.backup_lasted = 0
    if (g.plan_weak and g.plan_steps > b.horizon_steps - b.nominal_steps and g.has_next
            and predicted(x, g.next_x)):
        # on a plan short of the energy reserve (the backup law, charging as well as the wheels allow): it
        # goes on, checked afresh every nominal_steps samples (a candidate is a sample off the same path)
        _follow_plan(x, f, g, u)
        return GATE_BACKUP
    if verify(x, u, True, f, g):
        return GATE_VERIFIED
    candidate_weak = g.weak_law >= 0  # safe to the horizon, short of the energy reserve
    if g.plan_steps > 0:  # the plan verified earlier: its next command is its backup law's, here
        on_plan = g.has_next and predicted(x, g.next_x)
        if on_plan and g.plan_settled:
            g.law = g.plan_law
            g.t = g.t_call
            inside = settled(x, b, g)
            if g.in_terminal and not inside:
                # the state left the terminal set it had reached: the law's target moved off it (its
                # cone-clear choice changed as the sun moved on), and the way to the new one was never
                # checked; a fresh plan checks it, else the plan is over
                g.plan_settled = 0
                on_plan = False
            g.in_terminal = inside
        if on_plan and g.plan_settled:
            # a settled plan holds for good on its own trajectory, while its next sample holds (a cone the law
            # meets ahead, which the terminal set's look-ahead did not reach: a fresh plan instead)
            g.reused += 1
            _follow_plan(x, f, g, g.plan_command)
            if g.has_next:
                for a in range(3):
                    u[a] = g.plan_command[a]
                return GATE_BACKUP
            g.reused -= 1
            g.plan_steps = 0
            on_plan = False
        # else a fresh plan from here (any variant), one short of the energy reserve if that is all there is (the
        # backup law charges best)
        if verify(x, g.u_backup, False, f, g) or commit_weak(g, b, g.u_backup):
            for a in range(3):
                u[a] = g.u_backup[a]
            return GATE_BACKUP
        if not on_plan:
            # off the plan (sensor errors, a model other than the plant's): its command is verified from a
            # state the spacecraft is not in; or out of its terminal set: the law's way on is not verified;
            # the candidate (its rows robust to the errors) instead
            g.plan_steps = 0
            g.has_next = 0
            return _weak_candidate(x, u, candidate_weak, f, g)
        _follow_plan(x, f, g, u)
        return GATE_BACKUP
    if verify(x, g.u_backup, False, f, g) or commit_weak(g, b, g.u_backup):
        for a in range(3):
            u[a] = g.u_backup[a]
        return GATE_BACKUP
    return _weak_candidate(x, u, candidate_weak, f, g)


@numba.njit(**LEAF)
def _weak_candidate(x: Array, u: Array, weak: bool, f: np.void, g: np.void) -> int:
    """The gate's last resort: the candidate u, committed as a plan safe to its horizon if it was one short of
    the energy reserve only (weak: verified again, now to commit it); else, where a variant's own command
    stayed safe longer in its rollout than the candidate in any of its (`verify` counted the substeps),
    GATE_TOWARD_BACKUP (the caller, `pipeline.filter_state`, answers that command, g.longest_u, instead of
    u_des); else the candidate, unverified."""
    if weak and (verify(x, u, True, f, g) or commit_weak(g, f.backup, u)):
        return GATE_VERIFIED
    if g.backup_lasted > g.answer_lasted:
        return GATE_TOWARD_BACKUP
    return GATE_UNVERIFIED
