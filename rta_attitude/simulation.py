"""Sampled-data closed loop: controller -> filter -> zero-order hold -> RK4 plant.

At each sample t_k = k dt: u_des = controller(x_k, q_c(t_k)); u_act = filter(x_k, u_des) (or u_des
without RTA); both cross the torque interface (u -> tau = D u -> u), exactly as over DDS; the plant
saturates u at psi_dot_max and integrates x over [t_k, t_k + dt] with `substeps` RK4 steps,
renormalising the quaternion after each. Every substep's constraint values are kept, so
violations between samples are seen.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import model, plant_kernel
from .asif import AsifFilter, FilterResult
from .constraints import ConstraintSet
from .controller import pd_command, zero_command
from .params import Config, Scenario
from .state import Q

Array = NDArray[np.float64]
log = logging.getLogger(__name__)


def rk4_step(x: Array, u: Array, h_s: float, cfg: Config) -> Array:
    """One classical RK4 step of length h_s (s) with u held; x (..., 19), u (..., 3)."""
    k1 = model.state_derivative(x, u, cfg)
    k2 = model.state_derivative(x + 0.5 * h_s * k1, u, cfg)
    k3 = model.state_derivative(x + 0.5 * h_s * k2, u, cfg)
    k4 = model.state_derivative(x + h_s * k3, u, cfg)
    out = x + (h_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    out[..., Q] /= np.linalg.norm(out[..., Q], axis=-1, keepdims=True)
    return out


def saturate(u: Array, cfg: Config) -> Array:
    """The actuator: wheel accelerations clipped to +-psi_dot_max (..., 3)."""
    limit = cfg.limits.wheel_accel_max_rad_s2
    return np.clip(u, -limit, limit)


def integrate(x: Array, u: Array, dt_s: float, cfg: Config, substeps: int | None = None) -> tuple[Array, Array]:
    """Hold u over dt_s. Returns (x at t + dt (..., 19), the substep states (substeps, ..., 19)).

    Each state runs through the compiled `plant_kernel.integrate_hold`, which performs the
    operations of `rk4_step` (and `model.state_derivative`) in the same order: the same numbers,
    ~100x faster on one state.
    """
    n = substeps or cfg.substeps
    u = saturate(np.asarray(u, dtype=float), cfg)
    x = np.asarray(x, dtype=float)
    lead = x.shape[:-1]
    X = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
    U = np.ascontiguousarray(np.broadcast_to(u, (*lead, 3)).reshape(-1, 3))
    K = _plant_parameters(cfg)
    out = np.empty((X.shape[0], n, X.shape[1]))
    for k in range(X.shape[0]):
        plant_kernel.integrate_hold(X[k], U[k], float(dt_s), n, K, out[k])
    subs = np.moveaxis(out, 1, 0).reshape((n, *lead, x.shape[-1]))
    return subs[-1].copy(), subs


_PLANT_PARAMETERS: dict[int, tuple[Config, Array]] = {}
"""plant_kernel parameter vectors by id(cfg) (the Config is kept, so its id stays its own)."""


def _plant_parameters(cfg: Config) -> Array:
    hit = _PLANT_PARAMETERS.get(id(cfg))
    if hit is None or hit[0] is not cfg:
        if len(_PLANT_PARAMETERS) > 64:
            _PLANT_PARAMETERS.clear()
        hit = _PLANT_PARAMETERS[id(cfg)] = (cfg, plant_kernel.plant_parameters(cfg))
    return hit[1]


def substep_minima(h_start: Array, h_substeps: Array, t_s: Array, dt_s: Array) -> tuple[Array, Array]:
    """Minimum of h over each step (its start sample and its RK4 substeps) and when it occurs.

    Args:
        h_start: h at the start of each step (..., m).
        h_substeps: h at the substeps (substeps, ..., m); the last one is the next sample.
        t_s: start time of each step (...), s.
        dt_s: length of each step (...) or a scalar, s.

    Returns:
        (h_min (..., m), time of the minimum (..., m) in s).
    """
    n_sub = h_substeps.shape[0]
    j = np.argmin(h_substeps, axis=0)
    hs_min = np.take_along_axis(h_substeps, j[None], axis=0)[0]
    frac = np.arange(1, n_sub + 1) / n_sub
    t = np.asarray(t_s, dtype=float)[..., None]
    dt = np.asarray(dt_s, dtype=float)
    dt = dt[..., None] if dt.ndim else dt
    return np.minimum(hs_min, h_start), np.where(hs_min < h_start, t + dt * frac[j], t)


@dataclass
class Trajectory:
    """One run's time series; step arrays have N rows, sample arrays N + 1.

    Attributes:
        names: constraint names (m,).
        t_s: sample times (N + 1,), s.
        x: states at the samples (N + 1, 19), model units.
        q_c: commanded quaternion at each step (N, 4).
        u_des, u: desired and applied wheel accelerations (N, 3), rad/s^2 (u after saturation).
        omega_dot: body angular acceleration at the start of each step (N, 3), rad/s^2.
        h: physical constraint values at the samples (N + 1, m).
        h_substep_min: minimum of h over each step's substeps (N, m).
        h_substep_argmin_s: time of that minimum (N, m), s.
        bc, slack, intervening: filter records per step (N, m); zeros without RTA.
        box_active: (N, 3); status, fallback: (N,) strings; iterations (N,); solve_time_s (N,).
    """

    names: tuple[str, ...]
    t_s: Array
    x: Array
    q_c: Array
    u_des: Array
    u: Array
    omega_dot: Array
    h: Array
    h_substep_min: Array
    h_substep_argmin_s: Array
    bc: Array
    slack: Array
    intervening: Array
    box_active: Array
    status: NDArray[np.str_]
    fallback: NDArray[np.str_]
    iterations: NDArray[np.int64]
    solve_time_s: Array
    rta: bool
    preset: str
    scenario: str
    meta: dict[str, object] = field(default_factory=dict)

    @property
    def steps(self) -> int:
        return len(self.u)


class ClosedLoop:
    """Controller + optional filter + plant for one scenario; step it or `run()` it."""

    def __init__(self, cfg: Config, scenario: Scenario, rta: bool = True) -> None:
        self.cfg = cfg.for_scenario(scenario)
        self.scenario = scenario
        self.rta = rta
        self.filter = AsifFilter(self.cfg)
        self.constraints = ConstraintSet.from_config(self.cfg)

    def desired(self, x: Array, t_s: float) -> tuple[Array, Array]:
        """(q_c, u_des) of the primary controller at state x, time t_s; u_des crosses the torque interface."""
        q_c = self.scenario.command_at(t_s)
        if self.scenario.controller == "pd":
            u_des = pd_command(x, q_c, self.cfg)
        else:
            u_des = zero_command(x)
        return q_c, model.through_torque_interface(u_des, self.cfg)

    def command(self, x: Array, u_des: Array) -> tuple[Array, FilterResult | None]:
        """(u_act after the torque interface, filter result or None without RTA)."""
        if not self.rta:
            return model.through_torque_interface(u_des, self.cfg), None
        res = self.filter.filter(x, u_des)
        return model.through_torque_interface(res.u, self.cfg), res

    def run(self, dt_s: float | None = None, progress: bool = False) -> Trajectory:
        """Simulate the whole scenario; dt defaults to filter.sample_time_s."""
        cfg = self.cfg
        dt = dt_s or cfg.filter.sample_time_s
        n = round(self.scenario.duration_s / dt)
        m = len(self.constraints.names)
        x = np.empty((n + 1, self.scenario.x0.size))
        x[0] = self.scenario.x0
        arrays = {k: np.zeros((n, 3)) for k in ("u_des", "u", "omega_dot", "box_active")}
        q_c = np.zeros((n, 4))
        h = np.zeros((n + 1, m))
        h_min, h_arg = np.zeros((n, m)), np.zeros((n, m))
        bc, slack, inter = np.zeros((n, m)), np.zeros((n, m)), np.zeros((n, m), dtype=bool)
        status = np.full(n, "off", dtype=object)
        fallback = np.full(n, "", dtype=object)
        iters = np.zeros(n, dtype=np.int64)
        times = np.zeros(n)
        h[0] = self.constraints.safety_values(x[0])
        steps = range(n)
        if progress:
            from tqdm import tqdm

            steps = tqdm(steps, desc=f"simulate {self.scenario.name}", unit="step", leave=False)
        for k in steps:
            t = k * dt
            q_c[k], u_des = self.desired(x[k], t)
            u, res = self.command(x[k], u_des)
            u = saturate(u, cfg)
            arrays["u_des"][k], arrays["u"][k] = u_des, u
            arrays["omega_dot"][k] = model.omega_dot(x[k], u, cfg)
            x[k + 1], subs = integrate(x[k], u, dt, cfg)
            hs = self.constraints.safety_values(subs)  # (substeps, m)
            h_min[k], h_arg[k] = substep_minima(h[k], hs, np.float64(t), dt)
            h[k + 1] = hs[-1]
            if res is not None:
                bc[k], slack[k], inter[k] = res.bc, res.slack, res.intervening
                arrays["box_active"][k] = res.box_active
                status[k], fallback[k], iters[k], times[k] = res.status, res.fallback, res.iterations, res.solve_time_s
        return Trajectory(
            names=self.constraints.names, t_s=dt * np.arange(n + 1), x=x, q_c=q_c, u_des=arrays["u_des"],
            u=arrays["u"], omega_dot=arrays["omega_dot"], h=h, h_substep_min=h_min, h_substep_argmin_s=h_arg,
            bc=bc, slack=slack, intervening=inter, box_active=arrays["box_active"].astype(bool),
            status=status.astype(str), fallback=fallback.astype(str), iterations=iters, solve_time_s=times,
            rta=self.rta, preset=cfg.filter.preset, scenario=self.scenario.name,
            meta={"config": cfg.source, "dt_s": dt, "substeps": cfg.substeps},
        )  # fmt: skip


def simulate(cfg: Config, scenario: str | Scenario, rta: bool = True, preset: str | None = None,
             progress: bool = False) -> Trajectory:
    """Run a scenario (by name or object) in process, no DDS.

    Args:
        cfg: configuration.
        scenario: scenario name (e.g. 'paper-example') or object.
        rta: filter on (True) or u_des passed straight to the plant.
        preset: override the filter preset ('robust' or 'paper').
        progress: show a progress bar.
    """
    if preset is not None:
        cfg = cfg.with_preset(preset)
    scen = cfg.scenario(scenario) if isinstance(scenario, str) else scenario
    return ClosedLoop(cfg, scen, rta).run(progress=progress)


__all__ = ["ClosedLoop", "Trajectory", "integrate", "rk4_step", "saturate", "simulate", "substep_minima"]
