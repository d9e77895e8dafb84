"""The gatekeeper (`filter.gatekeeper`): the backup law against independent computations, the gate's rule
(never an unverified candidate while a plan exists), recursive feasibility on Monte Carlo runs, and
the default (no backup law) unchanged."""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
import pytest
from helpers import best_panel_cos

from rta_attitude import config
from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.sensors import Instruments, interface_energy_error
from rta_attitude.dynamics.spacecraft import integrate, torque_to_wheel_accel, wheel_accel_to_torque
from rta_attitude.errors import ConfigError
from rta_attitude.filter.gatekeeper.gate import gate, reset, verify
from rta_attitude.filter.gatekeeper.gate import predicted as backup_predicted
from rta_attitude.filter.gatekeeper.law import (
    CORRIDOR_HALF_WIDTH_RAD,
    RATE_LIMIT_FRACTION,
    SETTLED_RATE_FRACTION,
    TILT_WHEEL_MARGIN,
    VARIANTS,
    sun_safe_error,
)
from rta_attitude.filter.gatekeeper.records import GATE_DTYPE
from rta_attitude.filter.gatekeeper.rollout import (
    backup_command,
    backup_rollout,
    check_margins,
    energy_reserve,
    is_settled,
)
from rta_attitude.filter.outcome import (
    GATE_BACKUP,
    GATE_NAMES,
    GATE_OFF,
    GATE_TOWARD_BACKUP,
    GATE_UNVERIFIED,
    GATE_VERIFIED,
)
from rta_attitude.filter.records import filter_record
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.viability.laws import law_command
from rta_attitude.viability.params import from_config

NAMES = config.load().constraint_names
"""The default configuration's constraints, in row order."""

Array = np.ndarray


def with_backup(cfg: Config, law: str = "sun_safe", horizon_s: float | None = None) -> Config:
    return cfg.with_backup(law, horizon_s)


@pytest.fixture(scope="module")
def cfg() -> Config:
    return with_backup(config.load())


@pytest.fixture(scope="module")
def states(cfg: Config) -> Array:
    x0, _ = sample_initial_states(20, 1, cfg)
    return x0


def momentum_rad_s(x: Array, cfg: Config) -> Array:
    """|J w - s D psi| / D of states (..., 19)."""
    sc = cfg.spacecraft
    H = sc.J * x[..., 4:7] - sc.torque_sign * sc.wheel_inertia_kgm2 * x[..., 7:10]
    return np.linalg.norm(H, axis=-1) / sc.wheel_inertia_kgm2


@numba.njit
def _gate(x: Array, u: Array, fa: np.ndarray, ga: np.ndarray) -> int:
    return gate(x, fa[0], ga[0], u)


@numba.njit
def _reset(ga: np.ndarray) -> None:
    reset(ga[0])


def test_config_choice_and_default() -> None:
    """The gatekeeper is on by default; the paper's scenarios run the paper's method (no gatekeeper), and
    `none` turns it off."""
    cfg = config.load()
    assert cfg.filter.backup_law == "sun_safe"
    assert filter_record(cfg)[0]["backup"]["law"] == 1
    assert filter_record(cfg.with_backup("none"))[0]["backup"]["law"] == 0
    for name in ("paper_example", "passed_example", "slack_on_exclusion_zone"):
        assert cfg.for_scenario(cfg.scenario(name)).filter.backup_law == "none"
    assert cfg.for_scenario(cfg.scenario("battery_vs_temperature")).filter.backup_law == "sun_safe"
    with pytest.raises(ConfigError, match=r"filter\.backup_law"):
        with_backup(cfg, "sideways")
    with pytest.raises(ConfigError, match=r"filter\.backup_horizon_s"):
        with_backup(cfg, "sun_safe", 0.0)


def test_backup_law_equals_the_viability_oracles_sun_safe_ff(cfg: Config) -> None:
    """Where the wheels can hold the momentum at the sun-safe attitude (no momentum roll), the compiled
    law is the oracle's `sun_safe_ff` (numpy: Shepperd, cross products, w x H feed-forward)."""
    f = filter_record(cfg)
    m = from_config(cfg)
    rng = np.random.default_rng(3)
    x0, _ = sample_initial_states(40, 7, cfg)
    x0[:, 7:10] *= 0.3  # wheel speeds within 0.3 psi_max
    assert np.all(momentum_rad_s(x0, cfg) < 0.6 * cfg.limits.psi_max_rad_s)
    for x in x0:
        x[12] = rng.uniform(0.0, 2 * np.pi)
        np.testing.assert_allclose(backup_command(x, f), law_command(
            x[:13], "sun_safe_ff", m, rate_limit_fraction=RATE_LIMIT_FRACTION), rtol=1e-9, atol=1e-9)


def test_the_earth_side_variant_is_the_oracles_sun_safe_ff_at_any_momentum(cfg: Config) -> None:
    """The EARTH_SIDE variant aims at the Earth-side sun-safe attitude whatever the momentum, as the oracle's
    `sun_safe_ff` does (numpy, written apart): with large momenta (|H| / D > 552 rad/s, where the sun-safe
    variant rolls or tilts its target) the two commands agree to 1e-9, and the sun-safe variant's differs."""
    f = filter_record(cfg)
    m = from_config(cfg)
    x0, _ = sample_initial_states(200, 7, cfg)
    large = x0[momentum_rad_s(x0, cfg) > f[0]["backup"]["momentum_variant_rad_s"]][:30]
    assert len(large) == 30
    differs = 0
    for x in large:
        u = backup_command(x, f, "earth_side")
        np.testing.assert_allclose(u, law_command(x[:13], "sun_safe_ff", m, rate_limit_fraction=RATE_LIMIT_FRACTION),
                                   rtol=1e-9, atol=1e-9)
        differs += not np.allclose(u, backup_command(x, f, "sun_safe"), rtol=1e-6, atol=1e-6)
    assert differs >= 15


@numba.njit
def _verify(x: Array, u: Array, fa: np.ndarray, ga: np.ndarray) -> bool:
    return verify(x, u, False, fa[0], ga[0])


def test_verify_commits_the_first_variant_whose_rollout_passes(cfg: Config) -> None:
    """`verify` of the backup law (no candidate) from large-momentum states of seed 1 commits the first of
    the variants, in VARIANTS order, whose own rollout (each variant's `backup_rollout` of its command,
    checked here one by one) settles, or is safe to the horizon with the energy reserve at its end; and
    commits none where none does. States are picked so that each outcome and a later variant appear."""
    f = filter_record(cfg)
    x0, _ = sample_initial_states(400, 1, cfg)
    large = x0[momentum_rad_s(x0, cfg) > f[0]["backup"]["momentum_variant_rad_s"]]
    picked: dict[int, int] = {}
    for x in large:
        want = -1
        for k, variant in enumerate(VARIANTS):
            found, traj = backup_rollout(x, backup_command(x, f, variant), f, variant)
            if found == "settled" or (found == "horizon" and _reserve(traj[-1], f, np.zeros(1, GATE_DTYPE))):
                want = k
                break
        if picked.get(want, 0) >= 2:
            continue
        g = np.zeros(1, GATE_DTYPE)
        _reset(g)
        u = np.zeros(3)
        ok = _verify(x, u, f, g)
        assert ok == (want >= 0)
        if ok:
            assert int(g[0]["plan_law"]) == want
            np.testing.assert_array_equal(u, backup_command(x, f, VARIANTS[want]))
        picked[want] = picked.get(want, 0) + 1
        if sum(picked.values()) >= 8 and any(k > 1 for k in picked) and 0 in picked:
            break
    assert any(k > 1 for k in picked), picked  # a variant after the sun-safe and momentum ones was committed
    assert 0 in picked


