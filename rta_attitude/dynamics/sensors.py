"""What the flight software sees and what the wheels do: sensor noise and bias on the published state,
torque noise and a first-order lag on the applied command (`sensors:` in the parameter file). Seeded.

    y_k   = measure(x_k)                    the state the controller and the filter read (docs/noise.md)
    u_k   = actuate(u_cmd_k)                the wheel accelerations the plant holds over [t_k, t_k+1)

Measurement at sample k (every draw an independent standard normal n, by (seed, stream, k, channel)):

| entries     | measured                                                    | parameter                        |
|-------------|-------------------------------------------------------------|----------------------------------|
| q           | dq(attitude_noise n) (x) q  (a small body-frame rotation)   | attitude_noise (star tracker)    |
| omega       | omega + b_k + gyro_noise n;  b_{k+1} = b_k + walk sqrt(dt) n | gyro_noise, gyro_bias, gyro_bias_walk |
| psi         | psi + wheel_speed_noise n                                   | tachometers                      |
| T, E        | + temperature_noise n, + energy_noise n                     | thermistor, fuel gauge           |
| theta_S, CW | exact (ephemeris)                                           |                                  |

b_0 = gyro_bias n. The actuator: the wheels' acceleration follows the command through a first-order lag
of time constant `actuator_lag_s` (tau): over a hold of dt from the previous output v, the output is
v(s) = u_cmd + (v - u_cmd) e^(-s/tau); the plant holds its mean over the hold, u_cmd + (v - u_cmd)
(tau/dt)(1 - e^(-dt/tau)) (exact in the momentum delivered, so exact in psi at the samples), plus
torque_noise n; the next hold starts from v(dt). The actuator limit saturates after this.

The draws are counter-based (a SplitMix64 hash of seed, stream, sample and channel, then Box-Muller),
so the same (seed, stream, k) gives the same noise in the compiled loop, the Monte Carlo (stream = run
index) and the plant node, with no generator state to carry: a lockstep run over DDS equals the
in-process run bit for bit with noise too. With `enabled` false `measure` copies x and `actuate`
copies u_cmd, exactly.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.quaternion import product
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

SENSORS_DTYPE = np.dtype([
    ("enabled", np.uint8),
    ("seed", np.uint64),
    ("stream", np.uint64),                 # which noise sequence (the Monte Carlo: the run's index)
    ("dt_s", np.float64),                  # sample time (the bias walk and the lag)
    ("attitude_noise_rad", np.float64),
    ("gyro_noise_rad_s", np.float64),
    ("gyro_bias_rad_s", np.float64),
    ("gyro_bias_walk_rad_s_sqrt_s", np.float64),
    ("wheel_speed_noise_rad_s", np.float64),
    ("temperature_noise_K", np.float64),
    ("energy_noise_J", np.float64),
    ("torque_noise_rad_s2", np.float64),   # on the wheel acceleration (torque / D)
    ("actuator_lag_s", np.float64),
])  # fmt: skip

INSTRUMENT_DTYPE = np.dtype([
    ("bias", np.float64, (3,)),            # the gyro bias now, rad/s
    ("u_end", np.float64, (3,)),           # the actuator's output at the end of the last hold, rad/s^2
    ("started", np.uint8),                 # bias drawn
    ("dq", np.float64, (4,)),              # scratch: the attitude error's quaternion
])  # fmt: skip
"""What the sensors and the actuator carry from one sample to the next."""

# channels of one sample's draws
CH_ATTITUDE, CH_GYRO, CH_WALK, CH_WHEEL, CH_TEMP, CH_ENERGY, CH_TORQUE, CH_BIAS0 = 0, 3, 6, 9, 12, 13, 14, 17

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def sensors_record(cfg: Config, stream: int = 0) -> NDArray[np.void]:
    """The SENSORS_DTYPE record (1,) of a configuration (`sensors:`), noise sequence `stream`."""
    s = cfg.sensors
    rec = np.zeros(1, SENSORS_DTYPE)
    r = rec[0]
    r["enabled"], r["seed"], r["stream"], r["dt_s"] = s.enabled, s.seed, stream, cfg.filter.sample_time_s
    for name in ("attitude_noise_rad", "gyro_noise_rad_s", "gyro_bias_rad_s", "gyro_bias_walk_rad_s_sqrt_s",
                 "wheel_speed_noise_rad_s", "temperature_noise_K", "energy_noise_J", "torque_noise_rad_s2",
                 "actuator_lag_s"):
        r[name] = getattr(s, name)
    return rec


def new_instruments() -> NDArray[np.void]:
    """A fresh INSTRUMENT_DTYPE record (1,): the bias is drawn at the first measurement."""
    return np.zeros(1, INSTRUMENT_DTYPE)


@numba.njit(**LEAF)
def reset_instruments(ins: np.void) -> None:
    """Back to a fresh INSTRUMENT_DTYPE record (a new run): the bias is drawn again at the first
    measurement, the lag starts from rest."""
    ins.started = 0
    for a in range(3):
        ins.bias[a] = 0.0
        ins.u_end[a] = 0.0


@numba.njit(**LEAF)
def _mix(z: np.uint64) -> np.uint64:
    """SplitMix64's finaliser (Steele, Lea, Flood 2014): a bijection of 64-bit words that avalanches."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@numba.njit(**LEAF)
