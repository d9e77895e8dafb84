"""Shared test utilities: seeded random states inside and around the safe set."""

from __future__ import annotations

import numpy as np

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.quaternion import from_matrix
from rta_attitude.dynamics.state import STATE_SIZE


def random_states(rng: np.random.Generator, n: int, cfg: Config) -> np.ndarray:
    """n random states (n, 19): uniform attitudes, rates up to 1.5 w_max, any wheel speed and sun angle."""
    x = np.zeros((n, STATE_SIZE))
    q = rng.normal(size=(n, 4))
    x[:, 0:4] = q / np.linalg.norm(q, axis=1, keepdims=True)
    x[:, 4:7] = rng.uniform(-1.5, 1.5, (n, 3)) * cfg.limits.omega_max_rad_s
    x[:, 7:10] = rng.uniform(-1.0, 1.0, (n, 3)) * cfg.limits.psi_max_rad_s
    x[:, 10] = rng.uniform(250.0, 300.0, n)
    x[:, 11] = rng.uniform(500.0, 10000.0, n)
    x[:, 12] = rng.uniform(0, 2 * np.pi, n)
    x[:, 13:19] = rng.normal(size=(n, 6)) * [100, 100, 100, 0.1, 0.1, 0.1]
    return x


def to_torque(u: np.ndarray, cfg: Config) -> np.ndarray:
    """tau = D u, as the nodes convert (rta_attitude.dynamics.spacecraft.wheel_accel_to_torque)."""
    from rta_attitude.dynamics.spacecraft import wheel_accel_to_torque

    return wheel_accel_to_torque(np.asarray(u, dtype=float), cfg.spacecraft.wheel_inertia_kgm2)


def to_wheel_accel(tau: np.ndarray, cfg: Config) -> np.ndarray:
    """u = tau / D, as the nodes convert."""
    from rta_attitude.dynamics.spacecraft import torque_to_wheel_accel

    return torque_to_wheel_accel(np.asarray(tau, dtype=float), cfg.spacecraft.wheel_inertia_kgm2)


def saturate(u: np.ndarray, cfg: Config) -> np.ndarray:
    """The actuator's clip at the wheel-acceleration limit."""
    lim = cfg.limits.wheel_accel_max_rad_s2
    return np.clip(u, -lim, lim)


