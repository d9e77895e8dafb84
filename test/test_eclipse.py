"""The Earth's shadow (`environment.eclipse`): its arc against the cylinder computed with vectors, the plant in it,
the battery's eclipse floor against times found by stepping the orbit, the battery row against finite
differences, a configuration that cannot recharge refused, and the example's slew into the shadow."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import random_states, sun_safe_state

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.battery import eclipse_floors
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.quaternion import attitude_matrices
from rta_attitude.dynamics.state import ENERGY, TEMP, THETA_S
from rta_attitude.errors import ConfigError
from rta_attitude.filter.gatekeeper.rollout import is_settled
from rta_attitude.filter.records import filter_record
from rta_attitude.simulation.closed_loop import simulate
from rta_attitude.simulation.metrics import summarize_trajectory

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "config" / "examples" / "eclipse.yaml"
CFG = config.load(EXAMPLE)
R_EARTH_M = 6_378_137.0
MU_M3_S2 = 3.986004418e14


def _in_shadow(theta_S: np.ndarray, beta: float, n: float) -> np.ndarray:
    """The cylinder with vectors: the spacecraft at a x_Hill, behind the Earth and within R_E of the Earth-sun
    line."""
    a = (MU_M3_S2 / n**2) ** (1 / 3)
    s = np.stack([math.cos(beta) * np.cos(theta_S), math.cos(beta) * np.sin(theta_S),
                  np.full_like(theta_S, math.sin(beta))], axis=-1)
    r = np.array([a, 0.0, 0.0])
    along = s @ r
    off = np.linalg.norm(r - along[:, None] * s, axis=-1)
    return (along < 0) & (off < R_EARTH_M)


@pytest.mark.parametrize("beta_deg", [0.0, 30.0, 55.0, 65.0])
def test_the_shadow_arc_is_the_cylinders(beta_deg: float) -> None:
    cfg = config.load(EXAMPLE, overrides={"environment.sun_beta_deg": beta_deg})
    env = cfg.environment
    theta = np.linspace(0.0, 2 * math.pi, 400_001)[:-1]
    shadow = _in_shadow(theta, math.radians(beta_deg), env.mean_motion_rad_s)
    measured_s = shadow.mean() * env.orbit_period_s
    assert abs(env.eclipse_s - measured_s) < 2 * env.orbit_period_s / len(theta)
    if beta_deg == 0.0:  # 852 km: the Earth's half-angle 61.9 deg, a 2,104 s eclipse of the 6,118 s orbit
        assert 2100 < env.eclipse_s < 2110 and 6110 < env.orbit_period_s < 6125
    if beta_deg == 65.0:  # beyond the Earth's angular radius: no eclipse
        assert env.eclipse_s == 0.0 and not shadow.any()
    # the plant's sunlit test on the same grid
    p = spacecraft.plant_record(cfg)
    x = np.zeros((len(theta[::1000]), 19))
    x[:, 3], x[:, THETA_S], x[:, TEMP], x[:, ENERGY] = 1.0, theta[::1000], 280.0, 5000.0
    f = spacecraft.state_derivative(x, np.zeros((len(x), 3)), p)
    dark = _in_shadow(theta[::1000], math.radians(beta_deg), env.mean_motion_rad_s)
    np.testing.assert_array_equal(f[dark, ENERGY], -cfg.power.load_W)  # no charge in the shadow


def test_in_the_shadow_the_panel_charges_nothing_and_the_sun_heats_nothing() -> None:
    """Panel and thermal face toward the sun's line at theta_S = pi (deep in the shadow): E falls at the load,
    and T changes only by the Earth's infrared and the face's own radiation."""
    p = spacecraft.plant_record(CFG)
    x = np.zeros(19)
    x[THETA_S], x[TEMP], x[ENERGY] = math.pi, 290.0, 5000.0
    # the body's -j_B face and +k_B panel toward -x_Hill (the sun's line at theta_S = pi; the Earth there too)
    x[0:4] = (-0.5, 0.5, -0.5, 0.5)
    f = spacecraft.state_derivative(x, np.zeros(3), p)
    assert f[ENERGY] == -CFG.power.load_W
    th, env = CFG.thermal, CFG.environment
    A = attitude_matrices(x[None, 0:4])[0]
    face = A @ np.array([-1.0, 0.0, 0.0])  # the Earth's direction in body axes
    c_e = float(np.dot(face, th.face_normal_body))
    ir = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * env.earth_view_factor * max(0.0, c_e) \
        * env.earth_temperature_K**4
    out = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * x[TEMP] ** 4
    assert f[TEMP] == pytest.approx((ir - out) / (th.mass_kg * th.specific_heat_J_kgK), rel=1e-12)


def test_the_floor_is_what_the_load_needs_through_the_shadow_ahead() -> None:
    """At theta_S across the orbit, the times to the shadow's end (inside it) and to its start (outside) found by
    stepping the orbit 0.5 s at a time with the vector cylinder: in the shadow the floor is the load times the
    time left; outside, the eclipse's energy less eclipse_ramp_W times the time to the shadow."""
    env, L = CFG.environment, CFG.power.load_W
    n, beta, dt = env.mean_motion_rad_s, env.sun_beta_rad, 0.5
    t = np.arange(0.0, env.orbit_period_s + 10.0, dt)
    rng = np.random.default_rng(5)
    theta0 = rng.uniform(0.0, 2 * math.pi, 60)
    floors = eclipse_floors(theta0, spacecraft.plant_record(CFG)[0])
    eclipse_energy = L * env.eclipse_s
    for th0, floor in zip(theta0, floors):
        dark = _in_shadow(th0 - n * t, beta, n)
        if dark[0]:
            expect = L * t[np.argmin(dark)]  # the first sunlit step
        else:
            expect = eclipse_energy - CFG.eclipse_ramp_W * t[np.argmax(dark)]
        assert floor == pytest.approx(expect, abs=2 * dt * L + 1e-6)
    # continuous where the shadow begins (the eclipse's energy) and where it ends (nothing left)
    a = env.eclipse_half_arc_rad
    p = spacecraft.plant_record(CFG)[0]
    start = eclipse_floors(np.array([math.pi + a + 1e-9, math.pi + a - 1e-9]), p)
    end = eclipse_floors(np.array([math.pi - a + 1e-9, math.pi - a - 1e-9]), p)
    np.testing.assert_allclose(start, eclipse_energy, atol=1e-3)
    np.testing.assert_allclose(end, 0.0, atol=1e-3)