def test_rollout_equals_the_plants_python_integrate(cfg: Config, states: Array) -> None:
    """The kernel's rollout (candidate hold, then the backup law) equals the plant's Python `integrate`
    driven sample by sample with `backup_command`, to 1e-12."""
    f = filter_record(cfg)
    p = f["plant"]
    D = cfg.spacecraft.wheel_inertia_kgm2
    S = cfg.substeps
    dt = cfg.filter.sample_time_s
    for k in (3, 7, 16):
        for variant in ("sun_safe", "momentum"):
            x = states[k]
            u = np.array([1.0, -2.0, 0.5])
            _, traj = backup_rollout(x, u, f, variant)
            assert len(traj) >= S
            ref: list[Array] = []
            while len(ref) * S < len(traj):
                if ref:
                    u = backup_command(x, f, variant)
                u_rt = torque_to_wheel_accel(wheel_accel_to_torque(u, D), D)
                x, subs = integrate(x, u_rt, dt, p, S)
                ref.append(subs)
            np.testing.assert_allclose(traj, np.concatenate(ref)[:len(traj)], rtol=0, atol=1e-12)


def test_backup_law_brings_a_state_to_the_sun_safe_attitude(cfg: Config, states: Array) -> None:
    f = filter_record(cfg)
    x = states[3]
    assert momentum_rad_s(x, cfg) < 300.0
    assert not is_settled(x, f)
    found, traj = backup_rollout(x, backup_command(x, f), f)
    assert found == "settled"
    end = traj[-1]
    assert is_settled(end, f)
    cs = ConstraintSet(cfg)
    angles = cs.angles(end[None])
    assert float(np.degrees(angles["panel_sun"][0])) < 5.0  # +k_B on the sun
    assert abs(float(np.degrees(angles["exclusion_zone"][0])) - 90.0) < 5.0  # the sensor perpendicular
    assert np.all(np.abs(end[4:7]) <= 0.1 * cfg.limits.omega_max_rad_s)  # rates damped
    h = cs.safety_values(traj)
    hard = [i for i, n in enumerate(NAMES) if n not in cfg.slacked_constraints]
    assert np.all(h[:, hard] >= 0)


def test_gate_never_applies_an_unverified_candidate(cfg: Config, states: Array) -> None:
    """A candidate that leads to a violation within the horizon (full wheel acceleration about x from a
    rate near w_max) is replaced by the committed plan's backup command; a good candidate is applied."""
    f = filter_record(cfg)
    g = np.zeros(1, GATE_DTYPE)
    x = states[3].copy()
    u_max = cfg.u_max_rad_s2
    # a safe candidate (the backup law's own command) is verified and commits a plan
    u = backup_command(x, f)
    applied = u.copy()
    assert GATE_NAMES[_gate(x, applied, f, g)] == "verified"
    np.testing.assert_array_equal(applied, u)
    assert g[0]["plan_steps"] == round(cfg.filter.backup_horizon_s / cfg.filter.sample_time_s)
    # a bad candidate: the rate about x pushed past w_max within a sample
    x[4] = 0.9 * cfg.limits.omega_max_rad_s
    x[5] = x[6] = 0.0
    bad = np.array([u_max[0], 0.0, 0.0]) * np.sign(cfg.spacecraft.torque_sign)
    assert backup_rollout(x, bad, f)[0] == "failed"
    applied = bad.copy()
    code = _gate(x, applied, f, g)
    assert code == GATE_BACKUP
    np.testing.assert_array_equal(applied, backup_command(x, f))
    # without a plan, a failing candidate is left in place only if the backup law's own command fails too
    # (the filter then applies it, or its answer to a backup command: `pipeline.filter_state`)
    _reset(g)
    applied = bad.copy()
    code = _gate(x, applied, f, g)
    if code == GATE_BACKUP:
        assert backup_rollout(x, applied, f)[0] != "failed"
    else:
        assert code in (GATE_UNVERIFIED, GATE_TOWARD_BACKUP)
        np.testing.assert_array_equal(applied, bad)
    # every command the gate calls verified passes an independent rollout
    rng = np.random.default_rng(5)
    for _ in range(20):
        _reset(g)
        y = states[rng.integers(len(states))]
        cand = rng.uniform(-1.0, 1.0, 3) * u_max
        applied = cand.copy()
        code = _gate(y, applied, f, g)
        assert code in (GATE_VERIFIED, GATE_BACKUP, GATE_UNVERIFIED, GATE_TOWARD_BACKUP)
        if code == GATE_VERIFIED:
            np.testing.assert_array_equal(applied, cand)
            assert any(backup_rollout(y, cand, f, v)[0] != "failed" for v in ("sun_safe", "momentum"))


def test_where_nothing_verifies_the_filter_answers_the_backup_command_that_lasted_longest(cfg: Config) -> None:
    """Monte Carlo run 1684 of seed 1 at t = 45 s of its loop (|H| / D = 781 rad/s): nothing verifies. Checked
    here rollout by rollout (`backup_rollout`, each variant in VARIANTS order, the plan's first as after a
    reset): the filter's answer to u_des = 0 held a sample then each variant fails, and so does each variant's
    own command, and one of those stays safe longer than any rollout of the answer; the backup law through the
    filter does not verify either. The gate then names `toward_backup` and the filter applies its own answer to
    the command of the variant that lasted longest (the first of the longest): a filter without a gatekeeper
    given that command as u_des answers the same, bit for bit. The record's u_des stays the primary's command."""
    from rta_attitude.filter.asif import AsifFilter

    c = config.load()
    x0, _ = sample_initial_states(5000, 1, c)
    x = run_runs(c, x0[1684:1685], 45.0, record=True).trajectory[0, 45]
    assert momentum_rad_s(x, c) > float(filter_record(c)[0]["backup"]["momentum_variant_rad_s"])
    f = filter_record(c)
    on, alone = AsifFilter(c), AsifFilter(c.with_backup("none"))
    answer = alone.filter(x, np.zeros(3)).u
    answer_lasted = 0
    for v in VARIANTS:
        found, checked = backup_rollout(x, answer, f, v, candidate=True)
        assert found == "failed"
        answer_lasted = max(answer_lasted, len(checked))
    lasted = []
    for v in VARIANTS:
        found, checked = backup_rollout(x, backup_command(x, f, v), f, v)
        assert found == "failed"
        lasted.append(len(checked))
    assert max(lasted) > answer_lasted
    longest = VARIANTS[int(np.argmax(lasted))]
    res = on.filter(x, np.zeros(3))
    assert res.gate == "toward_backup"
    np.testing.assert_array_equal(res.u, alone.filter(x, backup_command(x, f, longest)).u)
    assert not np.array_equal(res.u, answer)
    np.testing.assert_array_equal(res.u_des, 0.0)


