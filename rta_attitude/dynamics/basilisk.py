"""Basilisk (AVS Lab, the optional `bsk` package) as an independent truth plant: the module that
imports Basilisk, and only when a `BasiliskPlant` is built (`plant.simulator: basilisk`).

What Basilisk integrates: a rigid hub with the configured balanced reaction wheels (`BalancedWheels`, N >= 3) on
their spin axes a_i (`spacecraft.wheel_spin_axes_body`, A's columns), torque-commanded, RK4 at
h = dt / substeps (its `svIntegratorRK4`), optionally the gravity-gradient torque of a point-mass Earth
(`GravityGradientEffector`) and a circular orbit (rotating Hill frame). Its equations carry the wheels'
gyroscopic torque always, so it is the `gyrostat` model whatever `spacecraft.model` says (the filter keeps
`filter.model`).

Mapping (each line checked in test/test_basilisk.py):

    attitude   Basilisk's MRP sigma_BN has the DCM [BN] = A(q_BN); q = [2 s, 1 - |s|^2] / (1 + |s|^2),
               s = q_v / (1 + q4) (either MRP set gives the same attitude; q keeps a continuous sign)
    frames     N = Hill at t = 0; Hill inertial (paper): q_BH = q_BN; rotating Hill: the orbit starts at
               r x_N with velocity n r y_N, so q_BH = q_BN (x) q_NH(t), q_NH = [0, 0, -sin(nt/2), cos(nt/2)]
    rates      omega_BN_B is the state's omega
    hub        Basilisk's hub inertia is the whole spacecraft's (balanced wheels add none): J + D A A^T
               (J + D I with a wheel on each body axis)
    wheels     motor torque u_s = -D u_i on wheel i (held over the step, clipped by Basilisk at D psi_dot_max,
               as the actuator clips u; with spacecraft.transport_delay_s, written when the delay's substeps
               are over, the previous step's torque held before); psi_i = -(Omega_i + a_i . omega), Omega_i
               the wheel's rate relative to the body

With these readings Basilisk's equations are the gyrostat model exactly: H_B = (J + D A A^T) w + D A Omega
= J w - D A psi, the rotor equation D (Omega_dot_i + a_i . w_dot) = u_s gives psi_dot = u, and H_B_dot +
w x H_B = tau gives J w_dot = -w x (J w - D A psi) + D A u (+ tau_gg: r x (D I r) = 0 with a wheel on each
body axis, so the hub's extra D changes no gravity-gradient torque; with skewed wheels Basilisk's hub adds
3 n^2 r x (D A A^T r), below 3 n^2 D ~ 1.3e-10 N m here, which the compiled model leaves out). J is the
spacecraft without the rotors' spin inertia and psi the negative inertial rotor rate, the readings
`dynamics.spacecraft` states. Basilisk's wheel-speed limit is left off (Omega_max < 0): the wheels are not
stopped at psi_max, so the psi constraints are judged on the truth, as on the compiled plant.

Not from Basilisk: T, E, theta_S and the Clohessy-Wiltshire entries. Basilisk has no model of the
paper's lumped -j_B face node or its battery, and theta_S and CW do not depend on the attitude; they
are integrated by the compiled model (`spacecraft.derivative`, gyrostat) over each substep from
Basilisk's state at the substep's start, so their inputs are Basilisk's attitude (`_follow`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.plant import initial_state
from rta_attitude.dynamics.quaternion import product
from rta_attitude.dynamics.spacecraft import RK4_WORK_ROWS, plant_record, rk4_hold, saturated
from rta_attitude.dynamics.state import STATE_SIZE, wheel_column
from rta_attitude.errors import ConfigError
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

MU_EARTH_M3_S2 = 3.986004415e14
"""Earth's gravitational parameter, Basilisk's value (astroConstants MU_EARTH, km^3/s^2 x 1e9)."""
HUB_MASS_KG = 12.0
"""Hub mass of a 6U CubeSat; no effect on the attitude (centre of mass at B, no translation coupling)."""
NS_PER_S = 1_000_000_000
BASILISK_ROWS = 10
"""Entries of the state that Basilisk integrates: q (4), omega (3), psi (the first three wheels; wheels past the
third are entries 19.., `state.wheel_column`)."""


# ----------------------------------------------------------------------------- frame conversions


def quaternion_to_mrp(q: Array) -> Array:
    """Basilisk's MRP sigma (3,) of a quaternion (4,) (scalar last, any norm): the short set, |sigma| <= 1."""
    qa = np.asarray(q, dtype=float)
    qa = qa / np.linalg.norm(qa)
    if qa[3] < 0.0:
        qa = -qa
    return qa[:3] / (1.0 + qa[3])


