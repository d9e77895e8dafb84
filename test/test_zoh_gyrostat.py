"""The coupled zero-order-hold rate rows of the gyrostat model (`constraints.angular_rate.zoh_rows`,
docs/gyrostat.md) against the plant integrated finely over the hold (RK4, 200 steps a second): their
prediction of omega at the check points is within the allowance they subtract, and a command that meets
them keeps |omega_i| inside (1 - zoh_margin) omega_max at every fine step after the first check point
and inside omega_max throughout."""

from __future__ import annotations

import numpy as np
import pytest

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.angular_rate import ZOH_TIMES
from rta_attitude.constraints.base import ZOH_CHECKS, ZOH_ROWS
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import OMEGA, PSI
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.montecarlo.sampling import sample_initial_states

CFG = config.load().with_backup("none")  # the ASIF's own answer (the gatekeeper: test_backup.py)
W_MAX = CFG.limits.omega_max_rad_s
LIMIT = (1 - CFG.filter.zoh_margin) * W_MAX
DT = CFG.filter.sample_time_s
FINE = 200
"""RK4 steps over one hold for the reference trajectory."""


def _states(n: int, seed: int) -> np.ndarray:
    """Monte Carlo initial states (inside the safe set, |omega_i| <= 0.95 omega_max, |psi| <= 547 rad/s)."""
    x, _ = sample_initial_states(n, seed, CFG)
    return x


def _fine(x: np.ndarray, u: np.ndarray, cfg=CFG) -> np.ndarray:
    """States after each of FINE RK4 steps over the hold (FINE, 19), the plant integrated independently of
    the rows (the actuator saturation is far beyond these u)."""
    return spacecraft.integrate(x, u, DT, spacecraft.plant_record(cfg), FINE)[1]


def test_rows_exist_only_for_the_gyrostat_in_the_robust_preset() -> None:
    x = _states(20, 3)
    assert np.all(ConstraintSet(CFG).evaluate(x).zoh_rows == ZOH_ROWS)
    assert np.all(ConstraintSet(CFG.with_preset("paper")).evaluate(x).zoh_rows == 0)
    assert np.all(ConstraintSet(CFG.with_models(filter="paper")).evaluate(x).zoh_rows == 0)


def test_prediction_error_is_within_the_allowance() -> None:
    """At each check point tau_m: omega_i(tau_m) from the fine integration lies within the rows' allowance of
    their affine prediction zoh_gain . u + free (free = -(lo + hi) / 2; allowance = LIMIT - (hi - lo) / 2),
    for random u in U; and the prediction is far better than the allowance (the exact linear part is right)."""
    rng = np.random.default_rng(18)
    x = _states(300, 11)
    tab = ConstraintSet(CFG).evaluate(x)
    ratios = []
    for k in range(len(x)):
        u = rng.uniform(-1, 1, 3) * CFG.u_max_rad_s2
        traj = _fine(x[k], u)
        for q in range(ZOH_ROWS):
            m, i = q // 3, tab.zoh_axis[k, q]
            assert i == q % 3
            step = round(ZOH_TIMES[m] * FINE) - 1
            free = -(tab.zoh_lo[k, q] + tab.zoh_hi[k, q]) / 2
            allowance = LIMIT - (tab.zoh_hi[k, q] - tab.zoh_lo[k, q]) / 2
            err = abs(traj[step, OMEGA][i] - (tab.zoh_gain[k, q] @ u + free))
            assert err <= allowance, (k, m, i, err, allowance)
            ratios.append(err / allowance)
    assert np.median(ratios) < 0.2


def _filtered_holds(cfg, n: int, seed: int):
    """(state, command) pairs where the filter of cfg solved its QP without a fallback, for random desired
    commands beyond U (the filter intervenes)."""
    rng = np.random.default_rng(seed)
    f = AsifFilter(cfg)
    x = _states(n, seed)
    out = []
    for k in range(n):
        r = f.filter(x[k], rng.uniform(-1.5, 1.5, 3) * cfg.u_max_rad_s2)
        if str(r.status) in ("solved", "pass"):
            out.append((x[k], np.asarray(r.u, dtype=float)))
    return out


def _worst_between_samples(cfg, holds) -> tuple[float, float]:
    """max |omega_i| / omega_max over every fine step of every hold, after the first check point and overall,
    the plant being the gyrostat."""
    late = overall = 0.0
    first = round(ZOH_TIMES[0] * FINE)
    for x, u in holds:
        w = np.abs(_fine(x, u, CFG)[:, OMEGA]) / W_MAX
        late = max(late, w[first - 1:].max())
        overall = max(overall, w.max())
    return late, overall


def test_commands_meeting_the_rows_keep_the_rate_between_samples() -> None:
    """Substep check: the filter's solved commands at 400 Monte Carlo states (desired commands up to 1.5 U)
    keep |omega_i| <= (1 - zoh_margin) omega_max at every fine step from the first check point on, and
    <= omega_max everywhere."""
    holds = _filtered_holds(CFG, 400, 5)
    assert len(holds) > 300
    late, overall = _worst_between_samples(CFG, holds)
    assert late <= 1 - CFG.filter.zoh_margin + 1e-12
    assert overall <= 1.0


def test_the_first_order_interval_is_not_enough_for_the_gyrostat() -> None:
    """The control: the paper model's first-order intervals (filter.model paper), on the same gyrostat plant
    and states, let the rate overshoot between samples (what the coupled rows are for)."""
    holds = _filtered_holds(CFG.with_models(filter="paper"), 400, 5)
    _, overall = _worst_between_samples(CFG, holds)
    assert overall > 1.0


@pytest.mark.parametrize("check", range(ZOH_CHECKS))
def test_prediction_at_zero_wheel_speed_is_the_first_order_one(check: int) -> None:
    """psi = 0 (no wheel term), omega = 0: the prediction is exactly omega + (f + G u) tau: zoh_gain = G tau
    (diagonal) and free = 0, by hand."""
    x = _states(1, 2)[0]
    x[OMEGA], x[PSI] = 0.0, 0.0
    tab = ConstraintSet(CFG).evaluate(x)
    tau = ZOH_TIMES[check] * DT
    rows = slice(3 * check, 3 * check + 3)
    np.testing.assert_allclose(tab.zoh_gain[rows], np.diag(CFG.spacecraft.control_gain * tau), rtol=1e-14, atol=0)
    np.testing.assert_allclose(-(tab.zoh_lo[rows] + tab.zoh_hi[rows]) / 2, 0.0, atol=1e-18)
