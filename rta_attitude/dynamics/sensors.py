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

from rta_attitude.config.loader import CELSIUS_OFFSET_K
from rta_attitude.config.schema import Config
from rta_attitude.dynamics.environment import sun_hill
from rta_attitude.dynamics.quaternion import attitude_matrix, product
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
    ("bus_voltage_V", np.float64),         # BatteryState.charge = E / (V 3600) (`encode`)
    ("wheel_sign", np.float64),            # spacecraft.torque_sign s: the rotors spin at -s psi
    ("sun_cos_beta", np.float64),          # the sun's beta angle: the sun vector's message (`encode`)
    ("sun_sin_beta", np.float64),
])  # fmt: skip

# the fields of the message interface (see "the interface" below), in their order
F_Q, F_OMEGA, F_POS, F_VEL_BODY, F_WHEEL, F_TEMP_C, F_CHARGE_AH, F_SUN = 0, 4, 7, 10, 13, 16, 17, 18
FIELD_SIZE = 21

INSTRUMENT_DTYPE = np.dtype([
    ("bias", np.float64, (3,)),            # the gyro bias now, rad/s
    ("u_end", np.float64, (3,)),           # the actuator's output at the end of the last hold, rad/s^2
    ("u_inflight", np.float64, (3,)),      # what the wheels held over the last hold (saturated): over the
                                           # next one's transport delay (`spacecraft.rk4_delayed`), rad/s^2
    ("started", np.uint8),                 # bias drawn
    ("dq", np.float64, (4,)),              # scratch: the attitude error's quaternion
    ("A", np.float64, (3, 3)),             # scratch: A(q) of `deliver`
    ("fields", np.float64, (FIELD_SIZE,)),  # scratch: the message fields of `deliver`
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
    r["bus_voltage_V"], r["wheel_sign"] = cfg.power.bus_voltage_V, cfg.spacecraft.torque_sign
    beta = cfg.environment.sun_beta_rad
    r["sun_cos_beta"], r["sun_sin_beta"] = math.cos(beta), math.sin(beta)
    return rec


def new_instruments() -> NDArray[np.void]:
    """A fresh INSTRUMENT_DTYPE record (1,): the bias is drawn at the first measurement."""
    return np.zeros(1, INSTRUMENT_DTYPE)


@numba.njit(**LEAF)
def reset_instruments(ins: np.void) -> None:
    """Back to a fresh INSTRUMENT_DTYPE record (a new run): the bias is drawn again at the first
    measurement, the lag and the transport delay start from rest."""
    ins.started = 0
    for a in range(3):
        ins.bias[a] = 0.0
        ins.u_end[a] = 0.0
        ins.u_inflight[a] = 0.0


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


# ----------------------------------------------------------------------------- the interface
# What crosses the flight software's interface: the fields of the standard messages that carry a measured
# state (docs/ros_interface.md), in this order. `encode` writes them, `decode` rebuilds the state a reader
# gets from them; the plant node publishes `encode`'s fields, the controller and filter nodes `decode` what
# they receive, and the in-process loops hand the controller and the filter `deliver(y) = decode(encode(y))`,
# so that a run over DDS equals `simulate` bit for bit. Not the identity: the charge is a float32 (E back to
# |E| 2^-24, ~4.4e-4 J at 7,300 J), theta_S comes back through atan2 (in (-pi, pi], to an ulp), the CW
# velocity through A(q) and back; T through degC and back (exact for 136.6-546.3 K).
FIELD_MESSAGES: dict[str, tuple[int, int]] = {
    "Odometry.pose.pose.orientation (x y z w)": (F_Q, 4), "Odometry.twist.twist.angular [rad/s]": (F_OMEGA, 3),
    "Odometry.pose.pose.position (Hill) [m]": (F_POS, 3), "Odometry.twist.twist.linear (body) [m/s]": (F_VEL_BODY, 3),
    "JointState.velocity (rotor speeds, -s psi) [rad/s]": (F_WHEEL, 3), "Temperature.temperature [degC]": (F_TEMP_C, 1),
    "BatteryState.charge (float32) [Ah]": (F_CHARGE_AH, 1), "Vector3Stamped.vector (sun, Hill)": (F_SUN, 3),
}  # fmt: skip
"""Where each message field sits in the FIELD_SIZE vector (first index, length)."""
SECONDS_PER_HOUR = 3600.0
ENERGY_RELATIVE_ERROR = 2.0**-24 + 2.0**-51
"""|E(read) - E| <= this |E|: the float32 charge (half an ulp, 2^-24 relative) and the double roundings of
the division and the product (2^-53 each, with room)."""


def interface_energy_error(cfg: Config) -> float:
    """Bound on |E(read) - E(measured)| wherever E < E_min (where a battery violation can hide): a filter
    that keeps the read E >= E_min + this keeps the measured E >= E_min (if E < E_min, E(read) <= E (1 +
    rel) < E_min + rel E_min)."""
    return ENERGY_RELATIVE_ERROR * abs(cfg.limits.energy_min_J)


@numba.njit(**LEAF)
def encode(y: Array, s: np.void, A: Array, out: Array) -> None:
    """The message fields (FIELD_SIZE,) of the state y (19,) into out; A: a (3, 3) scratch."""
    for i in range(4):
        out[F_Q + i] = y[i]
    attitude_matrix(y[0], y[1], y[2], y[3], A)
    for a in range(3):
        out[F_OMEGA + a] = y[4 + a]
        out[F_POS + a] = y[13 + a]
        out[F_VEL_BODY + a] = A[a, 0] * y[16] + A[a, 1] * y[17] + A[a, 2] * y[18]
        out[F_WHEEL + a] = -s.wheel_sign * y[7 + a]
    out[F_TEMP_C] = y[10] - CELSIUS_OFFSET_K
    out[F_CHARGE_AH] = np.float32(y[11] / (s.bus_voltage_V * SECONDS_PER_HOUR))
    out[F_SUN], out[F_SUN + 1], out[F_SUN + 2] = sun_hill(y[12], s.sun_cos_beta, s.sun_sin_beta)


@numba.njit(**LEAF)
def decode(f: Array, s: np.void, A: Array, out: Array) -> None:
    """The state (19,) a reader rebuilds from the message fields f (FIELD_SIZE,) into out; A: a (3, 3)
    scratch. The CW velocity comes back through the received attitude (A(q)^T)."""
    for i in range(4):
        out[i] = f[F_Q + i]
    attitude_matrix(f[F_Q], f[F_Q + 1], f[F_Q + 2], f[F_Q + 3], A)
    for a in range(3):
        out[4 + a] = f[F_OMEGA + a]
        out[7 + a] = -s.wheel_sign * f[F_WHEEL + a]
        out[13 + a] = f[F_POS + a]
        out[16 + a] = A[0, a] * f[F_VEL_BODY] + A[1, a] * f[F_VEL_BODY + 1] + A[2, a] * f[F_VEL_BODY + 2]
    out[10] = f[F_TEMP_C] + CELSIUS_OFFSET_K
    out[11] = f[F_CHARGE_AH] * (s.bus_voltage_V * SECONDS_PER_HOUR)
    out[12] = math.atan2(f[F_SUN + 1], f[F_SUN])


@numba.njit(**LEAF)
def deliver(y: Array, s: np.void, A: Array, fields: Array, out: Array) -> None:
    """The state the controller and the filter get for the measured y (19,): decode(encode(y)), into out
    (A (3, 3), fields (FIELD_SIZE,): scratch)."""
    encode(y, s, A, fields)
    decode(fields, s, A, out)


@numba.njit(**LEAF)
def read(x: Array, k: int, s: np.void, ins: np.void, y: Array, out: Array) -> None:
    """Sample k as the flight software reads it: the measured state y (`measure`) and what crosses the
    interface into out (`deliver`)."""
    measure(x, k, s, ins, y)
    deliver(y, s, ins.A, ins.fields, out)


@numba.njit(**LEAF)
def _encode(y: Array, s: NDArray[np.void], A: Array, out: Array) -> None:
    encode(y, s[0], A, out)


@numba.njit(**LEAF)
def _decode(f: Array, s: NDArray[np.void], A: Array, out: Array) -> None:
    decode(f, s[0], A, out)


def message_fields(y: Array, record: NDArray[np.void]) -> Array:
    """`encode` of one state (19,) with a SENSORS_DTYPE record (1,): the fields (FIELD_SIZE,)."""
    out = np.empty(FIELD_SIZE)
    _encode(np.ascontiguousarray(y, dtype=float), record, np.empty((3, 3)), out)
    return out


def state_from_fields(f: Array, record: NDArray[np.void]) -> Array:
    """`decode` of one field vector (FIELD_SIZE,) with a SENSORS_DTYPE record (1,): the state (19,)."""
    out = np.empty(STATE_SIZE)
    _decode(np.ascontiguousarray(f, dtype=float), record, np.empty((3, 3)), out)
    return out


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

    def deliver(self, y: Array) -> Array:
        """What the controller and the filter get for the measured state y (19,) (`deliver`)."""
        out = np.empty(STATE_SIZE)
        ins = self.state[0]
        deliver(np.ascontiguousarray(y, dtype=float), self.record[0], ins["A"], ins["fields"], out)
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


__all__ = ["ENERGY_RELATIVE_ERROR", "FIELD_MESSAGES", "FIELD_SIZE", "F_CHARGE_AH", "F_OMEGA", "F_POS", "F_Q", "F_SUN",
           "F_TEMP_C",
           "F_VEL_BODY", "F_WHEEL", "INSTRUMENT_DTYPE", "SENSORS_DTYPE", "Instruments", "actuate", "decode",
           "deliver", "encode", "interface_energy_error", "measure", "message_fields", "new_instruments",
           "normal", "normals", "read",
           "reset_instruments", "sensors_record", "state_from_fields"]
