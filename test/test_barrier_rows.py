"""The compiled rows and box of one state (`constraints.rows`) against the numpy oracle (test/oracles,
the first implementation; the compiled rows are also checked against finite differences in
test_constraints), at random states and at the arccos poles."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from helpers import random_states
from oracles.constraints import ConstraintSet as OracleSet

from rta_attitude import config
from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.spacecraft import integrate, plant_record
from rta_attitude.dynamics.state import THETA_S, Q

CFG = config.load()


def oracle_box(x: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """The box lo <= u <= hi from the numpy oracle: U, intersected in the robust preset with the
    one-step ZOH intervals; an interval that misses U shrinks the box to U's nearest edge."""
    oracle = OracleSet.from_config(cfg)
    u_max = cfg.u_max_rad_s2
    lo = np.broadcast_to(-u_max, (*np.shape(x)[:-1], 3)).copy()
    hi = np.broadcast_to(u_max, (*np.shape(x)[:-1], 3)).copy()
    if cfg.filter.preset == "robust":
        zlo, zhi = oracle.zoh_bounds(oracle.context(x), cfg.filter.sample_time_s, cfg.filter.zoh_margin)
        new_lo, new_hi = np.maximum(lo, zlo), np.minimum(hi, zhi)
        bad = new_lo > new_hi
        edge = np.where(zhi < lo, lo, hi)
        lo, hi = np.where(bad, edge, new_lo), np.where(bad, edge, new_hi)
    return lo, hi


def _pole_states(rng: np.random.Generator, cfg: Config) -> np.ndarray:
    """Random states plus attitudes at and next to the arccos poles of the angle constraints."""
    x = random_states(rng, 1500, cfg)
    p = x[:6].copy()
    p[0, Q], p[0, THETA_S] = (0.0, 0.0, 0.0, 1.0), math.pi  # sensor anti-sun
    p[1, Q], p[1, THETA_S] = (0.0, 0.0, 0.0, 1.0), 0.0  # sensor on the sun
    p[2, Q] = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))  # antenna (+j_B) on the Earth (-x Hill)
    p[3, Q], p[3, THETA_S] = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)), 0.5 * math.pi  # panel on the sun
    p[4, Q], p[4, THETA_S] = (0.0, 0.0, 0.0, 1.0), math.pi + 0.9e-3  # inside the pole guard
    p[5, Q], p[5, THETA_S] = (0.0, 0.0, 0.0, 1.0), math.pi + 1.1e-3  # just outside it
    return np.concatenate([x, p])


def _with_margins(cfg: Config) -> Config:
    margins = {"temperature": 0.1, "battery": 20.0}
    barriers = {k: dataclasses.replace(v, margin=margins[k]) if k in margins else v for k, v in cfg.barriers.items()}
    pointing = tuple(dataclasses.replace(c, gains=dataclasses.replace(c.gains, margin=m))
                     for c, m in zip(cfg.pointing, (1e-3, 2e-3)))
    return dataclasses.replace(cfg, barriers=barriers, pointing=pointing)


@pytest.mark.parametrize("variant", ["robust", "paper", "robust-with-margins", "rates-disabled"])
def test_compiled_rows_and_box_equal_the_reference(variant: str) -> None:
    if variant == "robust-with-margins":
        cfg = _with_margins(CFG.with_preset("robust"))
    elif variant == "rates-disabled":  # the ZOH bounds leave out omega: only psi shapes the box
        cfg = dataclasses.replace(CFG, barriers={**CFG.barriers,
                                                 "omega": dataclasses.replace(CFG.barriers["omega"], enabled=False)})
    else:
        cfg = CFG.with_preset(variant)
    x = _pole_states(np.random.default_rng(3), cfg)
    ref = OracleSet.from_config(cfg).evaluate(x)
    lo, hi = oracle_box(x, cfg)
    out = ConstraintSet(cfg).evaluate(x)
    for key, r in (("h", ref.h), ("psi0", ref.psi0), ("psi1", ref.psi1), ("drift", ref.drift), ("gain", ref.gain),
                   ("lo", lo), ("hi", hi)):
        # the same formulas; summation order may differ in the last bit
        np.testing.assert_allclose(out[key], r, rtol=1e-12, atol=1e-13, err_msg=key)
    # the pole guard: inside it the exclusion-zone row has no gain on u; just outside it has
    assert np.all(out["gain"][-2, 0] == 0.0) and np.any(out["gain"][-1, 0] != 0.0)
    # one state at a time gives the batch's numbers exactly
    one = ConstraintSet(cfg).evaluate(x[7])
    for key in ("h", "psi0", "psi1", "drift", "gain", "lo", "hi"):
        np.testing.assert_array_equal(one[key], out[key][7])


def test_the_wheel_bound_by_hand() -> None:
    """psi_y at 0.95 psi_max, omega = 0: the robust box's upper bound on u_y brings psi_y to (1 - margin) psi_max
    in one hold, by hand from psi(t + dt) = psi + u dt; with sensor errors, less the tachometer's and the
    torque noise's bounds (e_psi + e_u dt, docs/noise.md). The plant held at that bound keeps psi_y at or
    below it at every substep (psi is linear in a hold)."""
    x = CFG.scenario("paper-example").x0.copy()
    x[4:7] = 0.0
    psi_max, dt, m = CFG.limits.psi_max_rad_s, CFG.filter.sample_time_s, CFG.filter.zoh_margin
    x[7:10] = (0.0, 0.95 * psi_max, 0.0)
    hi = ConstraintSet(CFG).evaluate(x)["hi"][1]
    assert hi == pytest.approx(((1 - m) * psi_max - x[8]) / dt, rel=1e-12)
    noisy = CFG.with_noise()
    s, b = noisy.sensors, noisy.sensors.bound_sigma
    room = b * s.wheel_speed_noise_rad_s + b * s.torque_noise_rad_s2 * dt
    assert ConstraintSet(noisy).evaluate(x)["hi"][1] == pytest.approx(hi - room / dt, rel=1e-12)
    _, subs = integrate(x, np.array([0.0, hi, 0.0]), dt, plant_record(CFG), CFG.substeps)
    assert np.all(subs[:, 8] <= (1 - m) * psi_max * (1 + 1e-14))
    assert subs[-1, 8] == pytest.approx((1 - m) * psi_max, rel=1e-12)


def test_zoh_box_hand_calculation() -> None:
    """omega_y at 0.9 omega_max, psi_y = 0: the robust box's upper bound on u_y keeps omega_y(t + dt)
    at (1 - margin) omega_max, by hand from omega_y(t + dt) = omega_y + (f_y + G_y u_y) dt (the paper's
    model; the gyrostat's coupled rows: test_zoh_gyrostat)."""
    cfg = CFG.with_models("paper", "paper")
    x = cfg.scenario("paper-example").x0.copy()
    x[4:7] = (0.0, 0.9 * CFG.limits.omega_max_rad_s, 0.0)  # no gyroscopic drift with omega_x = omega_z = 0
    x[7:10] = 0.0
    out = ConstraintSet(cfg.with_preset("robust")).evaluate(x)
    G = CFG.spacecraft.control_gain[1]
    dt = CFG.filter.sample_time_s
    expect = ((1 - CFG.filter.zoh_margin) * CFG.limits.omega_max_rad_s - x[5]) / (G * dt)
    assert out["hi"][1] == pytest.approx(min(expect, CFG.u_max_rad_s2[1]), rel=1e-12)
    paper = ConstraintSet(cfg.with_preset("paper")).evaluate(x)
    np.testing.assert_array_equal(paper["hi"], CFG.u_max_rad_s2)