def _unit(z: np.uint64) -> float:
    """A 64-bit word to a float in (0, 1] (its top 53 bits)."""
    return (float(z >> np.uint64(11)) + 1.0) * (1.0 / 9007199254740992.0)


@numba.njit(**LEAF)
def normal(seed: np.uint64, stream: np.uint64, k: np.int64, channel: np.int64) -> float:
    """A standard normal draw, a pure function of (seed, stream, sample k, channel) (Box-Muller of two
    hashed uniforms)."""
    key = _mix(_mix(seed + _GOLDEN) ^ stream)
    z = _mix(key ^ _mix(np.uint64(k) * _GOLDEN + np.uint64(channel)))
    u1 = _unit(z)
    u2 = _unit(_mix(z + _GOLDEN))
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@numba.njit(**LEAF)
def measure(x: Array, k: int, s: np.void, ins: np.void, out: Array) -> None:
    """The measured state of sample k (the table in the module docstring) into out (19,); advances the
    gyro bias by one sample. Exactly x when the sensors are off."""
    for i in range(STATE_SIZE):
        out[i] = x[i]
    if not s.enabled:
        return
    seed, stream = s.seed, s.stream
    if not ins.started:
        for a in range(3):
            ins.bias[a] = s.gyro_bias_rad_s * normal(seed, stream, 0, CH_BIAS0 + a)
        ins.started = 1
    # attitude: dq (x) q, dq the rotation by the small vector e (its quaternion, vector first)
    e0 = s.attitude_noise_rad * normal(seed, stream, k, CH_ATTITUDE)
    e1 = s.attitude_noise_rad * normal(seed, stream, k, CH_ATTITUDE + 1)
    e2 = s.attitude_noise_rad * normal(seed, stream, k, CH_ATTITUDE + 2)
    angle = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if angle > 0.0:
        sh = math.sin(0.5 * angle) / angle
        dq = ins.dq
        dq[0], dq[1], dq[2], dq[3] = e0 * sh, e1 * sh, e2 * sh, math.cos(0.5 * angle)
        product(dq, x[0:4], out[0:4])
    walk = s.gyro_bias_walk_rad_s_sqrt_s * math.sqrt(s.dt_s)
    for a in range(3):
        out[4 + a] = x[4 + a] + ins.bias[a] + s.gyro_noise_rad_s * normal(seed, stream, k, CH_GYRO + a)
        ins.bias[a] += walk * normal(seed, stream, k, CH_WALK + a)
        out[7 + a] = x[7 + a] + s.wheel_speed_noise_rad_s * normal(seed, stream, k, CH_WHEEL + a)
    out[10] = x[10] + s.temperature_noise_K * normal(seed, stream, k, CH_TEMP)
    out[11] = x[11] + s.energy_noise_J * normal(seed, stream, k, CH_ENERGY)


@numba.njit(**LEAF)
def actuate(u_cmd: Array, k: int, s: np.void, ins: np.void, out: Array) -> None:
    """The wheel accelerations (3,) the plant holds over sample k for the command u_cmd (before the
    actuator's saturation): the lag's mean over the hold plus torque noise. Exactly u_cmd when off;
    out may be u_cmd."""
    if not s.enabled:
        for a in range(3):
            out[a] = u_cmd[a]
        return
    tau = s.actuator_lag_s
    if tau > 0.0:
        decay = math.exp(-s.dt_s / tau)
        mean_gain = (tau / s.dt_s) * (1.0 - decay)
    else:
        decay, mean_gain = 0.0, 0.0
    for a in range(3):  # (out may be u_cmd)
        start, cmd = ins.u_end[a], u_cmd[a]
        ins.u_end[a] = cmd + (start - cmd) * decay
        out[a] = cmd + (start - cmd) * mean_gain + s.torque_noise_rad_s2 * normal(s.seed, s.stream, k, CH_TORQUE + a)


class Instruments:
    """The sensors and the actuator of one run, stepped from Python (the plant node, the stepped loop):
    `measure(x, k)` then `actuate(u, k)` at each sample k, as the compiled loop calls them."""

    def __init__(self, cfg: Config, stream: int = 0) -> None:
        self.record = sensors_record(cfg, stream)
        self.state = new_instruments()

    def measure(self, x: Array, k: int) -> Array:
        """The measured state of sample k (19,) (advances the gyro bias: call once per sample)."""
        out = np.empty(STATE_SIZE)
        measure(np.ascontiguousarray(x, dtype=float), k, self.record[0], self.state[0], out)
        return out

    def actuate(self, u_cmd: Array, k: int) -> Array:
        """The wheel accelerations (3,) held over sample k for the command u_cmd (before saturation)."""
        out = np.empty(3)
        actuate(np.ascontiguousarray(u_cmd, dtype=float), k, self.record[0], self.state[0], out)
        return out


@numba.njit(**LEAF)
def _normals(seed: np.uint64, stream: np.uint64, n: int, channel: int, out: Array) -> None:
    for k in range(n):
        out[k] = normal(seed, stream, k, channel)


def normals(seed: int, stream: int, n: int, channel: int = 0) -> Array:
    """Draws k = 0..n-1 of one channel (n,) (for tests and statistics)."""
    out = np.empty(n)
    _normals(np.uint64(seed), np.uint64(stream), n, channel, out)
    return out


__all__ = ["INSTRUMENT_DTYPE", "SENSORS_DTYPE", "Instruments", "actuate", "measure", "new_instruments", "normal",
           "normals", "reset_instruments", "sensors_record"]
