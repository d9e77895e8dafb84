"""The gatekeeper's records: its parameters (BACKUP_DTYPE, a field of the filter's record) and its memory and
scratch (GATE_DTYPE, in each filter workspace), read by name in compiled code."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import BACKUP_LAWS, MAX_BACKUP_SUBSTEPS, MAX_NOMINAL_STEPS, Config
from rta_attitude.constraints.base import CONE_DTYPE, MAX_CONES, MAX_ROWS, constraint_record, drive_lag
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.dynamics.environment import FIXED_HILL
from rta_attitude.dynamics.quaternion import from_matrix
from rta_attitude.dynamics.sensors import (
    FIELD_SIZE,
    SENSORS_DTYPE,
    sensors_record,
)
from rta_attitude.dynamics.spacecraft import (
    PLANT_DTYPE,
    RK4_WORK_ROWS,
    plant_record,
    wheel_rate_momentum,
)
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter.gatekeeper.law import (
    CONE_CLEARANCE_RAD,
    RATE_LIMIT_FRACTION,
    RATE_TIME_CONSTANT_S,
    RESERVE_STEP_S,
    SETTLED_ANGLE_RAD,
    SETTLED_RATE_FRACTION,
)

Array = NDArray[np.float64]
M = MAX_ROWS


NO_LAW, SUN_SAFE = (BACKUP_LAWS.index(n) for n in ("none", "sun_safe"))
"""Codes of the backup laws (`filter.backup_law`)."""


BACKUP_DTYPE = np.dtype([
    ("law", np.int8),                    # BACKUP_LAWS code (NO_LAW: no gatekeeper)
    ("horizon_steps", np.int64),         # samples of the backup law after the candidate's hold
    ("substeps", np.int64),              # RK4 steps per sample (integrator.substeps)
    ("kp", np.float64),                  # attitude gain of the rate command (controller.kp)
    ("kd", np.float64),                  # rate gain (controller.kd): w_ref = -(kp / kd) dq_v
    ("rate_limit_rad_s", np.float64),    # |w_ref_a| <= this
    ("rate_time_constant_s", np.float64),
    ("settled_sin_half_angle", np.float64),
    ("settled_rate_rad_s", np.float64),
    ("omega_max_rad_s", np.float64),
    ("psi_max_rad_s", np.float64),
    ("psi_limit_rad_s", np.float64),     # the wheel speed the law's targets may use (psi_max; less with sensor errors)
    ("psi_hold_rad_s", np.float64),      # the law keeps each wheel within this (psi_limit less one reading's error)
    ("momentum_variant_rad_s", np.float64),  # the MOMENTUM variant only where |J w - s D psi| / D exceeds this
    ("nominal_steps", np.int64),         # samples of the filter's own answers before the backup law (>= 1)
    ("reserve_steps", np.int64),         # steps of `energy_reserve`'s projection (0: off)
    ("energy_min_J", np.float64),        # E_min: the terminal set keeps the eclipse's floor above it
    ("horizon_at_rest", np.uint8),       # a horizon-only plan must end at rest (filter.backup_horizon_at_rest)
    ("reserve_step_s", np.float64),      # ... each this long
    ("margin", np.float64, (M,)),        # what each h must keep in a rollout (`check_margins`; 0 without sensor errors)
    ("candidate_margin", np.float64, (M,)),  # ... in a candidate's rollout (`apply_measurement_margins`)
    ("interface", SENSORS_DTYPE),        # how the filter receives a state (`sensors.deliver`): plans predict that
    ("dt_s", np.float64),                # the sample
    # the law's frame (`law.law_state`): rows the secondary axis x the sun axis, the secondary axis, the sun axis
    ("permuted", np.uint8),              # 1: the law's frame is not the body frame
    ("permute_wheels", np.uint8),        # 1: and the wheels (on the body axes) turn with it: psi' = P psi, u = P^T u'
    ("law_axes", np.float64, (3, 3)),    # P: the law frame's axes in body axes (a signed permutation)
    ("law_quat", np.float64, (4,)),      # q_P, A(q_P) = P
    ("law_plant", PLANT_DTYPE),          # the filter's plant model in the law's frame (J, D / J permuted)
    ("u_reach_rad_s2", np.float64, (3,)),  # what a drive in any state holds, in the law's frame
    ("secondary", np.float64, (3,)),     # the secondary axis' target, Hill
    ("radiator", np.float64, (3,)),      # the thermal face's normal, in the law's frame
    # the hard pointing constraints the law's target keeps clear of (`law.keep_cones`)
    ("n_keep", np.int64),
    ("keep", np.int64, (MAX_CONES,)),    # their cones in `cones`
    ("keep_axes", np.float64, (MAX_CONES, 3)),  # their boresights in the law's frame
    ("cones", CONE_DTYPE, (MAX_CONES,)),  # the cone table (`constraints.base`)
    ("cone_clearance_rad", np.float64),  # law.CONE_CLEARANCE_RAD
])  # fmt: skip
"""The gatekeeper's parameters (a field of the filter's record)."""


GATE_DTYPE = np.dtype([
    ("plan_steps", np.int64),            # samples the committed plan is still verified for (0: none)
    ("drive", np.float64, (3,)),         # the wheel drive's state as the filter's commands left it, rad/s^2
    # (`pipeline.drive_command`; 0 at rest, and where the lag is not compensated)
    ("inflight", np.float64, (3,)),      # the last answer as the wheels hold it: over the transport delay
    ("x_delay", np.float64, (STATE_SIZE,)),  # the state at the delay's end the call plans from (`drive`)
    ("plan_n", np.int64),                # samples of the committed nominal plan (0: none) ...
    ("plan_at", np.int64),               # ... the one the next call should be at
    ("plan_x", np.float64, (MAX_NOMINAL_STEPS, STATE_SIZE)),  # its states at the samples (as received)
    ("plan_u", np.float64, (MAX_NOMINAL_STEPS, 3)),           # the filter's answers there (candidates)
    ("nominal_wait", np.int64),          # calls to wait before the next nominal plan is tried
    ("filtered_wait", np.int64),         # calls to wait before the backup law through the filter is tried again
    ("filtered_backoff", np.int64),      # ... the wait after its next failure (doubles, to FILTERED_BACKOFF_MAX)
    ("filtered_tries", np.int64),        # calls that tried the backup law through the filter (since reset)
    ("next_x", np.float64, (STATE_SIZE,)),  # the committed plan's state at the next sample, as the filter will
    # receive it (`sensors.deliver` of the prediction)
    ("has_next", np.uint8),              # ... next_x is set
    ("plan_settled", np.uint8),          # the committed plan reaches the terminal set (holds for good)
    ("in_terminal", np.uint8),           # the last state on a settled plan was in the terminal set
    ("plan_weak", np.uint8),             # the committed plan is safe to its horizon but short of the energy reserve
    ("weak_law", np.int8),               # the last `verify`'s first variant safe to the horizon without the
    # energy reserve (-1: none), its command and its state after the first sample (`commit_weak`)
    ("weak_u", np.float64, (3,)),
    ("weak_x", np.float64, (STATE_SIZE,)),
    ("first_x", np.float64, (STATE_SIZE,)),  # the last rollout's state after its first sample
    ("x0", np.float64, (STATE_SIZE,)),   # the state the call's rollouts start from
    ("t_call", np.float64),              # the call's time, s from the run's start: where its rollouts start
    ("t", np.float64),                   # the rollout's clock at its sample's start (`hold_sample`)
    ("reused", np.int64),                # calls answered from a committed plan without a rollout (since reset)
    ("checked", np.int64),               # substeps the last rollout checked
    ("x", np.float64, (STATE_SIZE,)),    # the rollout's state at the samples
    ("u", np.float64, (3,)),             # the command of the rollout's sample
    ("us", np.float64, (3,)),            # the command across the torque interface, saturated
    ("u_backup", np.float64, (3,)),      # the backup law's command at the filter's state
    ("h", np.float64, (M,)),
    ("hard_rows", np.int64, (M,)),       # the rows a rollout's sample checks (`rows.hard`), n_hard of them,
    ("hard_margin", np.float64, (M,)),   # and what each must keep (`rollout.rollout_margin`)
    ("n_hard", np.int64),
    ("subs", np.float64, (MAX_BACKUP_SUBSTEPS, STATE_SIZE)),
    ("work", np.float64, (RK4_WORK_ROWS, STATE_SIZE)),
    ("ctx", CONTEXT_DTYPE),
    ("A", np.float64, (3, 3)),
    ("fields", np.float64, (FIELD_SIZE,)),  # scratch of `sensors.deliver`
    ("target", np.float64, (3, 3)),      # the sun-safe attitude, rows i_B, j_B, k_B in Hill
    ("Hh", np.float64, (3,)),            # the body's angular momentum J w - s D psi in Hill, N m s
    ("load", np.float64),                # `_wheel_load` of the sun-safe target
    ("momentum_mode", np.uint8),         # 1: the target is the momentum mode's; 2: the tilted sun-safe one;
    # 3: the Earth-side one with a large momentum (EARTH_SIDE); 0: a terminal set may apply (`settled`)
    ("law", np.uint8),                   # the variant the rollout and the command use (VARIANTS)
    ("plan_law", np.uint8),              # the variant of the committed plan
    ("q_c", np.float64, (4,)),
    ("dq", np.float64, (3,)),
    ("wd", np.float64, (3,)),
    ("ua", np.float64, (3,)),            # the body's angular acceleration the law asks of u (`_rate_command`)
    ("candidate", np.uint8),             # the rollout checks a candidate: h >= candidate_margin (else margin)
    ("xm", np.float64, (STATE_SIZE,)),   # the law's state at the middle of its hold (`_rate_command`)
    ("answer_lasted", np.int64),         # this `gate` call: the most substeps a failed rollout of the answer checked
    ("backup_lasted", np.int64),         # ... of a failed rollout of a variant's own command, that command:
    ("longest_u", np.float64, (3,)),     # GATE_TOWARD_BACKUP's u_des
    ("xl", np.float64, (STATE_SIZE,)),   # the law's state, in its frame (`law.law_state`)
    ("ul", np.float64, (3,)),            # the law's command, in its frame
    ("xa", np.float64, (STATE_SIZE,)),   # a state ahead (`law._clear_ahead`)
    ("trial", np.float64, (3, 3)),       # `law.keep_cones`: a candidate target and the best so far
    ("best", np.float64, (3, 3)),
    ("base", np.float64, (3, 3)),        # `law.keep_cones`: the roll about the sun line the tilts turn
    ("plan_command", np.float64, (3,)),  # a settled plan's next command, before its sample is known to hold
])  # fmt: skip
"""The gatekeeper's memory (plan_steps) and scratch (one per filter workspace)."""