@numba.njit(**LEAF)
def mrp_quaternion(s1: float, s2: float, s3: float, out: Array) -> None:
    """The unit quaternion (4,) of an MRP sigma (either set) into out: [2 sigma, 1 - |sigma|^2] / (1 + |sigma|^2)."""
    n2 = s1 * s1 + s2 * s2 + s3 * s3
    k = 1.0 / (1.0 + n2)
    out[0] = 2.0 * s1 * k
    out[1] = 2.0 * s2 * k
    out[2] = 2.0 * s3 * k
    out[3] = (1.0 - n2) * k


@numba.njit(**LEAF)
def _mrp_quaternions(S: Array, out: Array) -> None:
    for k in range(S.shape[0]):
        mrp_quaternion(S[k, 0], S[k, 1], S[k, 2], out[k])


def mrp_to_quaternion(sigma: Array) -> Array:
    """Quaternions (..., 4) (scalar last, unit) of MRPs (..., 3), either set (`mrp_quaternion`)."""
    s = np.asarray(sigma, dtype=float)
    S = np.ascontiguousarray(s.reshape(-1, 3))
    out = np.empty((S.shape[0], 4))
    _mrp_quaternions(S, out)
    return out.reshape((*s.shape[:-1], 4))


# ----------------------------------------------------------------------------- Basilisk -> the state


@numba.njit(**LEAF)
def _follow(x0: Array, sigma: Array, w: Array, Omega: Array, t0_s: float, h_s: float, frame_rate: float, u: Array,
            pa: NDArray[np.void], out: Array, one: Array, quats: Array, work: Array) -> None:
    """The states (S, 16 + N) after each of S substeps into out, from Basilisk's sigma_BN, omega_BN_B and
    wheel speeds Omega (S, N) at t0 + (j + 1) h and the state x0 (16 + N,) at t0: q_BH (sign continuous
    with x0's), omega, psi = -(Omega + omega) from Basilisk; T, E, theta_S, CW by one RK4 step of the
    compiled model (record pa (1,)) over each substep from Basilisk's state at its start, with u held.
    one (1, 19), quats (2, 4), work (RK4_WORK_ROWS, 19): scratch."""
    p = pa[0]
    q_bn = quats[0]
    q_nh = quats[1]
    prev = x0
    for j in range(sigma.shape[0]):
        rk4_hold(prev, u, h_s, 1, p, one, work)  # T, E, theta_S, CW over the substep (uses work rows 0-7)
        row = out[j]
        for i in range(BASILISK_ROWS, STATE_SIZE):  # T, E, theta_S, CW
            row[i] = one[0, i]
        mrp_quaternion(sigma[j, 0], sigma[j, 1], sigma[j, 2], q_bn)
        half = 0.5 * frame_rate * (t0_s + (j + 1) * h_s)
        q_nh[0], q_nh[1], q_nh[2], q_nh[3] = 0.0, 0.0, -math.sin(half), math.cos(half)
        product(q_bn, q_nh, row[0:4])
        norm = math.sqrt(row[0] * row[0] + row[1] * row[1] + row[2] * row[2] + row[3] * row[3])
        if row[0] * prev[0] + row[1] * prev[1] + row[2] * prev[2] + row[3] * prev[3] < 0.0:
            norm = -norm
        for i in range(4):
            row[i] = row[i] / norm
        for a in range(3):
            row[4 + a] = w[j, a]
        if p.wheels_on_axes:
            for a in range(3):
                row[7 + a] = -(Omega[j, a] + w[j, a])
        else:  # psi_i = -(Omega_i + a_i . omega), a_i wheel i's spin axis
            A = p.wheel_axes
            for i in range(A.shape[1]):
                row[wheel_column(i)] = -(Omega[j, i] + (A[0, i] * w[j, 0] + A[1, i] * w[j, 1] + A[2, i] * w[j, 2]))
        prev = row


