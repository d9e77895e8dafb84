"""The filter never emits an invalid command: property-based (hypothesis) over random and extreme
states and commands, and bounded work on infeasible and near-infeasible QPs."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_states
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rta_attitude import config
from rta_attitude.filter import active_set
from rta_attitude.filter.asif import AsifFilter

CFG = config.load()
FILTERS = {name: AsifFilter(CFG.with_fallback(name)) for name in ("soften", "pass_through", "hold", "prioritize")}
EXTREME = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.floats(-1e6, 1e6),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e300, np.pi, 576.0, -576.0, 0.0174533]),
)


def _check(f, x, u_des):
    res = f.filter(x, u_des)
    assert res.u.shape == (3,)
    assert np.all(np.isfinite(res.u)), (x, u_des, res.u)
    assert np.all(np.abs(res.u) <= CFG.u_max_rad_s2 * (1 + 1e-12)), res.u
    assert res.status in ("pass", "solved", "fallback")
    return res


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(x=arrays(np.float64, 19, elements=EXTREME), u=arrays(np.float64, 3, elements=EXTREME),
       policy=st.sampled_from(sorted(FILTERS)))
def test_any_input_gives_a_finite_command_inside_U(x, u, policy):
    _check(FILTERS[policy], x, u)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), scale=st.floats(0.0, 3.0), policy=st.sampled_from(sorted(FILTERS)))
def test_physical_states_near_and_past_the_limits(seed, scale, policy):
    rng = np.random.default_rng(seed)
    x = random_states(rng, 1, CFG)[0]
    x[4:7] *= scale  # rates from zero to 4.5 w_max
    x[7:10] *= min(scale, 1.2)
    u = rng.normal(0, 100, 3)
    f = FILTERS[policy]
    res = _check(f, x, u)
    table = f.constraints.evaluate(x[None])
    lo, hi = table.lo, table.hi
    if res.gate in ("backup", "toward_backup", "filtered_backup"):
        return  # the gatekeeper's command (inside U, checked above) or the answer to it, not the answer to u_des
    assert np.all(res.u >= lo[0] - 1e-12) and np.all(res.u <= hi[0] + 1e-12)
    if res.status == "pass":
        np.testing.assert_array_equal(res.u, np.clip(u, lo[0], hi[0]))


def test_invalid_states_are_counted_fallbacks():
    f = AsifFilter(CFG)
    x = CFG.scenario("paper-example").x0.copy()
    for bad in (np.nan, np.inf):
        y = x.copy()
        y[5] = bad
        res = f.filter(y, np.ones(3))
        assert res.fallback == "invalid_state" and np.array_equal(res.u, np.zeros(3))
    y = x.copy()
    y[0:4] = 0.0
    assert f.filter(y, np.ones(3)).fallback == "invalid_state"
    assert f.counters.invalid_states == 3
    # a slightly non-unit quaternion is normalised, not rejected
    y = x.copy()
    y[0:4] *= 1.001
    assert f.filter(y, np.ones(3)).fallback == ""


@pytest.mark.parametrize("solver", ["active_set", "proxsuite"])
def test_solver_work_is_bounded_on_infeasible_and_near_infeasible_problems(solver):
    """Caps: the active-set method stops after MAX_ACTIVE_SET_ITER iterations in each of its
    POLISH_ROUNDS; proxsuite at max_iterations x max_inner_iterations, then the exact backup solver
    terminates finitely; then the fallback answers. Every call ends with a status."""
    f = AsifFilter(CFG.with_solver(solver))
    rng = np.random.default_rng(8)
    x = random_states(rng, 300, CFG)
    x[:, 4:7] *= 2.0  # many states far past the rate limit: infeasible or nearly so
    u = rng.uniform(-1, 1, (300, 3)) * 181.3
    b = f.filter_batch(x, u)
    if solver == "proxsuite":
        cap, tag = CFG.filter.max_iterations * CFG.filter.max_inner_iterations, "proxsuite"
    else:
        cap, tag = active_set.MAX_ACTIVE_SET_ITER * active_set.POLISH_ROUNDS, "active_set"
    solves = b.record["solves"]  # (prioritize: a QP per priority level and a last one)
    assert np.all(b.iterations <= cap * np.maximum(solves, 1)), b.iterations.max()
    assert (b.status_code == 2).sum() > 10 and (b.status_code == 1).sum() > 10  # both kinds are present
    assert all(s.startswith(tag) for s in b.solver_status[b.status_code > 0])
    assert np.all(np.isfinite(b.u))
    assert f.counters.fallbacks == int((b.status_code == 2).sum())