def test_where_nothing_verifies_call_after_call_the_filtered_search_backs_off(cfg: Config, states: Array) -> None:
    """The state of the test above (run 1684 of seed 1 at t = 45 s), fed to one filter call after call: nothing
    verifies at any call and no plan is committed, so the calls differ only by the gate's back-off. The
    backup law through the filter (up to 5 x 300 QPs) is tried at the 1st call, then after waits of 1, 2, 4, 8,
    16, 16, ... calls (FILTERED_BACKOFF_MAX); every call answers the same command, bit for bit (a skipped search
    is one that found nothing). A call at which the gate's check verifies a way out ends the back-off: the next
    call at that state tries the search at once."""
    from rta_attitude.filter.asif import AsifFilter
    from rta_attitude.filter.gatekeeper.plans import FILTERED_BACKOFF_MAX

    c = config.load()
    x0, _ = sample_initial_states(5000, 1, c)
    x = run_runs(c, x0[1684:1685], 45.0, record=True).trajectory[0, 45]
    on = AsifFilter(c)
    g = on._ws[0]["gate"]
    first = on.filter(x, np.zeros(3))
    assert first.gate == "toward_backup" and int(g["filtered_tries"]) == 1
    tried_at, wait, k = [1], 0, 1
    while k < 80:  # the schedule: waits 0, 1, 2, 4, ... capped
        k += wait + 1
        tried_at.append(k)
        wait = min(max(2 * wait, 1), FILTERED_BACKOFF_MAX)
    tries = [1]
    for _ in range(2, 81):
        res = on.filter(x, np.zeros(3))
        assert res.gate == "toward_backup"
        np.testing.assert_array_equal(res.u, first.u)
        tries.append(int(g["filtered_tries"]))
    before = [0, *tries[:-1]]
    assert [k + 1 for k in range(80) if tries[k] > before[k]] == [t for t in tried_at if t <= 80]
    assert tries[-1] == 9  # 80 calls: 1, 2, 4, 7, 12, 21, 38, 55, 72
    fine = next(y for y in states if AsifFilter(c).filter(y, np.zeros(3)).gate == "verified")
    assert on.filter(fine, np.zeros(3)).gate == "verified"  # a way out: the back-off ends
    n = int(g["filtered_tries"])
    on.filter(x, np.zeros(3))
    assert int(g["filtered_tries"]) == n + 1


@pytest.mark.parametrize(("run", "t_s"), [(2998, 0), (4994, 60)])
def test_where_the_backup_law_fails_alone_it_can_verify_through_the_filter(cfg: Config, run: int, t_s: int) -> None:
    """Monte Carlo runs of seed 1 where the filter's answer to u_des = 0, held a sample then each variant,
    fails, and so does each variant's own command: run 2998 at t = 0 (|H| / D = 778 rad/s, E_0 = 5,224 J; it
    failed before this mode) and run 4994 at t = 60 s of its loop (|H| / D = 777 rad/s). The backup law
    filtered by the ASIF (at every sample the filter's answer to the law's command) verifies: the gate names
    `filtered_backup`. Re-derived here independently: from x, at each sample the state as the filter receives
    it (`Instruments.deliver`), the law's command there (`backup_command`), a gate-less filter's answer to it,
    held over the sample through the torque interface by the plant's Python `integrate`: every substep keeps
    every hard constraint until the law's terminal set or, with this large momentum, to the horizon; the
    plan's committed commands and states are these, bit for bit, and the first is the one applied. At 2998's
    first state the plan ends with the energy reserve; at 4994's no variant's does (each filtered variant
    re-derived: safe to the horizon or failed, none with the reserve), and the first safe to the horizon is
    committed (as the law's own plans short of the reserve). Fed the plan's next states, the filter applies its
    commands ('backup')."""
    from rta_attitude.filter.asif import AsifFilter

    c = config.load()
    x0, _ = sample_initial_states(5000, 1, c)
    x = x0[run] if t_s == 0 else run_runs(c, x0[run:run + 1], float(t_s), record=True).trajectory[0, t_s]
    f = filter_record(c)
    b = f[0]["backup"]
    on, alone = AsifFilter(c), AsifFilter(c.with_backup("none"))
    answer = alone.filter(x, np.zeros(3)).u
    for v in VARIANTS:
        assert backup_rollout(x, answer, f, v, candidate=True)[0] == "failed"
        assert backup_rollout(x, backup_command(x, f, v), f, v)[0] == "failed"
    res = on.filter(x, np.zeros(3))
    assert res.gate == "filtered_backup"
    g = on._ws[0]["gate"]
    variant = VARIANTS[int(g["plan_law"])]
    n = int(g["plan_n"])
    assert n == round(c.filter.backup_nominal_s / c.filter.sample_time_s)
    plan_x, plan_u = g["plan_x"][:n].copy(), g["plan_u"][:n].copy()
    read = Instruments(c)
    cs = ConstraintSet.from_config(c)
    hard = np.array([name not in c.slacked_constraints for name in NAMES])
    p, D = f["plant"], c.spacecraft.wheel_inertia_kgm2

    def filtered(v: str) -> tuple[str, list[Array], list[Array]]:
        """The law v through a gate-less filter from x: how it ends, the received states and the commands."""
        y, states_, commands_ = x.copy(), [], []
        for j in range(int(b["horizon_steps"]) + 1):
            if j > 0 and is_settled(y, f, v):
                return "settled", states_, commands_
            xr = x if j == 0 else read.deliver(y)
            u = alone.filter(xr, backup_command(xr, f, v)).u
            states_.append(xr)
            commands_.append(u)
            y, subs = integrate(y, torque_to_wheel_accel(wheel_accel_to_torque(u, D), D), 1.0, p, c.substeps)
            if not np.all(cs.safety_values(subs)[:, hard] >= 0.0):
                return "failed", states_, commands_
        return ("reserve" if _reserve(y, f, np.zeros(1, GATE_DTYPE)) else "weak"), states_, commands_

    ended, states, commands = filtered(variant)
    assert ended != "failed"
    np.testing.assert_array_equal(plan_x, np.array(states[:n]))
    np.testing.assert_array_equal(plan_u, np.array(commands[:n]))
    np.testing.assert_array_equal(res.u, plan_u[0])
    if run == 2998:
        assert ended in ("settled", "reserve")
    else:
        assert ended == "weak"
        ends = [filtered(v)[0] for v in VARIANTS]
        assert "reserve" not in ends and "settled" not in ends
        assert VARIANTS.index(variant) == ends.index("weak")  # the first, in order, after a fresh start
    for j in range(1, 4):  # on the plan: its commands, no rollout of the backup law needed
        step = on.filter(plan_x[j], np.zeros(3))
        assert step.gate in ("backup", "verified")
        if step.gate == "backup":
            np.testing.assert_array_equal(step.u, plan_u[j])


def test_no_backup_law_leaves_the_gate_off(cfg: Config, states: Array) -> None:
    f = filter_record(cfg.with_backup("none"))
    g = np.zeros(1, GATE_DTYPE)
    u = np.array([1.0, 2.0, 3.0])
    assert _gate(states[0], u, f, g) == GATE_OFF
    np.testing.assert_array_equal(u, [1.0, 2.0, 3.0])


def test_recursive_feasibility_on_monte_carlo_runs(cfg: Config, states: Array) -> None:
    """Runs (u_des = 0, the campaign's loop) that never met a step without a verified plan stay safe at
    every RK4 substep; and the gate counts add up to the steps."""
    duration_s = 300.0
    x0 = states[:12]
    out = run_runs(cfg, x0, duration_s)
    steps = round(duration_s / cfg.filter.sample_time_s)
    np.testing.assert_array_equal(out.gate_steps.sum(axis=1), steps)
    assert np.all(out.gate_steps[:, GATE_OFF] == 0)
    hard = np.array([n not in cfg.slacked_constraints for n in NAMES])
    covered = (out.gate_steps[:, [GATE_UNVERIFIED, GATE_TOWARD_BACKUP]] == 0).all(axis=1)
    assert covered.sum() >= 6
    assert not np.any(out.violated_substeps[covered][:, hard])


def test_filter_result_names_what_the_gate_did(cfg: Config, states: Array) -> None:
    from rta_attitude.filter.asif import AsifFilter

    on, off = AsifFilter(cfg), AsifFilter(config.load().with_backup("none"))
    x = states[3]
    assert off.filter(x, np.zeros(3)).gate == "off"
    res = on.filter(x, np.zeros(3))
    assert res.gate == "verified"
    assert on._ws[0]["gate"]["plan_steps"] > 0
    on.reset()
    assert on._ws[0]["gate"]["plan_steps"] == 0


@numba.njit
def _target(x: Array, fa: np.ndarray, ga: np.ndarray) -> None:
    f = fa[0]
    sun_safe_error(x, f.plant, f.backup, ga[0])


