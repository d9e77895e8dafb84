"""Your own controller through the safety filter, on your own plant loop (docs/api.md).

An eigen-axis slew that points the sensor (+x_B) straight at the sun: the filter keeps it outside its keep-out
cone, and every other constraint, while changing the command as little as it can.

    python examples/your_controller.py
"""

import numpy as np

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.environment import sun_direction
from rta_attitude.dynamics.plant import make_plant
from rta_attitude.dynamics.quaternion import attitude_matrices
from rta_attitude.dynamics.state import make_state
from rta_attitude.filter.asif import AsifFilter

cfg = config.load()  # the package's parameters (or config.load("mine.yaml"): an overlay of them)
x = make_state([0.0, 0.0, 0.0, 1.0], T_K=270.0, E_J=6000.0, theta_S_rad=1.0)  # q: Hill -> body, scalar last
J, D = cfg.spacecraft.J, cfg.spacecraft.wheel_inertia_kgm2
asif, constraints = AsifFilter(cfg), ConstraintSet(cfg)
worst = np.full(len(constraints.names), np.inf)

with make_plant(cfg, x) as plant:
    for k in range(600):  # dt = 1 s
        t = k * cfg.filter.sample_time_s
        A = attitude_matrices(x[0:4])  # Hill -> body
        sun_body = A @ sun_direction(x[12], cfg.environment.sun_beta_rad)
        axis = np.cross([1.0, 0.0, 0.0], sun_body)  # turn +x_B toward the sun (your law here)
        tau = J * (0.02 * axis - 0.4 * x[4:7])  # a desired body torque, N m ...
        u_des = tau / (cfg.spacecraft.torque_sign * D)  # ... as wheel accelerations, rad/s^2 (u = psi_dot)
        u = asif.filter(x, u_des, t).u  # the filter's answer: the smallest change that keeps every constraint
        x, substeps = plant.step(u)  # held over the sample (zero-order hold), saturated at the actuator
        worst = np.minimum(worst, constraints.safety_values(substeps, t).min(axis=0))

for name, h in zip(constraints.names, worst):
    info = constraints.registry[name]
    print(f"{name:16s} min h {h:10.4g} {info.unit:10s} ({info.display(h):.3g} {info.display_unit})")
print("SAFE" if np.all(worst[constraints.registry.hard] >= 0.0) else "UNSAFE")
