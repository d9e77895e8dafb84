"""`limits.wheel_speed_relative_to_body`: the wheel-speed limit on the rotor's speed relative to the body,
|psi_i + omega_i| (psi is the rotor's inertial rate), as a drive's limit is; off, psi itself (the paper's)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.state import OMEGA, PSI
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states

CFG = config.load()
RELATIVE = config.load(overrides={"limits.wheel_speed_relative_to_body": True})


def test_h_judges_the_speed_relative_to_the_body_by_hand() -> None:
    L = CFG.limits
    x = sample_initial_states(20, 7, CFG)[0][:1].copy()
    x[0, PSI] = (L.psi_max_rad_s - 0.005, -(L.psi_max_rad_s - 0.005), 100.0)
    x[0, OMEGA] = (0.01, -0.01, -0.01)
    names = list(CFG.constraint_names)
    i = [names.index(f"psi_{a}") for a in "xyz"]
    inertial = ConstraintSet(CFG).safety_values(x)[0, i]
    relative = ConstraintSet(RELATIVE).safety_values(x)[0, i]
    v = x[0, PSI] + x[0, OMEGA]
    np.testing.assert_allclose(inertial, L.psi_max_rad_s**2 - x[0, PSI] ** 2, rtol=1e-12)
    np.testing.assert_allclose(relative, L.psi_max_rad_s**2 - v**2, rtol=1e-12)
    assert inertial[0] > 0 and relative[0] < 0 and relative[1] < 0  # 0.005 rad/s inside psi_max, 0.005 over it


def test_the_rows_keep_psi_within_psi_max_less_omega_max() -> None:
    """Robust preset: the one-step bound on u keeps the next psi within (1 - zoh_margin) of psi_max - omega_max."""
    L, f = RELATIVE.limits, RELATIVE.filter
    x = sample_initial_states(20, 7, RELATIVE)[0][:1].copy()
    x[0, PSI] = (0.0, 0.0, 0.0)
    box = ConstraintSet(RELATIVE).evaluate(x)
    keep = (1.0 - f.zoh_margin) * (L.psi_max_rad_s - L.omega_max_rad_s)
    hi = np.minimum(keep / f.sample_time_s, RELATIVE.u_max_rad_s2)
    np.testing.assert_allclose(box["hi"][0], np.minimum(hi, box["hi"][0]), rtol=0)  # (the rates may bound it less)
    x[0, PSI] = (keep, 0.0, 0.0)  # at the kept speed: no further outward acceleration
    assert ConstraintSet(RELATIVE).evaluate(x)["hi"][0, 0] <= 1e-9


def _relative_overshoot(cfg: config.Config) -> tuple[float, np.ndarray]:
    """Seed 7's runs 8 and 72 (u_des = 0) on cfg's plant: the most any rotor's speed relative to the body,
    |psi + omega|, passes psi_max (rad/s), and the hard constraints each run violated at a substep."""
    out = run_runs(cfg, sample_initial_states(5000, 7, cfg)[0][[8, 72]], 2000.0, record=True)
    X = out.trajectory
    over = float(np.max(np.abs(X[..., PSI] + X[..., OMEGA])) - cfg.limits.psi_max_rad_s)
    hard = [i for i, n in enumerate(cfg.constraint_names) if n not in cfg.slacked_constraints]
    return over, out.violated_substeps[:, hard]


def test_runs_that_ride_the_wheel_limit_keep_the_relative_speed_with_the_option() -> None:
    """Seed 7's runs 8 and 72 (u_des = 0) hold a wheel at psi_max under the default: read relative to the body
    (the drive's limit) the rotor then runs over it by up to omega_max. With the option the relative speed
    stays within psi_max at every substep, and every other hard constraint holds."""
    over_default, _ = _relative_overshoot(CFG)
    over_relative, violated = _relative_overshoot(RELATIVE)
    assert over_default > 1e-3  # the default's psi at psi_max, the rotor relative to the body over it
    assert over_relative <= 0.0 and not violated.any()


def test_check_config_says_what_the_filter_keeps() -> None:
    r = subprocess.run([sys.executable, "-m", "rta_attitude.cli", "check-config", "-p",
                        "limits.wheel_speed_relative_to_body=true"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "wheel speed: |psi + omega| <= 576 rad/s (relative to the body); the filter keeps |psi| <= 575.983 rad/s" \
        in r.stdout


def test_on_basilisk_the_drives_limit_holds_with_the_option() -> None:
    """The same two runs on Basilisk (an independent plant whose wheel states are rates relative to the body,
    docs/basilisk.md): its rotors' relative speed passes psi_max without the option and stays within it with."""
    pytest.importorskip("Basilisk")
    for cfg, over_limit in ((CFG, True), (RELATIVE, False)):
        over, violated = _relative_overshoot(cfg.with_simulator("basilisk"))
        assert (over > 1e-3) if over_limit else (over <= 0.0)
        assert not violated.any()
