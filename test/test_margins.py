"""Sampled-data margins derived from the vehicle (`constraints.margins`): the bound by hand for the paper's 6U,
and, measured, that a pointing constraint with the derived margin keeps h >= 0 at every RK4 substep while a
PD controller pushes its boresight into the cone, where without a margin the hold overshoots it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rta_attitude import config
from rta_attitude.config.schema import Config, Scenario
from rta_attitude.constraints.margins import derived_margin, sampled_data_margin
from rta_attitude.dynamics.quaternion import attitude_matrices
from rta_attitude.dynamics.state import make_state
from rta_attitude.simulation.closed_loop import simulate

TWELVE_U = {"spacecraft.inertia_kgm2": [0.2, 0.25, 0.15], "spacecraft.wheel_inertia_kgm2": 1e-4,
            "limits.omega_max_deg_s": 2.0}


def test_the_6U_bound_by_hand() -> None:
    """L dt^3 / 6 with L = |B| + 3 W |A| (1 + cot a) + W^3 (1 + 3 cot^2 a) at the 40 deg cone, the rates at
    1 deg/s and the wheels at 576 rad/s, the box U = 18.64 / 37.21 / 47.51 rad/s^2."""
    cfg = config.load()
    J1, J2, J3, D, w, P = 0.022, 0.044, 0.056, 4.1e-5, math.radians(1.0), 576.0
    U = cfg.u_max_rad_s2
    gyro = D * 2 * w * P  # the wheels' gyroscopic torque about each axis, N m
    A = np.array([(abs(J2 - J3) * w * w + gyro) / J1 + D / J1 * U[0],
                  (abs(J3 - J1) * w * w + gyro) / J2 + D / J2 * U[1],
                  (abs(J1 - J2) * w * w + gyro) / J3 + D / J3 * U[2]])
    d = (abs(J2 - J3), abs(J3 - J1), abs(J1 - J2))
    Jv = (J1, J2, J3)
    B = np.array([(d[i] * w * (A[(i + 1) % 3] + A[(i + 2) % 3]) + D * (P * (A[(i + 1) % 3] + A[(i + 2) % 3])
                                                                   + w * (U[(i + 1) % 3] + U[(i + 2) % 3]))) / Jv[i]
                  for i in range(3)])
    W = math.sqrt(3.0) * w + 0.001027
    cot = 1.0 / math.tan(math.radians(40.0))
    L = np.linalg.norm(B) + 3 * W * np.linalg.norm(A) * (1 + cot) + W**3 * (1 + 3 * cot**2)
    assert derived_margin(cfg, cfg.pointing[0], "gyrostat") == pytest.approx(L / 6.0, rel=1e-12)
    assert 0.019 < L / 6.0 < 0.03  # above the 6U's measured-and-tripled margin, as the issue asks
    # the configured margins stay (the paper's configuration, bit for bit); a cone without one derives its own
    assert sampled_data_margin(cfg, cfg.pointing[0].name) == 0.019
    bare = dataclasses.replace(cfg.pointing[0], gains=dataclasses.replace(cfg.pointing[0].gains, margin=None,
                                                                          margin_gyrostat=None))
    assert sampled_data_margin(dataclasses.replace(cfg, pointing=(bare, cfg.pointing[1])), bare.name) == pytest.approx(
        L / 6.0, rel=1e-12)


def _into_the_sun(cfg: Config) -> float:
    """The smallest h of the first cone (the sensor's, 40 deg from the sun) at any RK4 substep while the PD law
    commands the sensor onto the sun from 100 deg away, at five sun angles with the wheels spinning."""
    worst = math.inf
    for k, th in enumerate(np.radians([20.0, 60.0, 100.0, 150.0, 200.0])):
        sun = np.array([math.cos(th), math.sin(th), 0.0])
        gammas = np.linspace(0.0, 2.0 * math.pi, 721)
        qs = np.stack([np.zeros_like(gammas), np.zeros_like(gammas), np.sin(gammas / 2), np.cos(gammas / 2)], axis=1)
        angle = np.arccos(np.clip(attitude_matrices(qs)[:, 0, :] @ sun, -1.0, 1.0))  # +i_B (row 0 of A) to the sun
        start = qs[np.argmin(np.abs(angle - math.radians(100.0)))]
        x0 = make_state(start, psi_rad_s=[300.0 * (-1) ** k, -200.0, 250.0], T_K=270.0, E_J=8000.0, theta_S_rad=th)
        q_c = tuple(float(v) for v in qs[np.argmin(angle)])
        scenario = Scenario(name="into_the_sun", description="", duration_s=300.0, x0=x0, controller="pd",
                            schedule_s=(0.0,), schedule_q=(q_c,))  # type: ignore[arg-type]
        tr = simulate(cfg, scenario)
        worst = min(worst, float(tr.h_substep_min[:, 0].min()))
    return worst


@pytest.mark.parametrize("vehicle", ["6U", "12U"])
def test_the_derived_margin_holds_where_none_overshoots(vehicle: str) -> None:
    base = config.load(overrides=TWELVE_U if vehicle == "12U" else None).with_backup("none")
    out = {}
    for label, m in (("derived", None), ("none", 0.0)):
        cone = dataclasses.replace(base.pointing[0], gains=dataclasses.replace(base.pointing[0].gains, margin=m,
                                                                                margin_gyrostat=m))
        cfg = dataclasses.replace(base, pointing=(cone, base.pointing[1]))
        out[label] = (_into_the_sun(cfg), sampled_data_margin(cfg, cone.name))
    assert out["none"][0] < 0.0  # the hold overshoots the cone without a margin
    worst, margin = out["derived"]
    assert margin > 0.0 and worst >= 0.0  # with the derived margin, never inside the cone
    assert margin - worst > -out["none"][0]  # the overshoot it absorbed is at least the one it prevents
