"""What every safety constraint shares: the evaluation context and the barrier record.

A constraint's barrier condition is affine in u:  BC(x, u) = drift(x) + gain(x) . u  >= 0
(minus a slack delta when the constraint is soft). For relative degree 2 (HOCBF):

    Psi_0 = h (or its augmented form),   Psi_1 = dPsi_0/dt|_f + k1 Psi_0,
    BC    = dPsi_1/dt|_(f + g u) + k2 Psi_1 + bias,

and for relative degree 1:  BC = dh/dt|_(f + g u) + k1 h + bias. `bias` is the paper's sigma,
added to the final condition as the paper's equation writes it (AFRL's framework adds it to h).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from oracles import model
from oracles import quaternion as quat
from rta_attitude.config.schema import BarrierGains, Config
from rta_attitude.dynamics.state import OMEGA, PSI, THETA_S, Q

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Context:
    """Quantities every barrier needs, computed once per state batch (shapes (..., k))."""

    x: Array
    """States (..., 19)."""
    cfg: Config
    A: Array
    """Attitude matrices (..., 3, 3), Hill -> body."""
    omega: Array
    """Body rates (..., 3), rad/s."""
    omega_drift: Array
    """Gyroscopic part of omega_dot (..., 3), rad/s^2."""
    sun: Array
    sun_dot: Array
    sun_ddot: Array
    """r_S and its first two time derivatives (..., 3) in Hill."""
    t_s: Array = 0.0  # type: ignore[assignment]
    """The time of the states (...), s from the run's start (the cones' windows)."""
    cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)
    """Results shared by several constraints (e.g. the pointing table), filled on first use."""

    @classmethod
    def from_state(cls, x: Array, cfg: Config, t_s: float | Array = 0.0) -> Context:
        """Build the context of states x (..., 19) at times t_s (s)."""
        x = np.asarray(x, dtype=float)
        beta = cfg.environment.sun_beta_rad
        sun_dot, sun_ddot = model.sun_direction_rates(x[..., THETA_S], cfg.environment.mean_motion_rad_s, beta)
        return cls(
            x=x, cfg=cfg, A=quat.attitude_matrix(x[..., Q]), omega=x[..., OMEGA],
            omega_drift=(model.gyroscopic_rate(x[..., OMEGA], cfg.spacecraft.J)
                         + model.wheel_rate(x[..., OMEGA], x[..., PSI], cfg, cfg.filter.model)),
            sun=model.sun_direction(x[..., THETA_S], beta), sun_dot=sun_dot, sun_ddot=sun_ddot,
            t_s=np.broadcast_to(np.asarray(t_s, dtype=float), x.shape[:-1]),
        )  # fmt: skip

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.x.shape[:-1]


@dataclass(frozen=True)
class BarrierValues:
    """One constraint evaluated on a state batch.

    Attributes:
        h: physical safety value (...); h < 0 is a violation (units of the constraint).
        psi0: enforced barrier Psi_0 (...) (h itself, or the augmented form).
        psi1: second HOCBF level Psi_1 (...); equals psi0 for relative degree 1.
        drift: BC at u = 0 (...), including class-K terms and bias.
        gain: dBC/du (..., 3).
    """

    h: Array
    psi0: Array
    psi1: Array
    drift: Array
    gain: Array


class Constraint(Protocol):
    """A named safety constraint: its physical h and its barrier condition."""

    name: str
    relative_degree: int
    gains: BarrierGains

    def safety_value(self, ctx: Context) -> Array:
        """Physical h (...) of the states in ctx."""
        ...

    def evaluate(self, ctx: Context) -> BarrierValues:
        """h, Psi levels and the affine barrier condition of the states in ctx."""
        ...


def sampled_data_margin(cfg: Config, group: str) -> float:
    """The margin a relative-degree-2 constraint keeps in the `robust` preset (0 in `paper`): `margin` for
    the filter's model `paper`, `margin_gyrostat` for the gyrostat."""
    from rta_attitude.constraints.margins import sampled_data_margin as margin  # (a parameter, not under test)

    return margin(cfg, group)


def second_order_condition(
    psi0: Array, psi0_dot: Array, psi0_ddot_drift: Array, psi0_ddot_gain: Array, gains: BarrierGains
) -> tuple[Array, Array, Array]:
    """HOCBF with linear class-K functions: (Psi_1, drift, gain) of BC = Psi_0'' + k1 Psi_0' + k2 Psi_1 + bias."""
    psi1 = psi0_dot + gains.k1 * psi0
    drift = psi0_ddot_drift + gains.k1 * psi0_dot + gains.k2 * psi1 + gains.bias
    return psi1, drift, psi0_ddot_gain