def truth_record(cfg: Config) -> NDArray[np.void]:
    """The PLANT_DTYPE record (1,) of what Basilisk integrates: the configuration's plant as `gyrostat`."""
    return plant_record(replace(cfg, spacecraft=replace(cfg.spacecraft, model="gyrostat")))


# ----------------------------------------------------------------------------- the plant


class BasiliskPlant:
    """The spacecraft simulated by Basilisk, in the package's state layout; see the module docstring.

    Args:
        cfg: configuration: spacecraft (J, D; torque_sign must be 1), environment (mean motion,
            rotating_hill, gravity_gradient), limits.wheel_accel_max_rad_s2, integrator.substeps.
        x0: initial state (16 + N,).
        dt_s: hold time of one step, s (default filter.sample_time_s); dt_s / substeps must be a whole
            number of nanoseconds (Basilisk's clock).

    Raises:
        ConfigError: Basilisk is not installed, or dt / substeps is not a whole number of ns.
    """

    def __init__(self, cfg: Config, x0: Array, dt_s: float | None = None) -> None:
        x = initial_state(cfg, x0)
        dt = float(cfg.filter.sample_time_s if dt_s is None else dt_s)
        self.substeps = cfg.substeps
        self.h_ns = round(dt * NS_PER_S / self.substeps)
        if self.h_ns < 1 or self.h_ns * self.substeps != round(dt * NS_PER_S):
            raise ConfigError(f"plant.simulator basilisk: dt / substeps must be a whole number of ns, got "
                              f"{dt!r} s / {self.substeps}")
        self.dt_s = self.h_ns * self.substeps / NS_PER_S
        self.h_s = self.h_ns / NS_PER_S
        self.D = cfg.spacecraft.wheel_inertia_kgm2
        self.u_max = cfg.limits.wheel_accel_max_rad_s2
        env = cfg.environment
        self.n_rad_s = env.mean_motion_rad_s
        self.rotating_hill, self.gravity_gradient = env.rotating_hill, env.gravity_gradient
        self.frame_rate_rad_s = self.n_rad_s if self.rotating_hill else 0.0
        self.r_orbit_m = (MU_EARTH_M3_S2 / self.n_rad_s**2) ** (1.0 / 3.0)
        self.record = truth_record(cfg)
        self.J = self.record[0]["inertia_matrix"].copy()  # the simulated vehicle's tensor (`plant.inertia_kgm2`)
        self.x = x
        self.x[0:4] /= np.linalg.norm(self.x[0:4])
        self.t_ns = 0
        self.delay_substeps = cfg.delay_substeps
        self.n_wheels = cfg.spacecraft.n_wheels
        self._us = np.zeros(self.n_wheels)  # the command the wheels hold (over the next step's delay too)
        self._one = np.empty((1, x.shape[0]))
        self._quats = np.empty((2, 4))
        self._work = np.zeros((RK4_WORK_ROWS, x.shape[0]))
        self._closed = False
        self._build(self.x)

    @property
    def t_s(self) -> float:
        """Simulated time now, s."""
        return self.t_ns / NS_PER_S

    def _build(self, x: Array) -> None:
        try:
            from Basilisk.architecture import messaging
            from Basilisk.simulation import (
                GravityGradientEffector,
                extForceTorque,
                reactionWheelStateEffector,
                spacecraft,
            )
            from Basilisk.utilities import SimulationBaseClass, simIncludeGravBody, simIncludeRW
        except ImportError:
            from rta_attitude.config.schema import BASILISK_MISSING

            raise ConfigError(BASILISK_MISSING) from None

        sim = SimulationBaseClass.SimBaseClass()
        proc = sim.CreateNewProcess("plant")
        proc.addTask(sim.CreateNewTask("dynamics", self.h_ns))
        sc = spacecraft.Spacecraft()
        sc.ModelTag = "cubesat"
        sc.hub.mHub = HUB_MASS_KG
        sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
        A = self.record[0]["wheel_axes"]
        # balanced wheels add no inertia: the hub carries the rotors' spin-axis part, D sum_i a_i a_i^T
        sc.hub.IHubPntBc_B = (self.J + self.D * (A @ A.T)).tolist()
        sc.hub.sigma_BNInit = quaternion_to_mrp(x[0:4]).reshape(3, 1).tolist()  # N = Hill at t = 0
        w0 = x[4:7]
        sc.hub.omega_BN_BInit = w0.reshape(3, 1).tolist()
        r = self.r_orbit_m
        sc.hub.r_CN_NInit = [[r], [0.0], [0.0]]
        sc.hub.v_CN_NInit = [[0.0], [self.n_rad_s * r if self.rotating_hill else 0.0], [0.0]]

        factory = simIncludeRW.rwFactory()
        for a in range(self.n_wheels):
            axis = [float(v) for v in A[:, a]]
            rw = factory.create("custom", axis, Js=float(self.D), u_max=float(self.D * self.u_max),
                                RWModel=messaging.BalancedWheels, useMaxTorque=True)
            # rad/s (create() takes RPM); psi = -(Omega + a . omega)
            rw.Omega = float(-x[wheel_column(a)] - A[:, a] @ w0)
        wheels = reactionWheelStateEffector.ReactionWheelStateEffector()
        factory.addToSpacecraft("wheels", wheels, sc)
        self._command = messaging.ArrayMotorTorqueMsgPayload()
        self._command.motorTorque = [0.0] * messaging.MAX_EFF_CNT
        self._command_msg = messaging.ArrayMotorTorqueMsg().write(self._command)
        wheels.rwMotorCmdInMsg.subscribeTo(self._command_msg)
        # the wheels (higher priority) read the command before the hub integrates [t_k, t_k + h]
        sim.AddModelToTask("dynamics", wheels, None, 20)
        sim.AddModelToTask("dynamics", sc, None, 10)
        keep: list[Any] = [factory]
        if self.gravity_gradient:
            gravity = simIncludeGravBody.gravBodyFactory()
            earth = gravity.createCustomGravObject("earth", MU_EARTH_M3_S2)
            earth.isCentralBody = True
            gravity.addBodiesTo(sc)
            gg = GravityGradientEffector.GravityGradientEffector()
            gg.ModelTag = "gravity_gradient"
            gg.addPlanetName(earth.planetName)
            sc.addDynamicEffector(gg)
            sim.AddModelToTask("dynamics", gg, None, 5)
            keep += [gravity, earth, gg]
            if not self.rotating_hill:
                # the paper's inertial Hill frame: hold the spacecraft at r x_N (zenith fixed) with a force
                # that cancels point-mass gravity
                hold = extForceTorque.ExtForceTorque()
                hold.ModelTag = "hold"
                hold.extForce_N = [[HUB_MASS_KG * MU_EARTH_M3_S2 / r**2], [0.0], [0.0]]
                sc.addDynamicEffector(hold)
                sim.AddModelToTask("dynamics", hold, None, 5)
                keep.append(hold)
        self._states = sc.scStateOutMsg.recorder(self.h_ns)
        self._speeds = wheels.rwSpeedOutMsg.recorder(self.h_ns)
        sim.AddModelToTask("dynamics", self._states, None, 1)
        sim.AddModelToTask("dynamics", self._speeds, None, 1)
        self._sim, self._sc, self._wheels, self._keep = sim, sc, wheels, keep
        sim.InitializeSimulation()
        self._sim.TotalSim.StepUntilStop(0, -1)  # the t = 0 tick: writes the initial messages

    def _write_torque(self, us: Array) -> None:
        self._command.motorTorque = [float(-self.D * v) for v in us]
        self._command_msg.write(self._command)

    def step(self, u: Array) -> tuple[Array, Array]:
        """Saturate u (N,), rad/s^2, at the actuator limit and hold it over dt_s in Basilisk.

        Returns:
            (x(t + dt) (16 + N,), the states after each substep (substeps, 16 + N)).

        Raises:
            ValueError: u is not finite (Basilisk would integrate NaN torques), or the plant is closed.
        """
        if self._closed:
            raise ValueError("the Basilisk plant is closed")
        u = np.ascontiguousarray(u, dtype=float)
        if u.shape != (self.n_wheels,) or not np.all(np.isfinite(u)):
            raise ValueError(f"u must be {self.n_wheels} finite wheel accelerations, got {u!r}")
        t0_ns = self.t_ns
        # StepUntilStop is ConfigureStopTime + ExecuteSimulation without the Python event loop (the same
        # states, less time per step)
        if self.delay_substeps > 0:  # the previous command (in the message already) until the delay is over
            self._sim.TotalSim.StepUntilStop(t0_ns + self.h_ns * self.delay_substeps, -1)
        self._us[:] = saturated(u, self.record)  # the actuator
        self._write_torque(self._us)
        self.t_ns = t0_ns + self.h_ns * self.substeps
        self._sim.TotalSim.StepUntilStop(self.t_ns, -1)
        times = np.asarray(self._states.times(), dtype=np.int64)
        new = times > t0_ns  # the recorder also holds the t = 0 record once
        sigma = np.ascontiguousarray(np.asarray(self._states.sigma_BN)[new])
        w = np.ascontiguousarray(np.asarray(self._states.omega_BN_B)[new])
        Omega = np.ascontiguousarray(np.asarray(self._speeds.wheelSpeeds)[new][:, :self.n_wheels])
        self._states.clear()
        self._speeds.clear()
        if sigma.shape[0] != self.substeps:
            raise RuntimeError(f"Basilisk recorded {sigma.shape[0]} substeps, expected {self.substeps}")
        subs = np.empty((self.substeps, self.x.shape[0]))
        _follow(self.x, sigma, w, Omega, t0_ns / NS_PER_S, self.h_s, self.frame_rate_rad_s, self._us,
                self.record, subs, self._one, self._quats, self._work)
        self.x = subs[-1].copy()
        return self.x.copy(), subs

    def angular_momentum_N(self) -> Array:
        """Basilisk's own total angular momentum about the centre of mass, N frame (3,), N m s."""
        self._sc.computeEnergyMomentum(self.t_s)
        return np.array(self._sc.totRotAngMomPntC_N, dtype=float).reshape(3)

    def position_N(self) -> Array:
        """The spacecraft's position in N (3,), m (an orbit with rotating Hill, held without)."""
        reader = self._sc.scStateOutMsg.read()
        return np.array(reader.r_BN_N, dtype=float)

    def close(self) -> None:
        """Drop the Basilisk objects (SWIG frees them; Basilisk has no explicit teardown). Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._keep.clear()
        del self._states, self._speeds, self._sim, self._sc, self._wheels, self._command_msg

    def __enter__(self) -> BasiliskPlant:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["BASILISK_ROWS", "HUB_MASS_KG", "MU_EARTH_M3_S2", "BasiliskPlant", "mrp_quaternion", "mrp_to_quaternion",
           "quaternion_to_mrp", "truth_record"]
