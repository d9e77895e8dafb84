"""The closed loop of a vehicle with an array of N wheels (any N, `spacecraft.wheel_spin_axes_body`), stepped in
Python over the compiled plant: the primary's body command split over the wheels (its minimum-norm split, as
the torque interface does), the filter over the array (`filter.wheel_array`), the actuator's limit, the RK4
hold, and the safety values of every substep. What `simulate` runs where the wheels are not three (`ArrayLoop`).

A scenario states three wheel speeds (the paper's wheels on the body axes): an array starts holding the same
momentum, D psi on the body axes, split by its working wheels' minimum-norm split (psi = A^+ psi_3; a failed
wheel starts at rest: it spun down before the run).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config, Scenario
from rta_attitude.dynamics.controller import controller_record, desired_command
from rta_attitude.dynamics.plant import make_plant, simulated_model
from rta_attitude.dynamics.spacecraft import omega_dot, saturated, torque_to_wheels, wheel_accel_to_torque
from rta_attitude.dynamics.state import PSI, STATE_SIZE, state_size, wheel_columns
from rta_attitude.filter.wheel_array import ArrayFilter, ArraySafety
from rta_attitude.simulation.closed_loop import command_row
from rta_attitude.simulation.trajectory import Trajectory, substep_minima

Array = NDArray[np.float64]


def array_state(cfg: Config, x0: Array) -> Array:
    """The array's state (16 + N,) holding the momentum of a three-wheel state x0 (19,): the body entries of x0,
    the working wheels' speeds A_w^+ psi (x0's wheels on the body axes), a failed wheel's 0."""
    x0 = np.asarray(x0, dtype=float)
    n = cfg.spacecraft.n_wheels
    if x0.shape == (state_size(n),) and n != 3:
        return x0.copy()
    x = np.zeros(state_size(n))
    x[:STATE_SIZE] = x0
    work = ~cfg.spacecraft.wheel_failed  # a failed wheel starts at rest (it spun down before the run)
    cols = np.array(wheel_columns(n))
    x[cols] = 0.0
    x[cols[work]] = np.linalg.pinv(cfg.spacecraft.wheel_axes[:, work]) @ x0[PSI]
    return x


class ArrayLoop:
    """Controller + optional filter over the array + plant for one scenario; `run()` it (`ClosedLoop`'s face:
    `closed_loop.closed_loop` gives whichever the wheels need).

    Raises:
        ConfigError: rta and the array's filter does not take the configuration (`wheel_array.check_array`).
    """

    def __init__(self, cfg: Config, scenario: Scenario, rta: bool = True, filt: ArrayFilter | None = None,
                 safety: ArraySafety | None = None) -> None:
        """filt, safety: the filter and safety values of cfg for this scenario, made once by a caller that runs
        many states (the filter over an array keeps no memory from one run to the next)."""
        self.cfg = cfg.for_scenario(scenario)
        self.scenario = scenario
        self.rta = rta
        self.filter = (filt or ArrayFilter(self.cfg)) if rta else None
        self.safety = safety or ArraySafety(self.cfg)

    def run(self) -> Trajectory:
        """Simulate the whole scenario (see the module docstring)."""
        cfg, scenario, filt, safety = self.cfg, self.scenario, self.filter, self.safety
        truth = simulated_model(cfg)
        ctrl = controller_record(cfg, scenario.controller == "pd")
        D = cfg.spacecraft.wheel_inertia_kgm2
        n_w = cfg.spacecraft.n_wheels
        dt, S = cfg.filter.sample_time_s, cfg.substeps
        steps = round(scenario.duration_s / dt)
        sched_t = np.asarray(scenario.schedule_s, dtype=float)
        sched_q = np.ascontiguousarray(scenario.schedule_q, dtype=float)
        m = len(safety.names)
        x = np.empty((steps + 1, state_size(n_w)))
        h = np.empty((steps + 1, m))
        h_sub = np.empty((steps, S, m))
        q_c, u_des = np.empty((steps, 4)), np.empty((steps, n_w))
        u, w_dot = np.empty((steps, n_w)), np.empty((steps, 3))
        bc, slack = np.zeros((steps, m)), np.zeros((steps, m))
        inter, box = np.zeros((steps, m), dtype=bool), np.zeros((steps, n_w), dtype=bool)
        status, fallback = np.full(steps, "off", dtype=object), np.full(steps, "", dtype=object)
        iterations = np.zeros(steps, dtype=np.int64)
        x[0] = array_state(cfg, scenario.x0)
        h[0] = safety.values(x[0], 0.0)
        sub_t = dt * np.arange(1, S + 1) / S
        with make_plant(cfg, x[0], dt) as plant:
            for k in range(steps):
                t = k * dt
                q_c[k] = sched_q[command_row(sched_t, t)]
                body = desired_command(x[k, :STATE_SIZE], q_c[k], ctrl)
                u_des[k] = torque_to_wheels(wheel_accel_to_torque(body, D), truth)
                if filt is not None:
                    r = filt.filter(x[k], u_des[k], t)
                    u_k = r.u
                    bc[k], slack[k], inter[k], box[k] = r.bc, r.slack, r.intervening, r.box_active
                    status[k], fallback[k], iterations[k] = r.status, r.fallback, r.iterations
                else:
                    u_k = u_des[k]
                u[k] = saturated(u_k, truth)
                w_dot[k] = omega_dot(x[k], u[k], truth)
                x[k + 1], subs = plant.step(u[k])
                h_sub[k] = safety.values(subs, t + sub_t)
                h[k + 1] = h_sub[k, -1]
        ts = dt * np.arange(steps + 1)
        h_min, h_arg = substep_minima(h[:-1], np.moveaxis(h_sub, 1, 0), ts[:-1], dt)
        return Trajectory(
            names=safety.names, t_s=ts, x=x, q_c=q_c, u_des=u_des, u=u, omega_dot=w_dot, h=h, h_substep_min=h_min,
            h_substep_argmin_s=h_arg, bc=bc, slack=slack, intervening=inter, box_active=box,
            status=status.astype(str), fallback=fallback.astype(str), iterations=iterations,
            solve_time_s=np.zeros(steps), rta=self.rta, preset=cfg.filter.preset, scenario=scenario.name,
            meta={"config": cfg.source, "dt_s": dt, "substeps": S, "wheels": list(cfg.spacecraft.wheel_names)},
        )


__all__ = ["ArrayLoop", "array_state"]