@pytest.mark.parametrize(("variant", "share"), [("sun_safe", 1.0), ("tight", SETTLED_RATE_FRACTION),
                                               ("cross", SETTLED_RATE_FRACTION)])
def test_the_tilted_target_puts_the_panel_as_near_the_sun_as_the_wheels_allow(cfg: Config, variant: str,
                                                                              share: float) -> None:
    """Large momenta (|H|/D 600-830 rad/s) and the sun at any angle to H: the sun-safe target holds H at
    rest with the rate margin (|T H|_a + J_a w_max <= D psi_max, checked here in numpy; the TIGHT variant's
    with J_a 0.1 w_max, the terminal set's rates), and its panel is as near the sun as an optimiser (SLSQP
    from many starts over all rotations, the same wheel box) can put it: never nearer (sound), and at most
    1.5 deg farther (past a narrow corridor, on its side of H; the CROSS variant on the sun's side, against
    the optimiser over both sides)."""
    from scipy.spatial.transform import Rotation

    f = filter_record(cfg)
    sc, L = cfg.spacecraft, cfg.limits
    D = sc.wheel_inertia_kgm2
    cap = (1.0 - TILT_WHEEL_MARGIN) * D * L.psi_max_rad_s - sc.J * share * L.omega_max_rad_s
    rng = np.random.default_rng(11)
    modes, checked = set(), 0
    while checked < 8:
        x = np.zeros(19)
        x[0:4] = Rotation.random(random_state=rng.integers(1 << 31)).as_quat()  # scalar last, as the state
        x[7:10] = rng.choice([-1.0, 1.0], 3) * rng.uniform(300.0, 576.0, 3)
        x[12] = rng.uniform(0.0, 2.0 * np.pi)
        hb = -sc.torque_sign * D * x[7:10]
        if not 600.0 < np.linalg.norm(hb) / D < 830.0:
            continue
        g = np.zeros(1, GATE_DTYPE)
        g[0]["law"] = VARIANTS.index(variant)
        _target(x, f, g)
        mode, T, Hh = int(g[0]["momentum_mode"]), g[0]["target"], g[0]["Hh"]
        modes.add(mode)
        if mode == 1:  # the momentum mode: H on the body diagonal
            continue
        s = np.array([np.cos(x[12]), np.sin(x[12]), 0.0])
        assert np.all(np.abs(T @ Hh) <= cap + 1e-12)  # the wheels hold H there
        np.testing.assert_allclose(T @ T.T, np.eye(3), atol=1e-12)
        got = float(T[2] @ s)
        # past a narrow corridor the target keeps the panel on its side of H (k_B . H with the sign of H_3)
        side = (variant != "cross"
                and np.linalg.norm(Hh) * np.cos(np.pi / 4 - CORRIDOR_HALF_WIDTH_RAD) > cap[:2].min())
        best = best_panel_cos(Hh, s, cap, rng, side=float(np.sign(hb[2])) if side else 0.0)
        assert got <= best + 1e-9
        # within 1.5 deg: the target splits H_perp at 45 deg with the smaller of the two wheels' rate margins
        assert np.degrees(np.arccos(np.clip(got, -1, 1)) - np.arccos(np.clip(best, -1, 1))) < 1.5
        checked += 1
    assert 2 in modes  # the tilted target was exercised


def test_the_cross_variant_takes_the_momentum_through_the_corridor_to_the_suns_side(cfg: Config) -> None:
    """Monte Carlo run 4056 of seed 1 (|H| / D = 796 rad/s, E_0 = 4,650 J; it failed the battery at 243 s
    before this variant): the corridor across the i_B-j_B plane is narrow (the i_B and j_B wheels must hold
    nearly all of H there), and every attitude the wheels can hold on H_body's side of that plane keeps the
    panel more than 80 deg off the sun (an optimiser over rotations, `best_panel_cos`): each other variant's
    rollout fails the battery (or, the Earth-side one, a rate) within 300 s. The CROSS variant's rollout is
    safe for the whole horizon, checked here again substep by substep in numpy (wheel speeds, rates, the
    charge, the keep-out cone); H_body's k_B part changes sign on the way; the panel ends within 30 deg of
    the sun and the charge is rising there."""
    c = config.load()
    f = filter_record(c)
    x0, _ = sample_initial_states(5000, 1, c)
    x = x0[4056]
    assert 790.0 < momentum_rad_s(x, c) < 800.0
    sc, L = c.spacecraft, c.limits
    D = sc.wheel_inertia_kgm2
    hb = sc.J * x[4:7] - sc.torque_sign * D * x[7:10]
    g = np.zeros(1, GATE_DTYPE)
    _target(x, f, g)
    Hh = g[0]["Hh"]  # H in Hill (constant: no external torque)
    np.testing.assert_allclose(np.linalg.norm(Hh), np.linalg.norm(hb), rtol=1e-12)
    s = np.array([np.cos(x[12]), np.sin(x[12]), 0.0])
    cap = D * L.psi_max_rad_s * np.ones(3)
    this_side = best_panel_cos(Hh, s, cap, np.random.default_rng(3), side=float(np.sign(hb[2])))
    assert this_side < np.cos(np.radians(80.0))  # > 80 deg off the sun on this side, whatever the attitude
    for v in VARIANTS[:-1]:
        assert backup_rollout(x, backup_command(x, f, v), f, v)[0] == "failed"
    found, traj = backup_rollout(x, backup_command(x, f, "cross"), f, "cross")
    assert found == "horizon"
    assert np.all(np.abs(traj[:, 7:10]) <= L.psi_max_rad_s)
    assert np.all(np.abs(traj[:, 4:7]) <= L.omega_max_rad_s)
    assert np.all(traj[:, 11] >= L.energy_min_J)
    cs = ConstraintSet(c)
    h = cs.safety_values(traj)
    assert np.all(h[:, list(NAMES).index("exclusion_zone")] >= 0.0)
    hz = (sc.J[2] * traj[:, 6] - sc.torque_sign * D * traj[:, 9])
    assert hz[0] * hz[-1] < 0.0  # H_body crossed the i_B-j_B plane
    panel = np.degrees(cs.angles(traj[-1])["panel_sun"])
    assert panel < 30.0
    assert traj[-1, 11] > traj[-c.substeps * 30, 11]  # charging over the last 30 s


def test_a_large_momentum_moves_h_in_the_body_before_the_roll(cfg: Config) -> None:
    """With a large momentum far from its place at the target, the backup law turns the body about an axis
    perpendicular to H (the rate command is perpendicular to H_body), so H_body moves straight there and
    the wheels are not carried past their limit on the way."""
    f = filter_record(cfg)
    sc = cfg.spacecraft
    x0, _ = sample_initial_states(200, 1, cfg)
    seen = 0
    for x in x0:
        hb = sc.J * x[4:7] - sc.torque_sign * sc.wheel_inertia_kgm2 * x[7:10]
        if np.linalg.norm(hb) / sc.wheel_inertia_kgm2 < 600.0:
            continue
        g = np.zeros(1, GATE_DTYPE)
        _target(x, f, g)
        T, Hh, dq = g[0]["target"], g[0]["Hh"], g[0]["dq"]
        ht = T @ Hh / np.linalg.norm(Hh)  # H in the body at the target
        if g[0]["momentum_mode"] == 1 or np.arccos(np.clip(ht @ hb / np.linalg.norm(hb), -1, 1)) < np.radians(10):
            continue
        assert abs(dq @ hb) <= 1e-12 * np.linalg.norm(dq) * np.linalg.norm(hb)
        np.testing.assert_allclose(dq, 0.5 * np.cross(hb / np.linalg.norm(hb), ht), atol=1e-12)
        seen += 1
    assert seen >= 5