def integrate(x: np.ndarray, u: np.ndarray, dt_s: float, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """The plant's step of one state (dynamics.spacecraft.integrate with the configuration's record)."""
    from rta_attitude.dynamics.spacecraft import integrate as step
    from rta_attitude.dynamics.spacecraft import plant_record

    return step(x, u, dt_s, plant_record(cfg), cfg.substeps)


def best_panel_cos(h: np.ndarray, s: np.ndarray, caps: np.ndarray, rng: np.random.Generator, starts: int = 16,
                   side: float = 0.0) -> float:
    """An optimiser's answer (SLSQP from `starts` random rotations) to: the largest (R s)_3, the panel
    k_B's cosine to the sun s, over rotations R (from the frame of h and s to the body) with the body
    momentum R h inside the wheels' box |(R h)_a| <= caps_a, and (R h)_3 of the sign of `side` if it is
    not 0. -2 if no start ends feasible."""
    from scipy.optimize import minimize
    from scipy.spatial.transform import Rotation

    def body(r: np.ndarray, v: np.ndarray) -> np.ndarray:
        return Rotation.from_rotvec(r).apply(v)

    cons = [{"type": "ineq", "fun": lambda r, a=a, sg=sg: caps[a] - sg * body(r, h)[a]}
            for a in range(3) for sg in (1.0, -1.0)]
    if side:
        cons.append({"type": "ineq", "fun": lambda r: side * body(r, h)[2]})
    best = -2.0
    for seed in rng.integers(1 << 31, size=starts):
        start = Rotation.random(random_state=seed).as_rotvec()
        res = minimize(lambda r: -body(r, s)[2], start, constraints=cons, method="SLSQP",
                       options={"ftol": 1e-12, "maxiter": 500})
        if min(con["fun"](res.x) for con in cons) > -1e-10:
            best = max(best, -float(res.fun))
    return best


def starting_peer(role: str, namespace: str, context: object) -> object:
    """An rclpy node named like the run's node of `role` that is alive and still starting: in the graph, reading
    only /clock (as rclpy's time source does from a use_sim_time node's first moment, long before its kernels let
    it create the run's endpoints)."""
    import rclpy

    from rta_attitude import topics
    from rta_attitude.ros import interface

    node = rclpy.create_node(topics.NODE_NAMES[role], namespace=namespace, context=context)
    clock = topics.TOPICS[topics.CLOCK]
    node.create_subscription(interface.msg_class(clock.type_name), clock.name, lambda m: None,
                             interface.qos_profile(clock.qos))
    return node


def sun_safe_state(theta_S: float, E: float, T_K: float = 280.0) -> np.ndarray:
    """A state at rest at the paper's sun-safe attitude (+k_B on the sun, +j_B toward the Earth's side of it), no
    wheel momentum, the sun in the orbit plane at theta_S."""
    s = np.array([np.cos(theta_S), np.sin(theta_S), 0.0])
    e = np.array([-1.0, 0.0, 0.0])
    j = e - (e @ s) * s
    j /= np.linalg.norm(j)
    A = np.array([np.cross(j, s), j, s])  # rows: the body axes in Hill
    q = np.zeros(4)
    from_matrix(A, q)
    x = np.zeros(19)
    x[0:4], x[10], x[11], x[12] = q, T_K, E, theta_S
    return x


def hard_minimum(plant_cfg: Config, filter_cfg: Config, x0: np.ndarray, duration_s: float = 2000.0) -> float:
    """One run from x0 (u_des = 0) on plant_cfg's plant (its simulator, inertia, delay), filtered by filter_cfg's
    filter: the smallest h of plant_cfg's hard constraints at any substep (negative: one broke)."""
    from rta_attitude.config.schema import Scenario
    from rta_attitude.dynamics.plant import make_plant
    from rta_attitude.filter.asif import AsifFilter
    from rta_attitude.simulation.closed_loop import run_stepped

    steps = round(duration_s / filter_cfg.filter.sample_time_s)
    with make_plant(plant_cfg, x0) as plant:
        out = run_stepped(filter_cfg, Scenario("run", "", duration_s, x0, controller="none"), steps, plant,
                          AsifFilter(filter_cfg))
    hard = [i for i, n in enumerate(plant_cfg.constraint_names) if n not in plant_cfg.slacked_constraints]
    return float(out.h_sub[:, :, hard].min())


def rotation(angle_deg: float, axis: tuple[float, float, float]) -> np.ndarray:
    """The rotation matrix (3, 3) of angle_deg about axis (Rodrigues' formula)."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    a = np.radians(angle_deg)
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * K @ K


def turned_vehicle(cfg: Config, angle_deg: float, axis: tuple[float, float, float] = (1.0, 2.0, 3.0)
                   ) -> tuple[Config, np.ndarray]:
    """cfg's vehicle with its principal axes turned by R = rotation(angle_deg, axis) away from the body axes:
    J_body = R diag(J) R^T, given as the tensor's diagonal and products (`spacecraft.products_of_inertia_kgm2`).
    Returns (the configuration, R)."""
    import dataclasses

    R = rotation(angle_deg, axis)
    J = R @ np.diag(cfg.spacecraft.J) @ R.T
    sc = dataclasses.replace(cfg.spacecraft, inertia_kgm2=(J[0, 0], J[1, 1], J[2, 2]),
                             products_of_inertia_kgm2=(J[0, 1], J[0, 2], J[1, 2]))
    return dataclasses.replace(cfg, spacecraft=sc), R


SKEWED_AXES = ((0.9592, 0.1998, -0.1998), (0.3, 0.9, 0.3162), (-0.2506, 0.3509, 0.9023))
"""Three wheels' spin axes (rows, body axes), none on a body axis nor orthogonal to another (normalised where
used): a generic array."""


def with_wheels(cfg: Config, axes: tuple[tuple[float, float, float], ...] | np.ndarray) -> Config:
    """cfg with its wheels' spin axes (rows; normalised) set as `spacecraft.wheel_spin_axes_body` sets them."""
    import dataclasses

    rows = np.asarray(axes, dtype=float)
    rows = rows / np.linalg.norm(rows, axis=1, keepdims=True)
    sc = dataclasses.replace(cfg.spacecraft, wheel_axes_body=tuple(tuple(float(v) for v in r) for r in rows))
    return dataclasses.replace(cfg, spacecraft=sc)


def turned_with_wheels(cfg: Config, angle_deg: float, axis: tuple[float, float, float] = (1.0, 2.0, 3.0)
                       ) -> tuple[Config, np.ndarray]:
    """`turned_vehicle` with its wheels turned along: wheel i on the turned principal axis R e_i. The vehicle is
    cfg's principal one seen from body axes turned by R^T (omega_body = R omega, psi the same, u the same).
    Returns (the configuration, R)."""
    turned, R = turned_vehicle(cfg, angle_deg, axis)
    return with_wheels(turned, R.T), R


def against_basilisk(cfg: Config, x0: np.ndarray, us: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The substep states of cfg's vehicle from x0 under the commands us (held one sample each): on the compiled
    plant, on it with twice the substeps (every other substep: on the same grid), and on Basilisk."""
    import dataclasses

    from rta_attitude.dynamics.plant import make_plant

    def run(c: Config, simulator: str) -> np.ndarray:
        with make_plant(c.with_simulator(simulator), x0) as plant:
            return np.concatenate([plant.step(u)[1] for u in us])

    fine = run(dataclasses.replace(cfg, substeps=2 * cfg.substeps), "compiled")[1::2]
    return run(cfg, "compiled"), fine, run(cfg, "basilisk")


def max_angle(qa: np.ndarray, qb: np.ndarray) -> float:
    """The largest rotation angle (rad) between two quaternion series (..., 4)."""
    from rta_attitude.dynamics import quaternion as quat

    return float((2.0 * np.arcsin(np.minimum(1.0, np.linalg.norm(quat.error_vectors(qa, qb), axis=-1)))).max())
