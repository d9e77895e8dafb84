"""The filter's records: its parameters (FILTER_DTYPE: the filter's plant model, the constraints, the policy and
solver settings, the gatekeeper's), one call's result (RESULT_DTYPE, one state or a batch), and its scratch and
memory (WORKSPACE_DTYPE, `new_workspace`). Per-constraint arrays hold MAX_ROWS rows (the capacity); a
configuration uses its n_rows of them."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.base import (
    CONSTRAINT_DTYPE,
    MAX_ROWS,
    TABLE_DTYPE,
    constraint_record,
    drive_lag,
)
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.registry import levels
from rta_attitude.dynamics.spacecraft import PLANT_DTYPE, plant_record
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter import active_set, outcome
from rta_attitude.filter.gatekeeper.records import BACKUP_DTYPE, GATE_DTYPE, backup_record
from rta_attitude.filter.gatekeeper.rollout import apply_measurement_margins

Array = NDArray[np.float64]
M = MAX_ROWS


FILTER_DTYPE = np.dtype([
    ("plant", PLANT_DTYPE),                  # the filter's model of the spacecraft
    ("constraints", CONSTRAINT_DTYPE),
    ("policy", np.int8),                     # outcome.FALLBACKS code
    ("solver", np.int8),                     # outcome.SOLVERS code
    ("backup_solver", np.int8),              # outcome.BACKUP_SOLVERS code (proxsuite only)
    ("check_tolerance", np.float64),         # a solution must meet every row to this
    ("soften_weight", np.float64),           # slack weight of every row in the soften fallback
    ("max_active_set_iter", np.int64),
    ("eps_abs", np.float64),                 # proxsuite settings
    ("eps_primal_inf", np.float64),
    ("eps_dual_inf", np.float64),
    ("max_iterations", np.int64),
    ("max_inner_iterations", np.int64),
    ("backup", BACKUP_DTYPE),                # the gatekeeper (backup law NO_LAW: off)
    ("level", np.int64, (M,)),               # priority level of each constraint (0: most important)
    ("n_levels", np.int64),
    ("lag_gain", np.float64),                # the drive's lag compensated: c and e of `constraints.base.drive_lag`
    ("lag_decay", np.float64),               # (0: not compensated)
])  # fmt: skip
"""Everything one filter call reads, by name."""


RESULT_DTYPE = np.dtype([
    ("u", np.float64, (3,)),                 # u_act, rad/s^2, the command sent: finite, inside U
    ("u_held", np.float64, (3,)),            # the filter's answer: what the wheels hold over the sample (u
    # but where the drive's lag is compensated: `drive_command`)
    ("u_des", np.float64, (3,)),             # as received
    ("h", np.float64, (M,)),                 # physical h at x
    ("psi0", np.float64, (M,)),              # HOCBF levels at x
    ("psi1", np.float64, (M,)),
    ("bc", np.float64, (M,)),                # barrier conditions at u (slack not included)
    ("slack", np.float64, (M,)),             # delta_i of slacked rows
    ("intervening", np.uint8, (M,)),         # rows active at the solution
    ("uncontrollable", np.uint8, (M,)),      # rows violated whatever u is (no gradient in u)
    ("box_active", np.uint8, (3,)),          # axes the box clipped
    ("lo", np.float64, (3,)),                # the box
    ("hi", np.float64, (3,)),
    ("status", np.int8),                     # outcome.STATUS_NAMES code
    ("fallback", np.int8),                   # outcome.FALLBACK_REASONS code
    ("solver", np.int8),                     # the solver of the first QP (outcome.SOLVERS code)
    ("solve_result", np.int8),               # outcome.SOLVE_RESULTS code of the first QP, NOT_SOLVED if none
    ("backup_result", np.int8),              # quadprog's re-solve of it (proxsuite), NOT_SOLVED if none
    ("soft_result", np.int8),                # the soften fallback's QP, NOT_SOLVED if none
    ("qp_failed", np.uint8),                 # the first QP failed (the policy acted)
    ("raise_error", np.uint8),               # policy `raise` and the QP failed: Python raises
    ("gate", np.int8),                       # outcome.GATE_NAMES code: what the gatekeeper did
    ("gave_way", np.int8),                   # prioritize: the most important level that gave way (NO_LEVEL)
    ("iterations", np.int64),                # solver iterations of every solve of the call
    ("solves", np.int64),                    # QP solves of the call (a proxsuite solve and its re-solve: one)
    ("solve_time_s", np.float64),            # wall time of the whole call (set by the Python face)
])  # fmt: skip
"""What one filter call did, for one state (a batch: a leading axis)."""


WORKSPACE_DTYPE = np.dtype([
    ("ctx", CONTEXT_DTYPE),
    ("table", TABLE_DTYPE),
    ("x", np.float64, (STATE_SIZE,)),        # the state, quaternion normalised
    ("lo0", np.float64, (3,)),               # what the drive can hold this call (`drive_box`; the rows' box)
    ("hi0", np.float64, (3,)),
    ("u_target", np.float64, (3,)),          # u_des with non-finite entries set to 0
    ("gnorm", np.float64, (M,)),             # |dBC/du| of each row
    ("gate", GATE_DTYPE),                    # the gatekeeper's committed plan and scratch (memory!)
    ("result", RESULT_DTYPE),                # scratch: the answers the gatekeeper's nominal plan predicts
])  # fmt: skip
"""Scratch and memory of one filter: a WORKSPACES-long array (`new_workspace`); the call uses the first,
the gatekeeper's nominal plan runs the filter's own answers in the second."""


WORKSPACES = 2


def filter_record(cfg: Config) -> NDArray[np.void]:
    """The FILTER_DTYPE record (1,) of a configuration."""
    rec = np.zeros(1, FILTER_DTYPE)
    f = rec[0]
    f["plant"] = plant_record(cfg, cfg.filter.model)[0]
    f["constraints"] = constraint_record(cfg)[0]
    o = cfg.filter
    f["policy"] = outcome.FALLBACKS.index(o.fallback)
    f["solver"] = outcome.SOLVERS.index(o.solver)
    f["backup_solver"] = outcome.BACKUP_SOLVERS.index(o.backup_solver)
    f["check_tolerance"], f["soften_weight"] = o.check_tolerance, o.soften_weight
    f["max_active_set_iter"] = active_set.MAX_ACTIVE_SET_ITER
    f["eps_abs"], f["eps_primal_inf"], f["eps_dual_inf"] = o.eps_abs, o.eps_primal_inf, o.eps_dual_inf
    f["max_iterations"], f["max_inner_iterations"] = o.max_iterations, o.max_inner_iterations
    f["backup"] = backup_record(cfg)[0]
    f["level"][: len(cfg.constraint_names)] = levels(cfg)
    f["n_levels"] = len(cfg.priority_levels)
    f["lag_gain"], f["lag_decay"] = drive_lag(cfg)
    apply_measurement_margins(rec, cfg)  # the backup law inside its rollouts' margins (sensor errors on)
    return rec


def new_workspace() -> NDArray[np.void]:
    """A workspace record array (WORKSPACES,): scratch, and the gatekeeper's plan (none yet)."""
    return np.zeros(WORKSPACES, WORKSPACE_DTYPE)