def test_backup_nominal_s_is_validated() -> None:
    cfg = config.load()
    for bad in (0.0, 0.4, 121.0, float("nan")):
        with pytest.raises(ConfigError, match=r"filter\.backup_nominal_s"):
            dataclasses.replace(cfg, filter=dataclasses.replace(cfg.filter, backup_nominal_s=bad))
    assert filter_record(cfg)[0]["backup"]["nominal_steps"] == round(cfg.filter.backup_nominal_s)


def test_a_nominal_plan_holds_what_it_claims(cfg: Config, states: Array) -> None:
    """The plan the gate commits (the answer held a sample, then the filter's own answers, u_des held,
    then the backup law) is re-derived independently: its states are the plant's Python `integrate` of
    its commands, its answers are those of a filter without a gatekeeper at those states, every substep
    of its nominal part keeps every hard constraint and the backup law from its end settles safely.
    Fed those states in order, the filter applies the plan's answers without a new rollout; a state one
    ulp off the plan (a rate: rates cross the message interface exactly) is checked afresh; one float32 step
    of the battery's reading off it (the interface's rounding) is not."""
    from rta_attitude.filter.asif import AsifFilter

    assert cfg.filter.backup_nominal_s > cfg.filter.sample_time_s
    on, alone = AsifFilter(cfg), AsifFilter(cfg.with_backup("none"))
    read = Instruments(cfg)
    cs = ConstraintSet.from_config(cfg)
    hard = np.array([n not in cfg.slacked_constraints for n in NAMES])
    p = filter_record(cfg)["plant"]
    D = cfg.spacecraft.wheel_inertia_kgm2
    u_des = np.zeros(3)
    checked = 0
    for x in states[:8]:
        if momentum_rad_s(x, cfg) > 500.0:
            continue
        on.reset()
        res = on.filter(x, u_des)
        g = on._ws[0]["gate"]
        n = int(g["plan_n"])
        if res.gate != "verified" or n == 0:
            continue
        second_x = None
        x1 = x
        np.testing.assert_array_equal(res.u, alone.filter(x, u_des).u)
        assert n == round(cfg.filter.backup_nominal_s / cfg.filter.sample_time_s)
        plan_x, plan_u = g["plan_x"][:n].copy(), g["plan_u"][:n].copy()
        np.testing.assert_array_equal(plan_x[0], x1)
        np.testing.assert_array_equal(plan_u[0], res.u)
        y, subs_all = x1, []
        for j in range(n):
            if j > 0:  # the predicted state as the filter will receive it (the message interface)
                np.testing.assert_array_equal(plan_x[j], read.deliver(y))
                np.testing.assert_array_equal(plan_u[j], alone.filter(read.deliver(y), u_des).u)
            y, subs = integrate(y, torque_to_wheel_accel(wheel_accel_to_torque(plan_u[j], D), D), 1.0, p,
                                cfg.substeps)
            subs_all.append(subs)
        assert np.all(cs.safety_values(np.concatenate(subs_all))[:, hard] >= 0.0)
        found, tail = backup_rollout(y, backup_command(y, f := filter_record(cfg)), f)
        assert found == "settled"
        assert np.all(cs.safety_values(tail)[:, hard] >= 0.0)
        # the filter follows the plan without a new rollout while the states are the predicted ones
        for j in range(1, n):
            before = int(g["reused"])
            step = on.filter(plan_x[j], u_des)
            assert step.gate == "verified"
            np.testing.assert_array_equal(step.u, plan_u[j])
            assert int(on._ws[0]["gate"]["reused"]) == before + 1
            if j == 3:
                second_x = plan_x[j + 1].copy()
                break
        assert second_x is not None
        battery = second_x.copy()
        charge = np.float32(battery[11] / (cfg.power.bus_voltage_V * 3600.0))
        battery[11] = float(np.nextafter(charge, np.float32(np.inf))) * (cfg.power.bus_voltage_V * 3600.0)
        second_x[4] = np.nextafter(second_x[4], np.inf)  # one ulp off the plan's rate: a fresh check
        before = int(on._ws[0]["gate"]["reused"])
        on.filter(second_x, u_des)
        assert int(on._ws[0]["gate"]["reused"]) == before
        checked += 1
    assert checked >= 2
    # the battery's reading one float32 step from the prediction is still on the plan, the rate's ulp is not
    assert backup_predicted(battery, plan_x[4]) and not backup_predicted(second_x, plan_x[4])


def test_an_answer_off_the_plan_is_checked_alone_or_replaced_by_the_plans(cfg: Config, states: Array) -> None:
    """On a committed nominal plan's state but with another desired command (the answer differs from the
    plan's), the gate applies that answer only if a rollout of it verifies, else the plan's own answer."""
    from rta_attitude.filter.asif import AsifFilter

    on = AsifFilter(cfg)
    f = filter_record(cfg)
    u_max = cfg.u_max_rad_s2
    rng = np.random.default_rng(2)
    seen: list[str] = []
    for x in states[:10]:
        if momentum_rad_s(x, cfg) > 500.0:
            continue
        for _ in range(3):
            on.reset()
            on.filter(x, np.zeros(3))
            g = on._ws[0]["gate"]
            if int(g["plan_n"]) < 2:
                break
            at = int(g["plan_at"])
            planned, y = g["plan_u"][at].copy(), g["plan_x"][at].copy()
            g["nominal_wait"] = 1  # the answer alone, not a new nominal plan
            res = on.filter(y, rng.uniform(-1.0, 1.0, 3) * u_max)
            assert not np.array_equal(res.u_des, np.zeros(3))
            seen.append(res.gate)
            if res.gate == "verified":
                assert any(backup_rollout(y, res.u, f, v)[0] != "failed" for v in ("sun_safe", "momentum"))
            else:
                assert res.gate == "backup"
                np.testing.assert_array_equal(res.u, planned)
    assert len(seen) >= 3


def test_in_backup_mode_a_settled_plan_is_followed_without_a_new_rollout(cfg: Config, states: Array) -> None:
    """Where the candidate fails on the committed plan's predicted state (bit for bit) and the plan reaches
    the terminal set, the gate applies the plan's next command (its backup law) without a rollout, and
    predicts the next state as the plant's `integrate` of it, as the filter will receive it (the message
    interface: `Instruments.deliver`); one ulp off the prediction's rate it checks afresh."""
    read = Instruments(cfg)
    f = filter_record(cfg)
    p = f["plant"]
    D = cfg.spacecraft.wheel_inertia_kgm2
    g = np.zeros(1, GATE_DTYPE)
    x = states[3].copy()
    assert momentum_rad_s(x, cfg) < 300.0
    u = backup_command(x, f)
    assert GATE_NAMES[_gate(x, u.copy(), f, g)] == "verified"
    assert g[0]["has_next"] and g[0]["plan_settled"]

    def step(y: Array, v: Array) -> Array:
        return integrate(y, torque_to_wheel_accel(wheel_accel_to_torque(v, D), D), 1.0, p, cfg.substeps)[0]

    x1 = read.deliver(step(x, u))
    np.testing.assert_array_equal(g[0]["next_x"], x1)
    bad = np.array([np.nan, 0.0, 0.0])  # a candidate no rollout passes
    for _ in range(3):
        before = int(g[0]["reused"])
        applied = bad.copy()
        assert GATE_NAMES[_gate(x1, applied, f, g)] == "backup"
        np.testing.assert_array_equal(applied, backup_command(x1, f))
        assert int(g[0]["reused"]) == before + 1
        x1 = read.deliver(step(x1, applied))
        np.testing.assert_array_equal(g[0]["next_x"], x1)
    off = x1.copy()
    off[4] = np.nextafter(off[4], np.inf)
    before = int(g[0]["reused"])
    applied = bad.copy()
    assert GATE_NAMES[_gate(off, applied, f, g)] == "backup"
    assert int(g[0]["reused"]) == before


