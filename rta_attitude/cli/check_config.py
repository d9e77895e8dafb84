"""`rta-attitude check-config`: validate a parameter file (or an overlay) and print what it sets.

Exit 1 (one `ERROR:` line each) if the file or any scenario does not validate; warnings (`WARNING:` lines, exit
0) for what is valid but will not hold: a scenario whose initial state already violates a constraint, a
backup attitude that puts a configured cone inside itself at some sun geometry (`filter.gatekeeper`)."""

from __future__ import annotations

import argparse
import math
import sys

from rta_attitude.cli.options import add_config_arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude check-config`."""
    add_config_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """`rta-attitude check-config`."""
    from dataclasses import replace

    import numpy as np

    from rta_attitude.cli.options import load
    from rta_attitude.config.schema import EARTH_RADIUS_M, spanning
    from rta_attitude.constraints import ConstraintSet
    from rta_attitude.constraints.margins import (
        derived_margin,
        inertia_accel_bound,
        robust_inertia_uncertainty,
        sampled_data_margin,
    )
    from rta_attitude.constraints.registry import registry
    from rta_attitude.constraints.windows import ramp_start

    cfg = load(args)
    array = cfg.spacecraft.n_wheels != 3
    if array:  # the filter over the array (`filter.wheel_array`): its margins are its virtual vehicle's
        from rta_attitude.filter.wheel_array import check_array

        check_array(cfg)
    model = cfg.body_model
    print(f"{cfg.source}: ok")
    print(f"  preset {cfg.filter.preset}, fallback {cfg.filter.fallback}, dt {cfg.filter.sample_time_s} s, "
          f"{cfg.substeps} RK4 substeps")
    print(f"  plant model {cfg.spacecraft.model}, filter model {cfg.filter.model}, gatekeeper {cfg.filter.backup_law}")
    print(f"  admissible |u| <= {np.array2string(cfg.u_max_rad_s2, precision=2)} rad/s^2 "
          f"({', '.join(cfg.spacecraft.wheel_names)})")
    if array:
        print(f"  {cfg.spacecraft.n_wheels} wheels: the filter's QP is over their accelerations, the body's rows "
              f"through A; its margins take the body acceleration they can give, |A| U <= "
              f"{model.limits.wheel_accel_max_rad_s2:.4g} rad/s^2 on an axis")
    sc = cfg.spacecraft
    if not sc.principal:
        moments, axes = np.linalg.eigh(sc.inertia_matrix)
        off = np.degrees(np.arccos(np.minimum(1.0, np.abs(axes).max(axis=0))))  # each axis to its nearest body axis
        print(f"  products of inertia: principal moments {', '.join(f'{m:.6g}' for m in moments)} kg m^2, their axes "
              f"{', '.join(f'{a:.3g}' for a in off)} deg from the nearest body axes; every wheel turns every axis")
    if not sc.wheels_on_body_axes:
        off = np.degrees(np.arccos(np.minimum(1.0, np.abs(sc.wheel_axes).max(axis=0))))
        smallest = spanning(sc.wheel_axes)
        print(f"  wheels' spin axes {', '.join(f'{a:.3g}' for a in off)} deg from the nearest body axes (the axes' "
              f"smallest singular value {smallest:.3g}); every wheel turns every axis")
    if sc.control_lost:
        print(f"  WARNING: {sc.control_lost}: the filter keeps u = 0 on the failed wheel and holds what the others can")
    delta = robust_inertia_uncertainty(model)
    if delta > 0.0:
        worst = inertia_accel_bound(model, cfg.filter.model)
        print(f"  inertia within +-{100 * delta:g} % of the configured: the rows allow up to "
              f"{', '.join(f'{v:.2g}' for v in worst)} rad/s^2 of angular acceleration error (x, y, z; at the "
              f"rate and wheel limits)")
    if cfg.plant.inertia_kgm2 is not None:
        off = 100.0 * (np.array(cfg.plant.inertia_kgm2) / cfg.spacecraft.J - 1.0)
        outside = " (outside it)" if np.max(np.abs(off)) > 100.0 * delta else ""
        print(f"  the simulated vehicle's inertia (plant.inertia_kgm2) is {', '.join(f'{v:+.3g}' for v in off)} % off "
              f"the filter's model (x, y, z); the filter allows +-{100 * delta:g} %{outside}")
    if cfg.delay_substeps:
        print(f"  transport delay {cfg.spacecraft.transport_delay_s:g} s ({cfg.delay_substeps} of {cfg.substeps} "
              f"substeps): the filter plans from the state {cfg.spacecraft.transport_delay_s:g} s after each sample")
    L = cfg.limits
    if L.wheel_speed_relative_to_body:
        print(f"  wheel speed: |psi + omega| <= {L.psi_max_rad_s:g} rad/s (relative to the body); the filter keeps "
              f"|psi| <= {cfg.psi_keep_rad_s:.6g} rad/s")
    print(f"  pointing constraints ({len(cfg.pointing)}):")
    for c in cfg.pointing:
        b = ", ".join(f"{v:g}" for v in c.boresight_body)
        target = c.target if c.target_vector is None else f"{c.target} [{', '.join(f'{v:g}' for v in c.target_vector)}]"
        slack = f", slack weight {c.gains.slack_weight:g}" if c.gains.slack_weight else ""
        print(f"    {c.name}: {c.kind} [{b}] from {target}, half-angle {math.degrees(c.half_angle_rad):g} deg{slack}")
        bound = derived_margin(model, c, cfg.filter.model)
        if c.gains.sampled_data_margin(cfg.filter.model) is None:
            print(f"      sampled-data margin {sampled_data_margin(model, c.name):.3g} rad (derived from the vehicle, "
                  f"{cfg.filter.model} model)")
        else:
            print(f"      sampled-data margin {sampled_data_margin(model, c.name):.3g} rad (configured; the derived "
                  f"bound is {bound:.3g} rad)")
        for start, end in c.windows_s:
            t_on = ramp_start(cfg, c, start)
            print(f"      window [{start:g}, {end:g}] s: the barrier tightens from t = {t_on:.1f} s")
    env = cfg.environment
    if env.eclipse:
        if env.eclipse_s > 0.0:
            peak, need = cfg.power.peak_W, cfg.eclipse_power_W
            print(f"  eclipse: {env.eclipse_s:.0f} s of the {env.orbit_period_s:.0f} s orbit (altitude "
                  f"{(env.orbit_radius_m - EARTH_RADIUS_M) / 1e3:.0f} km, beta {math.degrees(env.sun_beta_rad):g} "
                  f"deg): the battery needs {cfg.eclipse_energy_J:.0f} J above E_min where the shadow begins, "
                  f"charged at {cfg.eclipse_ramp_W:.3g} W over the sunlit arc (the panel within "
                  f"{math.degrees(math.acos(need / peak)):.1f} deg of the sun)")
            if env.sun_beta_rad != 0.0:  # the longest eclipse of this orbit is at beta 0
                longest = replace(env, sun_beta_rad=0.0).eclipse_s
                print(f"    the longest eclipse of this orbit (beta 0): {longest:.0f} s, "
                      f"{cfg.power.load_W * longest:.0f} J above E_min")
        else:
            print(f"  eclipse: none at beta {math.degrees(env.sun_beta_rad):g} deg (the orbit stays in sunlight)")
    print(f"  priority levels: {' > '.join('+'.join(level) for level in cfg.priority_levels)}")
    print(f"  slacked: {', '.join(cfg.slacked_constraints) or 'none'}")
    print(f"  scenarios: {', '.join(s.replace('_', '-') for s in cfg.scenarios)}")
    constraints = registry(cfg)  # (names and units: any number of wheels)
    for name, scenario in cfg.scenarios.items():
        run_cfg = cfg.for_scenario(scenario)
        if array:
            from rta_attitude.filter.wheel_array import ArraySafety
            from rta_attitude.simulation.array_loop import array_state

            h = ArraySafety(run_cfg).values(array_state(run_cfg, scenario.x0), 0.0)
        else:
            h = ConstraintSet(run_cfg).safety_values(scenario.x0, 0.0)
        for i, c in enumerate(constraints):
            if h[i] < 0:
                print(f"WARNING: scenario {name}: the initial state violates {c.name} (h = {h[i]:.4g} {c.unit})",
                      file=sys.stderr)
    if cfg.filter.backup_law != "none":
        from rta_attitude.filter.gatekeeper.law import backup_attitude_conflicts

        o = cfg.filter
        for name, worst_deg, ranges in backup_attitude_conflicts(cfg):
            where = ", ".join(f"[{a:.0f}, {b:.0f}]" for a, b in ranges)
            side = "outside" if cfg.pointing_constraint(name).keep_in else "inside"
            print(f"WARNING: the backup attitude ({_axis(o.backup_sun_axis_body)} on the sun, "
                  f"{_axis(o.backup_secondary_axis_body)} toward {o.backup_secondary_target}) puts {name} {side} "
                  f"its cone (h down to {worst_deg:.1f} deg) for theta_S in {where} deg: there the backup law rolls "
                  f"about the sun line or turns the panel off the sun to keep it clear (docs/backup.md)",
                  file=sys.stderr)
    for message in cfg.scenario_errors.values():
        print(f"ERROR: {message}", file=sys.stderr)
    return 1 if cfg.scenario_errors else 0


def _axis(v: tuple[float, float, float]) -> str:
    """A signed body axis as +x, -y, ..."""
    i = max(range(3), key=lambda a: abs(v[a]))
    return f"{'+' if v[i] > 0 else '-'}{'xyz'[i]}"


__all__ = ["add_arguments", "run"]