def test_the_battery_row_with_an_eclipse_against_finite_differences() -> None:
    """Psi_1 = d/dt Psi_0 + k1 Psi_0 and BC = d/dt Psi_1 + k2 Psi_1 + bias along x_dot = f + g u, central
    differences, at random states in and out of the shadow (away from its edges and the barrier's kinks)."""
    cs = ConstraintSet(CFG)
    p = spacecraft.plant_record(CFG)
    rng = np.random.default_rng(11)
    x = random_states(rng, 3000, CFG)
    a = CFG.environment.eclipse_half_arc_rad
    th = x[:, THETA_S] % (2 * math.pi)
    edge = np.minimum(np.abs(th - (math.pi - a)), np.abs(th - (math.pi + a)))
    panel = cs.angles(x)["panel_sun"]
    x = x[(edge > 1e-3) & (panel > 0.02) & (np.abs(panel - math.pi / 2) > 0.02) & (panel < math.pi - 0.02)][:800]
    th = x[:, THETA_S] % (2 * math.pi)
    dark = np.abs(th - math.pi) < a
    assert dark.sum() > 100 and (~dark).sum() > 100
    u = rng.uniform(-1, 1, (len(x), 3)) * CFG.u_max_rad_s2
    xdot = spacecraft.state_derivative(x, u, p)
    i = cs.names.index("battery")
    g = CFG.gains("battery")
    eps = 1e-5

    def level(name: str, z: np.ndarray) -> np.ndarray:
        return getattr(cs.evaluate(z), name)[:, i]

    tab = cs.evaluate(x)
    dpsi0 = (level("psi0", x + eps * xdot) - level("psi0", x - eps * xdot)) / (2 * eps)
    expect = dpsi0 + g.k1 * tab.psi0[:, i]
    np.testing.assert_array_less(np.abs(tab.psi1[:, i] - expect), 1e-5 * (1e-6 + np.abs(expect)) + 1e-6)
    dpsi1 = (level("psi1", x + eps * xdot) - level("psi1", x - eps * xdot)) / (2 * eps)
    bc = tab.drift[:, i] + np.einsum("nk,nk->n", tab.gain[:, i], u)
    expect = dpsi1 + g.k2 * tab.psi1[:, i] + g.bias
    assert np.quantile(np.abs(bc - expect) / (np.abs(expect) + np.abs(tab.drift[:, i]) + 1e-9), 0.99) < 1e-5
    # in the shadow the row's floor falls as E does: Psi_0's E - floor part has no time derivative
    assert np.allclose(xdot[dark, ENERGY], -CFG.power.load_W)