@numba.njit
def _margins(fa: np.ndarray, out: Array) -> None:
    f = fa[0]
    check_margins(f.plant, f.constraints, out)


def test_rollout_margins_cover_the_measurement_errors(cfg: Config) -> None:
    """Without sensor errors the rollout keeps h >= 0; with them, each h keeps a margin such that whatever
    true state lies within the error bounds of the measured one (rates, wheel speeds: sampled here) has
    h >= 0 wherever the measured one keeps its margin."""
    from rta_attitude.constraints.base import measurement_errors

    col = {n: i for i, n in enumerate(NAMES)}
    read = interface_energy_error(cfg)  # the battery's float32 charge, with or without sensor errors
    zero = np.empty(len(NAMES))
    _margins(filter_record(cfg), zero)
    assert zero[col["battery"]] == read > 0
    np.testing.assert_array_equal(np.delete(zero, col["battery"]), 0.0)
    noisy = cfg.with_noise()
    m = np.empty(len(NAMES))
    _margins(filter_record(noisy), m)
    err = measurement_errors(noisy)
    assert m[col["exclusion_zone"]] == err["err_att_rad"] > 0
    assert m[col["temperature"]] == err["err_T_K"] > 0 and m[col["battery"]] == err["err_E_J"] + read
    L, G, dt = noisy.limits, noisy.spacecraft.control_gain, noisy.filter.sample_time_s
    rng = np.random.default_rng(4)
    for a in range(3):
        for name, limit, e in ((f"omega_{'xyz'[a]}", L.omega_max_rad_s,
                                err["err_omega_axis_rad_s"] + abs(G[a]) * err["err_u_rad_s2"][a] * dt),
                               (f"psi_{'xyz'[a]}", L.psi_max_rad_s,
                                err["err_psi_rad_s"] + err["err_u_rad_s2"][a] * dt)):
            measured = rng.uniform(-limit, limit, 20000)
            true = measured + rng.uniform(-e, e, measured.size)
            kept = limit**2 - measured**2 >= m[col[name]]
            assert kept.any() and np.all(limit**2 - true[kept] ** 2 >= 0.0), name


def test_a_candidate_keeps_the_reading_errors_three_times_and_the_backup_law_once(cfg: Config, states: Array) -> None:
    """Hysteresis (sensor errors on): a candidate's rollout keeps the pointing constraints', the temperature's and
    the charge's reading errors three times, the backup law's once; without sensor errors both margins are equal. A
    backup path whose lowest charge lies between the two floors (E's dynamics do not depend on E: the
    path is shifted, checked here) is accepted as the backup law's and refused as a candidate's, at the
    battery. And the extra is what the hand-over needs, no less: a candidate accepted at its floor from a
    reading e above the truth, then a next reading e below it (the worst two readings), leaves the backup
    law's path from that reading exactly at the backup law's floor; with one reading's extra it would fall e
    below it and be refused."""
    from rta_attitude.constraints.base import measurement_errors

    col = {n: i for i, n in enumerate(NAMES)}
    plain = filter_record(cfg)[0]["backup"]
    np.testing.assert_array_equal(plain["candidate_margin"], plain["margin"])
    noisy = cfg.with_noise()
    f = filter_record(noisy)
    b = f[0]["backup"]
    err = measurement_errors(noisy)
    extra = b["candidate_margin"] - b["margin"]
    cones = [col[c.name] for c in noisy.pointing]  # every pointing constraint (a slacked one is never checked)
    np.testing.assert_allclose(extra[cones], 2.0 * err["err_att_rad"], rtol=1e-12)
    assert err["err_att_rad"] > 0
    assert extra[col["temperature"]] == pytest.approx(2.0 * err["err_T_K"], rel=1e-12) and err["err_T_K"] > 0
    assert extra[col["battery"]] == pytest.approx(2.0 * err["err_E_J"], rel=1e-12) and err["err_E_J"] > 0
    np.testing.assert_array_equal(np.delete(extra, [*cones, col["temperature"], col["battery"]]), 0.0)
    E = 11
    S = noisy.substeps
    e = err["err_E_J"]  # one reading's error bound of the charge
    floor = noisy.limits.energy_min_J + b["margin"][col["battery"]]
    tried = 0
    for x in states:
        u = backup_command(x, f)
        found, path = backup_rollout(x, u, f)
        if found == "failed" or path[:, E].argmin() < S:
            continue  # a path whose charge falls after its first sample, then rises
        tried += 1
        y = x.copy()
        y[E] += floor + 0.5 * extra[col["battery"]] - path[:, E].min()
        found_b, path_b = backup_rollout(y, u, f)
        assert found_b == found
        np.testing.assert_allclose(path_b[:, E] - path[:, E], y[E] - x[E], atol=1e-9)
        found_c, path_c = backup_rollout(y, u, f, candidate=True)
        assert found_c == "failed"
        assert path_c[-1, E] < floor + extra[col["battery"]]
        c_rows = ConstraintSet(noisy).safety_values(path_c[-1])
        assert c_rows[col["battery"]] < b["candidate_margin"][col["battery"]]
        assert np.all(np.delete(c_rows >= b["candidate_margin"][: len(NAMES)], [col["battery"], col["communication"]]))
        # the hand-over: the candidate (the law's own command here) accepted with its lowest charge at its floor
        y = x.copy()
        y[E] += floor + extra[col["battery"]] + 1e-6 - path[:, E].min()
        found_c, path_c = backup_rollout(y, u, f, candidate=True)
        assert found_c == found
        nxt = path_c[S - 1].copy()  # one sample on, as the reading predicted it
        nxt[E] -= 2.0 * e  # the truth e below that reading, the next reading e below the truth
        u1 = backup_command(nxt, f)
        found_1, path_1 = backup_rollout(nxt, u1, f)
        assert found_1 == found, "the backup law from the worst next reading must still pass"
        assert path_1[:, E].min() == pytest.approx(floor + 1e-6, abs=1e-6)
        n = min(len(path_1), len(path_c) - S)  # the law's path from there: the candidate's, shifted
        np.testing.assert_allclose(path_1[:n, E], path_c[S:S + n, E] - 2.0 * e, atol=1e-6)
        if tried == 3:
            break
    assert tried == 3


def test_the_backup_law_does_not_overshoot_its_rate_limit_with_a_large_momentum(cfg: Config) -> None:
    """The law cancels the drift at its hold's middle: with a large momentum its held command changes the
    rates, and the gyroscopic torque with them, within the sample. From seed 1's first 150 states above
    552 rad/s that start inside the law's rate limit, its rollouts that pass (the plant's RK4 substeps;
    137 and 142 of them) keep every rate within 4 % of that limit after their first two samples, with and
    without sensor errors (the drift held from the hold's start: up to 11 and 18 % above it, 103 and 113
    passing, measured 2026-11-26). A failing rollout may overshoot: where a wheel is held at its
    checked speed, nothing cancels the drift."""
    states, _ = sample_initial_states(5000, 1, cfg)  # the same with or without sensor errors
    for noisy in (False, True):
        c = cfg.with_noise(noisy)
        f = filter_record(c)
        lim = float(f[0]["backup"]["rate_limit_rad_s"])
        x0 = states[(momentum_rad_s(states, c) > 552.0) & (np.abs(states[:, 4:7]).max(axis=1) < lim)][:150]
        assert len(x0) == 150
        worst = 0.0
        for x in x0:
            found, path = backup_rollout(x, backup_command(x, f), f)
            if found != "failed" and len(path) > 2 * c.substeps:
                worst = max(worst, float(np.abs(path[2 * c.substeps:, 4:7]).max()) / lim)
        assert 1.0 < worst <= 1.04, (noisy, worst)


