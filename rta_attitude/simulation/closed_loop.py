"""Sampled-data closed loop: controller -> filter -> zero-order hold -> RK4 plant, compiled.

At each sample t_k = k dt: u_des = controller(x_k, q_c(t_k)) crosses the torque interface (u -> tau =
D u -> u), as over DDS; u = filter(x_k, u_des) (or u_des without RTA), across the interface again;
the sensors and the actuator (`dynamics.sensors`: exact unless `sensors.enabled`) give the controller
and the filter the measured state y_k and the plant the actuated command; the actuator saturates u at
psi_dot_max; the plant holds it over [t_k, t_k + dt] with `substeps` RK4
steps (`dynamics.spacecraft.rk4_delayed`: with a transport delay, the previous command over its first
substeps); the safety values of every substep are kept, so violations
between samples are seen. `advance` is that step (filter, actuator, plant, checks) for one state:
`simulate` and the Monte Carlo (`montecarlo.runner`) both run it, so a Monte Carlo run equals
`simulate` of its initial state bit for bit, and the nodes run its parts (the filter node
`filter_state`, the plant node `integrate`), so a lockstep run over DDS equals it too.

Parameters: one LOOP_DTYPE record (the true plant, the filter with its own plant model, the
controller, RTA on/off, dt and substeps).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config, Scenario
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.rows import safety_values
from rta_attitude.dynamics.controller import (
    CONTROLLER_DTYPE,
    PrimaryController,
    checked_command,
    controller_record,
    desired_command,
    pd_command,
)
from rta_attitude.dynamics.plant import Plant, make_plant, simulated_model
from rta_attitude.dynamics.sensors import (
    INSTRUMENT_DTYPE,
    SENSORS_DTYPE,
    Instruments,
    actuate,
    read,
    sensors_record,
)
from rta_attitude.dynamics.spacecraft import (
    PLANT_DTYPE,
    RK4_WORK_ROWS,
    attitude_matrix,
    control_accel,
    demand_round_trip,
    omega_dot,
    omega_drift,
    plant_record,
    rk4_delayed,
    saturate,
    saturated,
    torque_round_trip,
    torque_to_wheels,
    wheel_accel_to_torque,
    wheels_to_torque,
)
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter.asif import AsifFilter, FilterResult
from rta_attitude.filter.pipeline import filter_state
from rta_attitude.filter.records import FILTER_DTYPE, RESULT_DTYPE, WORKSPACE_DTYPE, WORKSPACES, filter_record
from rta_attitude.jit import JIT, LEAF
from rta_attitude.simulation.trajectory import Trajectory, substep_minima

if TYPE_CHECKING:
    from rta_attitude.simulation.array_loop import ArrayLoop

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

LOOP_DTYPE = np.dtype([
    ("plant", PLANT_DTYPE),          # the spacecraft that is simulated
    ("filter", FILTER_DTYPE),        # the filter, with its own model of the plant
    ("controller", CONTROLLER_DTYPE),
    ("sensors", SENSORS_DTYPE),      # what the controller and the filter read, what the wheels do
    ("rta", np.uint8),               # 0: u_des goes to the plant unfiltered
    ("dt_s", np.float64),            # sample time (zero-order hold)
    ("substeps", np.int64),          # RK4 steps per sample
])  # fmt: skip


def loop_record(cfg: Config, rta: bool = True, pd: bool = True) -> NDArray[np.void]:
    """The LOOP_DTYPE record (1,) of a configuration (pd False: no primary controller, u_des = 0)."""
    rec = np.zeros(1, LOOP_DTYPE)
    rec[0]["plant"] = plant_record(cfg)[0]
    rec[0]["filter"] = filter_record(cfg)[0]
    rec[0]["controller"] = controller_record(cfg, pd)[0]
    rec[0]["sensors"] = sensors_record(cfg)[0]
    rec[0]["rta"], rec[0]["dt_s"], rec[0]["substeps"] = rta, cfg.filter.sample_time_s, cfg.substeps
    return rec


@numba.njit(**JIT)
def advance(x: Array, y: Array, u_des: Array, k: int, lp: np.void, ins: np.void, ws: NDArray[np.void], r: np.void,
            u: Array,
            subs: Array, hs: Array, ctx: np.void, work: Array) -> None:
    """Sample k (t = k dt) of the loop from the true state x (19,), read as y (`sensors.read`: measured, then
    across the message interface), with the
    desired command u_des (3,), already across the torque interface: filter of y at t (result r) if RTA,
    torque interface, the actuator (`sensors.actuate`, instruments ins) and its saturation (u), RK4 hold
    of x (subs (substeps, 19): the states after each substep, the last is x(t + dt)) and the safety
    values of every substep at its time (hs (substeps, m)). work: `rk4_work()` scratch."""
    p = lp.plant
    t = k * lp.dt_s
    if lp.rta:
        filter_state(y, u_des, t, lp.filter, ws, r)
        torque_round_trip(r.u, p, u)
    else:
        for a in range(3):
            u[a] = u_des[a]
    actuate(u, k, lp.sensors, ins, u)
    saturate(u, p, u)
    rk4_delayed(x, ins.u_inflight, u, lp.dt_s, lp.substeps, p, subs, work)
    for a in range(3):
        ins.u_inflight[a] = u[a]
    for j in range(lp.substeps):
        safety_values(subs[j], t + lp.dt_s * (j + 1) / lp.substeps, p, lp.filter.constraints, ctx, hs[j])


@numba.njit(**LEAF)
def command_row(times: Array, t_s: float) -> int:
    """Row of the command schedule in force at t_s (numpy.searchsorted(side='right') - 1, at least 0)."""
    k = 0
    while k < times.shape[0] and times[k] <= t_s:
        k += 1
    return max(k - 1, 0)


@numba.njit(**JIT)
def run_scenario(x0: Array, steps: int, sched_t: Array, sched_q: Array, loop: NDArray[np.void], X: Array,
                 Y: Array, H: Array, Hsub: Array, Q_C: Array, U_DES: Array, U: Array, W_DOT: Array,
                 R: NDArray[np.void]) -> None:
    """Simulate `steps` samples from x0 with the controller tracking the command schedule (sched_t (K,),
    sched_q (K, 4)); fills X (steps + 1, 19) (the truth), H (steps + 1, m) at the samples, Hsub (steps,
    substeps, m), the measured states Y, Q_C, U_DES, U, W_DOT (steps, ...) and the filter results R (steps,)."""
    lp = loop[0]
    p = lp.plant
    ins = np.zeros(1, INSTRUMENT_DTYPE)
    ws = np.zeros(WORKSPACES, WORKSPACE_DTYPE)
    ctx = np.zeros(1, CONTEXT_DTYPE)
    u_des, yd = np.empty(3), np.empty(STATE_SIZE)
    A, wd = np.empty((3, 3)), np.empty(3)
    subs = np.empty((lp.substeps, STATE_SIZE))
    work = np.zeros((RK4_WORK_ROWS, STATE_SIZE))
    X[0] = x0
    safety_values(X[0], 0.0, p, lp.filter.constraints, ctx[0], H[0])
    for k in range(steps):
        t = k * lp.dt_s
        Q_C[k] = sched_q[command_row(sched_t, t)]
        read(X[k], k, lp.sensors, ins[0], Y[k], yd)
        pd_command(yd, Q_C[k], lp.controller, u_des)
        demand_round_trip(u_des, p, U_DES[k])
        advance(X[k], yd, U_DES[k], k, lp, ins[0], ws, R[k], U[k], subs, Hsub[k], ctx[0], work)
        attitude_matrix(X[k, 0], X[k, 1], X[k, 2], X[k, 3], A)
        omega_drift(X[k], A, p, wd)
        for a in range(3):
            W_DOT[k, a] = control_accel(wd, U[k], p, a)
        X[k + 1] = subs[lp.substeps - 1]
        H[k + 1] = Hsub[k, lp.substeps - 1]


class ClosedLoop:
    """Controller + optional filter + plant for one scenario; `run()` it.

    Args:
        cfg: configuration.
        scenario: the scenario (initial state, controller, command schedule, duration).
        rta: filter on (True) or u_des passed straight to the plant.
    """

    def __init__(self, cfg: Config, scenario: Scenario, rta: bool = True) -> None:
        self.cfg = cfg.for_scenario(scenario)
        self.scenario = scenario
        self.rta = rta
        self.filter = AsifFilter(self.cfg)  # also compiles (or loads) the kernels
        self.loop = loop_record(self.cfg, rta, pd=scenario.controller == "pd")

    def run(self, dt_s: float | None = None) -> Trajectory:
        """Simulate the whole scenario; dt defaults to filter.sample_time_s. The compiled simulator runs
        `run_scenario`; another (`plant.simulator`) runs `run_stepped` over `dynamics.plant.make_plant`."""
        cfg = self.cfg
        lp = self.loop.copy()
        if dt_s is not None:
            lp[0]["dt_s"] = dt_s
        dt = float(lp[0]["dt_s"])
        n = round(self.scenario.duration_s / dt)
        if cfg.plant.simulator == "compiled":
            run = StepArrays.empty(n, cfg.substeps, len(cfg.constraint_names))
            sched_t = np.asarray(self.scenario.schedule_s, dtype=float)
            sched_q = np.ascontiguousarray(self.scenario.schedule_q, dtype=float)
            run_scenario(np.ascontiguousarray(self.scenario.x0, dtype=float), n, sched_t, sched_q, lp, run.x,
                         run.y, run.h, run.h_sub, run.q_c, run.u_des, run.u, run.omega_dot, run.results)
            if self.rta:
                self.filter.counters.add(run.results)
        else:
            with make_plant(cfg, self.scenario.x0, dt) as plant:
                run = run_stepped(cfg, self.scenario, n, plant, self.filter if self.rta else None)
        return self._trajectory(run, dt)

    def _trajectory(self, run: StepArrays, dt: float) -> Trajectory:
        cfg = self.cfg
        n = run.u.shape[0]
        R = run.results
        t = dt * np.arange(n + 1)
        h_min, h_arg = substep_minima(run.h[:-1], np.moveaxis(run.h_sub, 1, 0), t[:-1], dt)
        res = FilterResult(R, cfg.filter.fallback, cfg.priority_levels, cfg.constraint_names)
        if self.rta:
            status, fallback = res.status, res.fallback
            bc, slack, inter, box = res.bc, res.slack, res.intervening, res.box_active
        else:
            status, fallback = np.full(n, "off"), np.full(n, "")
            m = len(cfg.constraint_names)
            bc, slack, inter, box = (np.zeros((n, m)), np.zeros((n, m)), np.zeros((n, m), dtype=bool),
                                     np.zeros((n, 3), dtype=bool))
        return Trajectory(
            names=cfg.constraint_names, t_s=t, x=run.x, q_c=run.q_c, u_des=run.u_des, u=run.u, omega_dot=run.omega_dot,
            h=run.h, h_substep_min=h_min, h_substep_argmin_s=h_arg, bc=bc, slack=slack, intervening=inter,
            box_active=box, status=np.asarray(status, dtype=str), fallback=np.asarray(fallback, dtype=str),
            iterations=R["iterations"].copy() if self.rta else np.zeros(n, dtype=np.int64),
            solve_time_s=np.zeros(n), rta=self.rta, preset=cfg.filter.preset, scenario=self.scenario.name,
            meta={"config": cfg.source, "dt_s": dt, "substeps": cfg.substeps},
            y=run.y if cfg.sensors.enabled else None,
        )  # fmt: skip


@dataclass
class StepArrays:
    """What a closed-loop run records, step by step (N steps, S substeps, m constraints).

    Attributes:
        x: true states at the samples (N + 1, 19); h: safety values there (N + 1, m).
        y: the measured states (N, 19) (= x[:-1] without sensor errors); the controller and the filter
            read them across the message interface (`sensors.deliver`).
        h_sub: safety values after each substep (N, S, m) (the last is the next sample).
        q_c (N, 4), u_des, u, omega_dot (N, 3): command, desired and applied wheel accelerations
            (u after saturation), body angular acceleration at each step's start (the plant's model).
        results: the filter's RESULT_DTYPE records (N,) (zeros without RTA).
    """

    x: Array
    y: Array
    h: Array
    h_sub: Array
    q_c: Array
    u_des: Array
    u: Array
    omega_dot: Array
    results: NDArray[np.void]

    @classmethod
    def empty(cls, steps: int, substeps: int, m: int) -> StepArrays:
        """Arrays for `steps` steps of `substeps` substeps and m constraints (results zeroed)."""
        return cls(np.empty((steps + 1, STATE_SIZE)), np.empty((steps, STATE_SIZE)), np.empty((steps + 1, m)),
                   np.empty((steps, substeps, m)),
                   np.empty((steps, 4)), np.empty((steps, 3)), np.empty((steps, 3)), np.empty((steps, 3)),
                   np.zeros(steps, RESULT_DTYPE))


def run_stepped(cfg: Config, scenario: Scenario, steps: int, plant: Plant, filt: AsifFilter | None,
                stream: int = 0, command: PrimaryController | None = None) -> StepArrays:
    """The closed loop of `run_scenario`, one Python step at a time over any plant (`dynamics.plant`):
    at each sample the sensors (`dynamics.sensors.Instruments`), the primary controller (the PD law
    `pd_command` if the scenario has it, or `command`), the torque interface, the filter
    (`AsifFilter.filter`, if given), the interface again, the actuator and its limit, `plant.step`, and the safety
    values of every substep. Over `CompiledPlant` it equals `run_scenario` bit for bit (tested).

    Args:
        cfg: configuration (the scenario's slack weights applied: `Config.for_scenario`).
        scenario: command schedule and controller; the plant already starts at its x0.
        steps: samples to run.
        plant: the plant, at the scenario's initial state.
        filt: the filter; None: u_des goes to the plant unfiltered.
        stream: the sensors' noise sequence (the Monte Carlo: the run's index).
        command: a primary controller in Python in place of the scenario's, `PrimaryController`: u_des =
            command(y, q_c, t_s), the wheel accelerations (3,) in rad/s^2 that `pd_command` would give,
            from the measured state y (19,) as the filter reads it, the commanded attitude q_c (4,) of the
            scenario's schedule and the time t_s (copies: the loop's arrays are not the function's to change).

    Raises:
        ControllerError: `command` returned anything but 3 finite numbers.
    """
    S = cfg.substeps
    run = StepArrays.empty(steps, S, len(cfg.constraint_names))
    ctrl = controller_record(cfg, scenario.controller == "pd")
    truth = simulated_model(cfg)
    constraints = ConstraintSet(cfg)
    D = cfg.spacecraft.wheel_inertia_kgm2
    sched_t = np.asarray(scenario.schedule_s, dtype=float)
    sched_q = np.ascontiguousarray(scenario.schedule_q, dtype=float)
    instruments = Instruments(cfg, stream)
    run.x[0] = plant.x
    run.h[0] = constraints.safety_values(plant.x, 0.0)
    dt = plant.dt_s
    sub_t = dt * np.arange(1, S + 1) / S
    for k in range(steps):
        x = run.x[k]
        run.y[k] = instruments.measure(x, k)
        y = instruments.deliver(run.y[k])
        run.q_c[k] = sched_q[command_row(sched_t, k * plant.dt_s)]
        if command is None:
            u_des = desired_command(y, run.q_c[k], ctrl)
        else:
            u_des = checked_command(command(y.copy(), run.q_c[k].copy(), k * dt), k * dt)
        run.u_des[k] = torque_to_wheels(wheel_accel_to_torque(u_des, D), truth)
        if filt is not None:
            result = filt.filter(y, run.u_des[k], k * dt)
            run.results[k] = result.record
            u = torque_to_wheels(wheels_to_torque(result.u, truth), truth)
        else:
            u = run.u_des[k]
        run.u[k] = saturated(instruments.actuate(u, k), truth)
        run.omega_dot[k] = omega_dot(x, run.u[k], truth)
        x_next, subs = plant.step(run.u[k])
        run.h_sub[k] = constraints.safety_values(subs, k * dt + sub_t)
        run.x[k + 1] = x_next
        run.h[k + 1] = run.h_sub[k, -1]
    return run


def simulate(cfg: Config, scenario: str | Scenario, rta: bool = True, preset: str | None = None,
             duration_s: float | None = None) -> Trajectory:
    """Run a scenario (by name or object) in process, no DDS.

    Args:
        cfg: configuration.
        scenario: scenario name (e.g. 'paper-example') or object.
        rta: filter on (True) or u_des passed straight to the plant.
        preset: override the filter preset ('robust' or 'paper').
        duration_s: override the scenario's duration, s.
    """
    if preset is not None:
        cfg = cfg.with_preset(preset)
    scen = cfg.scenario(scenario) if isinstance(scenario, str) else scenario
    if duration_s is not None:
        scen = replace(scen, duration_s=float(duration_s))
    return closed_loop(cfg, scen, rta).run()


def closed_loop(cfg: Config, scenario: Scenario, rta: bool = True) -> ClosedLoop | ArrayLoop:
    """The closed loop of cfg's wheels: `ClosedLoop` (compiled) for three, `array_loop.ArrayLoop` (the filter over
    the array, stepped in Python) for more."""
    if cfg.spacecraft.n_wheels != 3:
        from rta_attitude.simulation.array_loop import ArrayLoop

        return ArrayLoop(cfg, scenario, rta)
    return ClosedLoop(cfg, scenario, rta)


def compile_kernels(cfg: Config) -> float:
    """Compile (or load from numba's cache) every kernel the closed loop, the nodes and the Monte Carlo
    run, by one step of a scenario. Returns the seconds it took."""
    import time

    from rta_attitude.kernel_cache import drop_stale_caches

    t0 = time.perf_counter()
    drop_stale_caches()
    name = next(iter(cfg.scenarios))
    simulate(cfg, name, duration_s=cfg.filter.sample_time_s)
    saturated(np.zeros(3), simulated_model(cfg))  # the stepped loop's and the plant node's actuator
    return time.perf_counter() - t0


__all__ = ["LOOP_DTYPE", "ClosedLoop", "StepArrays", "Trajectory", "advance", "closed_loop", "command_row",
           "compile_kernels",
           "loop_record", "run_scenario", "run_stepped", "simulate"]