def test_a_panel_that_cannot_recharge_the_eclipse_is_refused_in_one_line() -> None:
    """The paper's 6U (22.7 W panel, 15 W load) in the 852 km orbit: 31.6 kJ to carry through 2,104 s of shadow
    needs 7.9 W more than the load over the 4,014 s of sunlight, 22.9 W in all."""
    with pytest.raises(ConfigError, match=r"^environment\.eclipse: the panel \(22.7 W on the sun\) cannot recharge"):
        config.load(overrides={"environment.eclipse": True})
    config.load(overrides={"environment.eclipse": True, "environment.sun_beta_deg": 65.0})  # no shadow: fine


def test_the_example_slews_into_the_shadow_with_the_energy_it_needs() -> None:
    """The example's PD (identity, then a half turn about j) would hold the panel off the sun; the filter keeps E
    above E_min plus the eclipse's floor at every sample, so the battery carries the load through the 2,104 s
    shadow and ends above E_min. The same commands unfiltered enter the shadow with less than it needs."""
    tr = simulate(CFG, "into-the-shadow")
    summary = summarize_trajectory(tr, CFG.for_scenario(CFG.scenario("into-the-shadow")))
    assert summary["safe"], summary["violated"]
    p = spacecraft.plant_record(CFG)[0]
    floor = eclipse_floors(tr.x[:, THETA_S], p)
    E_min = CFG.limits.energy_min_J
    assert np.all(tr.x[:, ENERGY] - E_min >= floor)
    entry = int(np.argmax(np.abs(tr.x[:, THETA_S] % (2 * math.pi) - math.pi) < CFG.environment.eclipse_half_arc_rad))
    assert 900 < tr.t_s[entry] < 1100 and tr.x[-1, THETA_S] % (2 * math.pi) < math.pi - 0.9  # through it
    off = simulate(replace(CFG, filter=replace(CFG.filter, backup_law="none")), "into-the-shadow", rta=False)
    assert off.x[entry, ENERGY] - E_min < CFG.eclipse_energy_J


def test_the_backup_laws_terminal_set_keeps_the_energy_for_the_shadow_ahead() -> None:
    """At rest on the sun just before the shadow, the sun-safe attitude is a terminal set only with the eclipse's
    energy in the battery: with less, the panel on the sun cannot charge it in time and the shadow drains it."""
    f = filter_record(CFG)
    a = CFG.environment.eclipse_half_arc_rad
    E_min, need = CFG.limits.energy_min_J, CFG.eclipse_energy_J
    before = math.pi + a + 0.02  # 19 s of sunlight left
    floor = float(eclipse_floors(np.array([before]), spacecraft.plant_record(CFG)[0])[0])
    assert need - 60.0 < floor < need
    assert is_settled(sun_safe_state(before, E_min + floor + 1.0), f)
    assert not is_settled(sun_safe_state(before, E_min + floor - 1.0), f)
    # the same state without the eclipse is in the terminal set; and far from the shadow, little is needed
    sunlit_all_orbit = config.load(EXAMPLE, overrides={"environment.eclipse": False})
    assert is_settled(sun_safe_state(before, E_min + 100.0), filter_record(sunlit_all_orbit))
    assert is_settled(sun_safe_state(math.pi - a - 0.1, E_min + 300.0), f)  # 97 s after the shadow: 255 J


def test_check_config_states_what_the_eclipse_needs() -> None:
    r = subprocess.run([sys.executable, "-m", "rta_attitude.cli", "check-config", "--config", str(EXAMPLE), "-p",
                        "environment.sun_beta_deg=30"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    env = config.load(EXAMPLE, overrides={"environment.sun_beta_deg": 30.0}).environment
    assert f"  eclipse: {env.eclipse_s:.0f} s of the 6118 s orbit (altitude 852 km, beta 30 deg)" in r.stdout
    assert "    the longest eclipse of this orbit (beta 0): 2104 s, 10521 J above E_min" in r.stdout
    r = subprocess.run([sys.executable, "-m", "rta_attitude.cli", "check-config", "-p", "environment.eclipse=true"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1 and r.stdout == "" and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.startswith("ERROR: environment.eclipse: the panel (22.7 W on the sun) cannot recharge")