def test_the_backup_law_keeps_each_wheel_within_the_speed_its_rollouts_check(cfg: Config) -> None:
    """psi_dot = u: over a hold the wheel's speed is linear, so the law's command keeps it within
    psi_hold if it does at the hold's end. psi_hold is what the rollouts check (psi_limit: psi_max, less
    with sensor errors) less one reading's error (e = the tachometer's + the actuator's over a hold; 0
    without sensor errors). From 200 of seed 1's states with every wheel at 0.97-1.0 psi_limit, both
    variants' commands end their holds within psi_hold, some of them on it (the clip acts), and their
    rollouts keep every substep's wheel speeds within psi_limit (the law without the clip: up to 1.04
    psi_limit at a hold's end and 1.004 on the path, measured 2026-11-26)."""
    states, _ = sample_initial_states(5000, 1, cfg)
    rng = np.random.default_rng(5)
    for noisy in (False, True):
        c = cfg.with_noise(noisy)
        f = filter_record(c)
        b, con = f[0]["backup"], f[0]["constraints"]
        limit, hold, dt = float(b["psi_limit_rad_s"]), float(b["psi_hold_rad_s"]), c.filter.sample_time_s
        e = float(con["err_psi_rad_s"] + con["err_u_rad_s2"].max() * dt)
        assert (e > 0.5) == noisy and hold == pytest.approx(limit - e, rel=1e-12)
        ends, paths, on_it = [], [], 0
        for x in states[:200].copy():
            x[7:10] = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.97, 1.0, 3) * limit
            for variant in VARIANTS:
                u = backup_command(x, f, variant)
                end = np.abs(x[7:10] + dt * u)
                ends.append(end.max())
                on_it += bool(np.any(np.isclose(end, hold, rtol=1e-9, atol=0.0)))
                paths.append(np.abs(backup_rollout(x, u, f, variant)[1][:, 7:10]).max())
        assert max(ends) <= hold and max(paths) <= limit, (noisy, max(ends) / hold, max(paths) / limit)
        assert on_it >= 50, (noisy, on_it)


def test_off_its_plan_the_gate_does_not_apply_a_stale_backup_command(cfg: Config, states: Array) -> None:
    """After a plan was committed, a state that is not the one it predicted (sensor errors, another model),
    from which neither the candidate nor the backup law verifies, gets the candidate (unverified) and the
    plan is dropped: its backup command was verified from a state the spacecraft is not in."""
    f = filter_record(cfg)
    g = np.zeros(1, GATE_DTYPE)
    x = states[3].copy()
    assert GATE_NAMES[_gate(x, backup_command(x, f), f, g)] == "verified"
    assert g[0]["plan_steps"] > 0
    off = g[0]["next_x"].copy()
    off[4] = 1.5 * cfg.limits.omega_max_rad_s  # past the rate limit: no rollout from here passes
    cand = np.array([0.5, -0.5, 0.25])
    applied = cand.copy()
    assert GATE_NAMES[_gate(off, applied, f, g)] == "unverified"
    np.testing.assert_array_equal(applied, cand)
    assert g[0]["plan_steps"] == 0


def test_with_sensor_errors_the_backup_law_stays_inside_its_rollouts_margins(cfg: Config, states: Array) -> None:
    """Without sensor errors the backup law is as configured; with them its rate command and its targets'
    wheel speeds leave the rollouts' measurement margins (`apply_measurement_margins`), so that from calm
    states its own rollout, which keeps those margins, still reaches the terminal set."""
    plain = filter_record(cfg)[0]["backup"]
    assert plain["rate_limit_rad_s"] == RATE_LIMIT_FRACTION * cfg.limits.omega_max_rad_s
    assert plain["psi_limit_rad_s"] == cfg.limits.psi_max_rad_s
    noisy_cfg = cfg.with_noise()
    f = filter_record(noisy_cfg)
    m = np.empty(len(NAMES))
    _margins(f, m)
    b = f[0]["backup"]
    w_max, psi_max = cfg.limits.omega_max_rad_s, cfg.limits.psi_max_rad_s
    omega = [NAMES.index(f"omega_{a}") for a in "xyz"]
    psi = [NAMES.index(f"psi_{a}") for a in "xyz"]
    assert b["rate_limit_rad_s"] ** 2 < w_max**2 - m[omega].max()
    assert b["psi_limit_rad_s"] ** 2 == pytest.approx(psi_max**2 - m[psi].max(), rel=1e-12)
    settled = 0
    for x in states[:12]:
        if momentum_rad_s(x, cfg) > 400.0:
            continue
        found, _ = backup_rollout(x, backup_command(x, f), f)
        settled += found == "settled"
    assert settled >= 3


@numba.njit
def _reserve(x: Array, fa: np.ndarray, ga: np.ndarray) -> bool:
    f = fa[0]
    return energy_reserve(x, f.plant, f.constraints, f.backup, ga[0])


def with_lookahead(cfg: Config, seconds: float) -> Config:
    return dataclasses.replace(cfg, filter=dataclasses.replace(cfg.filter, backup_energy_lookahead_s=seconds))


def _projected_threshold(x: Array, cfg: Config, floor_J: float) -> float:
    """The least E at x for which the panel, held at the smallest angle to the sun at which the wheels hold
    the momentum at rest, keeps E >= floor at every 10 s step of the lookahead: written here with angles
    (the band of beta = angle(k_B, H) from the wheel box, the panel's distance to it), not the kernel's
    cosines. The attitude matrix from scipy (passive: A = R^T)."""
    from scipy.spatial.transform import Rotation

    sc, L, o = cfg.spacecraft, cfg.limits, cfg.filter
    D, J, w_max = sc.wheel_inertia_kgm2, np.asarray(sc.J), L.omega_max_rad_s
    A = Rotation.from_quat(x[0:4]).as_matrix().T
    hb = J * x[4:7] - sc.torque_sign * D * x[7:10]
    h0 = A.T @ hb
    hn = float(np.linalg.norm(h0))
    top = (1.0 - TILT_WHEEL_MARGIN) * L.psi_max_rad_s * D
    c1, c2, c3 = top - J * w_max
    lo_beta = np.arccos(min(1.0, c3 / hn))                  # the panel-axis wheel: |H cos beta| <= c3
    hi_beta = np.arcsin(min(1.0, np.hypot(c1, c2) / hn))    # the others: |H| sin beta <= |(c1, c2)|
    bands = [(lo_beta, hi_beta), (np.pi - hi_beta, np.pi - lo_beta)]
    if hn * np.cos(np.pi / 4 - CORRIDOR_HALF_WIDTH_RAD) > min(c1, c2):  # a narrow corridor: H_body's side
        bands = [bands[0] if hb[2] >= 0 else bands[1]]
    n = cfg.environment.mean_motion_rad_s
    frame = n if cfg.environment.rotating_hill else 0.0
    t = (np.arange(round(o.backup_energy_lookahead_s / 10.0)) + 0.5) * 10.0
    theta = x[12] - n * t
    sun = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(t)], axis=1)
    c, s = np.cos(-frame * t), np.sin(-frame * t)  # H fixed inertially: in Hill it turns by -frame t
    h = np.stack([c * h0[0] - s * h0[1], s * h0[0] + c * h0[1], np.full_like(t, h0[2])], axis=1)
    alpha = np.arccos(np.clip(np.sum(h * sun, axis=1) / hn, -1.0, 1.0))
    if hn <= c3:
        phi = np.zeros_like(t)
    else:
        phi = np.min([np.maximum(0.0, np.maximum(lo - alpha, alpha - hi)) for lo, hi in bands], axis=0)
    pw = cfg.power
    peak = pw.ideal_W_m2 * pw.degradation * pw.panel_area_m2
    gain = np.cumsum(10.0 * (peak * np.maximum(0.0, np.cos(phi)) - pw.load_W))
    return floor_J - float(gain.min())


