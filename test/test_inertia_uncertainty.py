"""`spacecraft.inertia_uncertainty`: the robust preset's rows hold for any vehicle whose principal moments are
within +-delta of the configured ones (docs/conventions.md, "Inertia")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.base import constraint_record, inertia_error
from rta_attitude.dynamics.spacecraft import omega_dot, plant_record
from rta_attitude.errors import ConfigError
from rta_attitude.montecarlo.sampling import sample_initial_states

DELTA = 0.01
CFG = config.load()
ROBUST = config.load(overrides={"spacecraft.inertia_uncertainty": DELTA})


def _with_inertia(cfg: config.Config, J: np.ndarray) -> config.Config:
    """cfg with principal moments J and no uncertainty: the 'true' vehicle."""
    sc = replace(cfg.spacecraft, inertia_kgm2=tuple(float(v) for v in J), inertia_uncertainty=0.0)
    return replace(cfg, spacecraft=sc)


def _true_inertias(rng: np.random.Generator, n: int) -> np.ndarray:
    """n inertias within +-DELTA of the configured one: the 8 corners of the box, then random points in it."""
    J = CFG.spacecraft.J
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    inside = rng.uniform(-1.0, 1.0, (max(0, n - 8), 3))
    return J * (1.0 + DELTA * np.vstack([corners, inside])[:n])


def test_the_uncertainty_is_checked_at_load() -> None:
    for bad in (-0.01, 0.5, float("nan")):
        with pytest.raises(ConfigError, match=r"spacecraft\.inertia_uncertainty"):
            config.load(overrides={"spacecraft.inertia_uncertainty": bad})


def test_the_acceleration_error_bound_holds_against_the_true_vehicle() -> None:
    """At 300 random states (wheels up to psi_max), any u in the box and 20 true inertias within +-1 % (the 8
    corners among them), the true vehicle's omega_dot (the plant's equations with its J) is within
    `inertia_error` of the model's on every axis; and the bound is not idle (at a corner it is within 3x of the
    largest error found)."""
    rng = np.random.default_rng(3)
    x = sample_initial_states(300, 7, CFG)[0]
    p = plant_record(ROBUST)
    c = constraint_record(ROBUST)
    U = ROBUST.u_max_rad_s2
    u = rng.uniform(-1.0, 1.0, (300, 3)) * U
    model = omega_dot(x, u, p)
    drift = omega_dot(x, np.zeros(3), p)
    bound = np.array([[inertia_error(c[0], p[0], x[k, 4:7], drift[k], a) for a in range(3)] for k in range(300)])
    worst = np.zeros(3)
    for J in _true_inertias(rng, 20):
        err = np.abs(omega_dot(x, u, plant_record(_with_inertia(CFG, J))) - model)
        assert np.all(err <= bound * (1.0 + 1e-9) + 1e-15), float(np.max(err - bound))
        worst = np.maximum(worst, np.max(err / bound, axis=0))
    assert np.all(worst > 1.0 / 3.0), worst


def test_a_robust_row_implies_the_true_vehicles_row() -> None:
    """For every row u reaches through omega_dot (cones, temperature, battery, rates), the robust row's
    condition drift + gain . u >= 0 implies the true vehicle's (its rows computed with its J): at 200 states,
    20 true inertias and 50 u in the box each, the true row's value is never below the robust one's. The wheel
    speeds' rows (psi_dot = u whatever J is) are the same on both."""
    rng = np.random.default_rng(5)
    x = sample_initial_states(200, 7, CFG)[0]
    robust = ConstraintSet(ROBUST).evaluate(x)
    names = list(ROBUST.constraint_names)
    psi = [names.index(f"psi_{a}") for a in "xyz"]
    others = [i for i in range(len(names)) if i not in psi]
    u = rng.uniform(-1.0, 1.0, (50, 3)) * ROBUST.u_max_rad_s2
    gap = np.inf
    for J in _true_inertias(rng, 20):
        true = ConstraintSet(_with_inertia(ROBUST, J)).evaluate(x)
        bc_true = true["drift"][:, :, None] + np.einsum("kia,ua->kiu", true["gain"], u)
        bc_robust = robust["drift"][:, :, None] + np.einsum("kia,ua->kiu", robust["gain"], u)
        scale = 1e-9 * (1.0 + np.abs(bc_true))
        assert np.all(bc_true[:, others] >= bc_robust[:, others] - scale[:, others])
        np.testing.assert_array_equal(true["gain"][:, psi], robust["gain"][:, psi])
        gap = min(gap, float(np.min(bc_true[:, others] - bc_robust[:, others])))
    assert gap < 1e-3 * float(np.max(np.abs(robust["drift"][:, others])))  # tight somewhere, not idle


def test_no_uncertainty_changes_nothing() -> None:
    """delta = 0 (the default) and the paper preset: the rows are the model's own."""
    x = sample_initial_states(50, 7, CFG)[0]
    plain = ConstraintSet(CFG).evaluate(x)
    paper = ConstraintSet(config.load(preset="paper", overrides={"spacecraft.inertia_uncertainty": DELTA})).evaluate(x)
    paper0 = ConstraintSet(config.load(preset="paper")).evaluate(x)
    assert np.all(constraint_record(CFG)["inertia_error_gain"] == 0.0)
    for field in ("drift", "gain", "lo", "hi"):
        np.testing.assert_array_equal(paper[field], paper0[field])
    robust = ConstraintSet(ROBUST).evaluate(x)
    assert np.all(robust["drift"] <= plain["drift"])  # the robust rows ask more, never less
