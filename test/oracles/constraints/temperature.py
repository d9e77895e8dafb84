"""Temperature of the -j_B face: T <= T_max.

    h_temp   = T_max - T                                      (K; relative degree 3)
    Psi_temp = T_max - T - delta0 max(0, pi/2 - theta_SI) - delta1 max(0, pi/2 - theta_EI)

theta_SI / theta_EI: sun / Earth incidence angles of the face normal -j_B. Psi_temp <= h_temp and
has relative degree 2 (u enters theta_ddot); it is enforced as a HOCBF. The clamps (SPEC sec. 4,
[resolved]) give the zero gradient the paper mentions when the face sees neither sun nor Earth.

    T_dot  = (alpha A S max(0, c_S) + (alpha A S A_f + sigma eps A T_E^4) F max(0, c_E)
              - sigma eps A T^4) / (m c_p)
    T_ddot = (alpha A S [c_S > 0] c_S_dot + (alpha A S A_f + sigma eps A T_E^4) F [c_E > 0] c_E_dot
              - 4 sigma eps A T^3 T_dot) / (m c_p)          (no u: T has relative degree 3)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracles.constraints.base import Array, BarrierValues, Context, sampled_data_margin, second_order_condition
from oracles.constraints.pointing import earth_pointing, sun_pointing
from oracles.model import face_normal, thermal_fluxes
from rta_attitude.config.schema import Augmentation, BarrierGains, Config
from rta_attitude.dynamics.state import TEMP


@dataclass(frozen=True)
class Temperature:
    """Upper temperature limit of the thermal node, through the angle-augmented barrier."""

    gains: BarrierGains
    augmentation: Augmentation
    T_max_K: float
    margin_K: float = 0.0
    """Sampled-data margin kept by the barrier (robust preset), K."""
    name: str = "temperature"
    relative_degree: int = 2

    @classmethod
    def from_config(cls, cfg: Config) -> Temperature:
        return cls(cfg.barriers["temperature"], cfg.augmentation, cfg.limits.temperature_max_K,
                   sampled_data_margin(cfg, "temperature"))

    def safety_value(self, ctx: Context) -> Array:
        return self.T_max_K - ctx.x[..., TEMP]

    def evaluate(self, ctx: Context) -> BarrierValues:
        cfg = ctx.cfg
        th, env = cfg.thermal, cfg.environment
        sun = sun_pointing(ctx, face_normal(cfg))
        earth = earth_pointing(ctx, face_normal(cfg))
        T = ctx.x[..., TEMP]
        heat_capacity = th.mass_kg * th.specific_heat_J_kgK
        T_dot = thermal_fluxes(sun.cos, earth.cos, T, cfg) / heat_capacity
        solar = th.absorptivity * th.area_m2 * env.solar_constant_W_m2
        earth_coeff = (solar * env.albedo_factor
                       + env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * env.earth_temperature_K**4)
        earth_on = (earth.cos > 0) if th.clamp_view_factor else np.ones_like(earth.cos, dtype=bool)
        T_ddot = (solar * (sun.cos > 0) * sun.cos_dot
                  + earth_coeff * env.earth_view_factor * earth_on * earth.cos_dot
                  - 4 * env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * T**3 * T_dot) / heat_capacity

        d0, d1 = self.augmentation.delta0_K_rad, self.augmentation.delta1_K_rad
        sun_on = sun.theta < np.pi / 2
        earth_in = earth.theta < np.pi / 2
        h = self.T_max_K - T
        psi0 = (h - self.margin_K - d0 * np.maximum(0.0, np.pi / 2 - sun.theta)
                - d1 * np.maximum(0.0, np.pi / 2 - earth.theta))
        psi0_dot = -T_dot + d0 * sun_on * sun.theta_dot + d1 * earth_in * earth.theta_dot
        psi0_ddot_drift = -T_ddot + d0 * sun_on * sun.theta_ddot_drift + d1 * earth_in * earth.theta_ddot_drift
        psi0_ddot_gain = (d0 * sun_on[..., None] * sun.theta_ddot_gain
                          + d1 * earth_in[..., None] * earth.theta_ddot_gain)
        psi1, drift, gain = second_order_condition(psi0, psi0_dot, psi0_ddot_drift, psi0_ddot_gain, self.gains)
        return BarrierValues(h, psi0, psi1, drift, gain)