def _kernel_threshold(x: Array, f: np.ndarray, candidate: bool = False) -> float:
    g = np.zeros(1, GATE_DTYPE)
    g[0]["candidate"] = candidate
    y = x.copy()
    lo, hi = -1e5, 1e5
    for _ in range(80):
        y[11] = 0.5 * (lo + hi)
        if _reserve(y, f, g):
            hi = y[11]
        else:
            lo = y[11]
    return hi


@pytest.mark.parametrize("rotating", [False, True])
def test_the_energy_reserve_is_the_projection_of_the_tilted_panel(cfg: Config, rotating: bool) -> None:
    """`energy_reserve` accepts exactly the energies at which the battery stays above E_min over the
    lookahead with the panel as near the sun as the wheels hold the momentum (an independent projection
    written with angles), for large momenta (|H|/D 560-830 rad/s, both sides of the split), a small one
    (the panel on the sun: the threshold is one step's charge below the floor), in an inertial Hill frame
    and in a rotating one (H turns with the sun there)."""
    from scipy.spatial.transform import Rotation

    c = with_lookahead(cfg, 3000.0)
    if rotating:
        c = dataclasses.replace(c, environment=dataclasses.replace(c.environment, rotating_hill=True))
    f = filter_record(c)
    assert f[0]["plant"]["frame_rate_rad_s"] == (c.environment.mean_motion_rad_s if rotating else 0.0)
    floor = c.limits.energy_min_J + float(f[0]["backup"]["margin"][NAMES.index("battery")])
    rng = np.random.default_rng(23)
    seen, tested = [], 0
    while tested < 10:
        x = np.zeros(19)
        x[0:4] = Rotation.random(random_state=rng.integers(1 << 31)).as_quat()
        x[4:7] = rng.uniform(-1.0, 1.0, 3) * c.limits.omega_max_rad_s
        x[7:10] = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.0 if tested == 0 else 300.0, 576.0, 3)
        x[10], x[12] = 280.0, rng.uniform(0.0, 2.0 * np.pi)
        hn = momentum_rad_s(x, c)
        if not (hn < 400.0 if tested == 0 else 560.0 < hn < 830.0):
            continue
        want = _projected_threshold(x, c, floor)
        got = _kernel_threshold(x, f)
        assert got == pytest.approx(want, abs=1e-6), (hn, got, want)
        x[11] = want + 1e-3
        assert _reserve(x, f, np.zeros(1, GATE_DTYPE))
        x[11] = want - 1e-3
        assert not _reserve(x, f, np.zeros(1, GATE_DTYPE))
        seen.append((hn, want))
        tested += 1
    assert seen[0][1] == pytest.approx(floor - 10.0 * (f[0]["plant"]["panel_peak_W"] - c.power.load_W))
    if not rotating:  # the sun turning past a fixed H: some momenta need a real reserve
        assert max(w for _, w in seen) > floor + 1000.0


def test_a_candidates_energy_reserve_keeps_the_candidates_floor(cfg: Config) -> None:
    """The reserve's projection keeps the floor of the rollout it ends: a candidate's (candidate_margin, the
    hand-over's three reading errors) or the backup law's (one): with sensor errors the least accepted charge
    at the same state is higher for a candidate by exactly the difference of the two battery margins; without
    them the two are the same. Large momenta (the reserve applies only there) from seed 1's states."""
    k = NAMES.index("battery")
    x0, _ = sample_initial_states(400, 1, cfg)
    large = [x for x in x0 if 600.0 < momentum_rad_s(x, cfg) < 830.0][:4]
    assert len(large) == 4
    for noisy in (False, True):
        c = with_lookahead(cfg.with_noise(noisy), 3000.0)
        f = filter_record(c)
        b = f[0]["backup"]
        extra = float(b["candidate_margin"][k] - b["margin"][k])
        assert (extra > 39.0) if noisy else (extra == 0.0)
        for x in large:
            law, cand = _kernel_threshold(x, f), _kernel_threshold(x, f, candidate=True)
            assert cand - law == pytest.approx(extra, abs=1e-6)


def test_short_of_the_energy_reserve_the_gate_applies_the_backup_law_and_follows_it(cfg: Config) -> None:
    """A large momentum (Monte Carlo run 377 of seed 1, |H|/D = 838 rad/s), the panel held by the backup
    law for 300 s: with plenty of charge the gate applies the candidate (u = 0: verified); with less than the
    lookahead needs (the horizon itself stays safe), it applies the backup law instead and commits its plan
    as one short of the reserve, which the lookahead 0 (off) would not (the candidate again). At the state
    the plan predicted, the plan is followed without a new rollout (one sample simulated: the next
    prediction) until nominal_steps samples have passed, then checked afresh."""
    c = config.load()
    f, f_off = filter_record(c), filter_record(with_lookahead(c, 0.0))
    x0, _ = sample_initial_states(5000, 1, c)
    x = x0[377].copy()
    assert 830.0 < momentum_rad_s(x, c) < 840.0
    D, p = c.spacecraft.wheel_inertia_kgm2, f[0:1]["plant"]
    for _ in range(300):
        u = torque_to_wheel_accel(wheel_accel_to_torque(backup_command(x, f), D), D)
        x, _ = integrate(x, u, 1.0, p, c.substeps)
    x[11] = 20000.0
    g = np.zeros(1, GATE_DTYPE)
    applied = np.zeros(3)
    assert _gate(x, applied, f, g) == GATE_VERIFIED and not g[0]["plan_weak"]
    np.testing.assert_array_equal(applied, 0.0)
    x[11] = 6000.0
    assert backup_rollout(x, np.zeros(3), f)[0] == "horizon"  # the candidate is safe to the horizon ...
    assert not _reserve(x, f, np.zeros(1, GATE_DTYPE))        # ... but short of the reserve at its end
    g_off = np.zeros(1, GATE_DTYPE)
    applied = np.zeros(3)
    assert _gate(x, applied, f_off, g_off) == GATE_VERIFIED
    g = np.zeros(1, GATE_DTYPE)
    applied = np.zeros(3)
    assert _gate(x, applied, f, g) == GATE_BACKUP and g[0]["plan_weak"] == 1
    np.testing.assert_array_equal(applied, backup_command(x, f, VARIANTS[int(g[0]["plan_law"])]))
    assert backup_rollout(x, applied, f, VARIANTS[int(g[0]["plan_law"])])[0] == "horizon"
    ins = Instruments(c)
    steps = int(f[0]["backup"]["horizon_steps"])
    nominal = int(f[0]["backup"]["nominal_steps"])
    followed = 0
    for _ in range(nominal + 2):
        u = torque_to_wheel_accel(wheel_accel_to_torque(applied, D), D)
        x, _ = integrate(x, u, 1.0, p, c.substeps)
        left = int(g[0]["plan_steps"])
        applied = np.zeros(3)
        code = _gate(ins.deliver(x), applied, f, g)
        assert code == GATE_BACKUP
        if int(g[0]["checked"]) == c.substeps:  # one sample: the plan followed, no rollout
            assert int(g[0]["plan_steps"]) == left - 1 and left > steps - nominal
            followed += 1
        else:  # checked afresh once the plan is nominal_steps old: committed again
            assert left <= steps - nominal + 1 and int(g[0]["plan_steps"]) == steps
    assert followed >= nominal - 1


def test_backup_energy_lookahead_is_validated() -> None:
    cfg = config.load()
    for bad in (-1.0, float("nan"), float("inf"), 2e6):
        with pytest.raises(ConfigError, match=r"filter\.backup_energy_lookahead_s"):
            with_lookahead(cfg, bad)
    assert filter_record(with_lookahead(cfg, 0.0))[0]["backup"]["reserve_steps"] == 0
    assert filter_record(cfg)[0]["backup"]["reserve_steps"] == round(cfg.filter.backup_energy_lookahead_s / 10.0)