def backup_record(cfg: Config) -> NDArray[np.void]:
    """The BACKUP_DTYPE record (1,) of a configuration."""
    rec = np.zeros(1, BACKUP_DTYPE)
    b = rec[0]
    o, L = cfg.filter, cfg.limits
    b["law"] = BACKUP_LAWS.index(o.backup_law)
    b["horizon_steps"] = max(1, round(o.backup_horizon_s / o.sample_time_s))
    b["substeps"] = cfg.substeps
    b["kp"], b["kd"] = cfg.controller.kp, cfg.controller.kd
    b["rate_limit_rad_s"] = RATE_LIMIT_FRACTION * L.omega_max_rad_s
    b["rate_time_constant_s"] = RATE_TIME_CONSTANT_S
    b["settled_sin_half_angle"] = math.sin(0.5 * SETTLED_ANGLE_RAD)
    b["settled_rate_rad_s"] = SETTLED_RATE_FRACTION * L.omega_max_rad_s
    b["omega_max_rad_s"], b["psi_max_rad_s"] = L.omega_max_rad_s, L.psi_max_rad_s
    b["psi_limit_rad_s"] = cfg.psi_keep_rad_s
    b["psi_hold_rad_s"] = cfg.psi_keep_rad_s
    b["nominal_steps"] = max(1, round(o.backup_nominal_s / o.sample_time_s))
    b["reserve_step_s"] = RESERVE_STEP_S
    b["reserve_steps"] = round(o.backup_energy_lookahead_s / RESERVE_STEP_S)
    b["energy_min_J"] = L.energy_min_J
    b["horizon_at_rest"] = o.backup_horizon_at_rest
    b["interface"] = sensors_record(cfg)[0]
    b["dt_s"] = o.sample_time_s
    sun = np.array(o.backup_sun_axis_body)
    second = np.array(o.backup_secondary_axis_body)
    P = np.array([np.cross(second, sun), second, sun])
    P = P + 0.0  # (no -0.0)
    b["law_axes"] = P
    b["permuted"] = not np.array_equal(P, np.eye(3))
    q = np.zeros(4)
    from_matrix(P, q)
    b["law_quat"] = q
    perm = np.abs(P)
    plant = plant_record(cfg, o.model)[0]
    # wheel i holds (A^-1 H)_i / D at rest, plus its rates' share: every |H| up to this fits every wheel in any
    # attitude (the largest row norm of A^-1 is 1 with the wheels on the body axes)
    most = max(wheel_rate_momentum(plant, i) for i in range(3))  # the largest over the wheels (any axis order)
    spread = float(np.max(np.linalg.norm(cfg.spacecraft.wheel_axes_inverse, axis=1)))
    b["momentum_variant_rad_s"] = (cfg.psi_keep_rad_s
                                   - most * L.omega_max_rad_s / cfg.spacecraft.wheel_inertia_kgm2) / spread
    # wheels on the body axes turn with the frame (each stays on its axis); other wheels keep their order, and
    # their axes turn instead (A' = P A, G' = P G)
    b["permute_wheels"] = b["permuted"] and cfg.spacecraft.wheels_on_body_axes
    if b["permuted"]:
        plant["inertia_kgm2"] = perm @ plant["inertia_kgm2"]
        plant["control_gain"] = perm @ plant["control_gain"]
        for key in ("inertia_matrix", "inertia_inverse"):  # tensors turn as P M P^T
            plant[key] = P @ plant[key] @ P.T + 0.0
        if b["permute_wheels"]:
            plant["control_matrix"] = P @ plant["control_matrix"] @ P.T + 0.0
        else:
            plant["control_matrix"] = P @ plant["control_matrix"] + 0.0
            plant["wheel_axes"] = P @ plant["wheel_axes"] + 0.0
            plant["wheel_axes_inverse"] = plant["wheel_axes_inverse"] @ P.T + 0.0
    b["law_plant"] = plant
    reach = (1.0 - 2.0 * drive_lag(cfg)[0]) * cfg.u_max_rad_s2  # (as `constraints.base.constraint_record`)
    b["u_reach_rad_s2"] = perm @ reach if b["permute_wheels"] else reach
    b["secondary"] = FIXED_HILL[o.backup_secondary_target]
    b["radiator"] = P @ np.array(cfg.thermal.face_normal_body)
    hard = [j for j, c in enumerate(cfg.pointing) if c.gains.enabled and not c.gains.slack_weight > 0]
    b["n_keep"] = len(hard)
    for k, j in enumerate(hard):
        b["keep"][k] = j
        b["keep_axes"][k] = P @ np.array(cfg.pointing[j].boresight_body)
    b["cones"] = constraint_record(cfg)[0]["cones"]
    b["cone_clearance_rad"] = CONE_CLEARANCE_RAD
    return rec
