"""What a flight log's autopilot gives the continuous fit: its calibration, its attitude.

**Held blocks.** An autopilot logs its IMU calibrated (PX4's ``sensor_combined``: m/s² and
rad/s in the body frame after its own calibration; ArduPilot's ``IMU``: the same), and a
flight turns the vehicle through little more than its yaw: gravity stays within a few tens of
degrees of the body's
down axis, so the accelerometer's gain and bias are not determined (``check_motion`` would
refuse the log) and the gyroscope's gain only about the yaw axis. The flight can determine the
compass (its gain, bias and the field's dip from the headings flown and the tilts of the legs)
and the interference term; holding the others at the autopilot's calibration lets the fit and
the verdict judge that. Held values: the accelerometer's gain ``g₀ I`` (PX4 and ArduPilot scale
their calibration to ``g₀`` = 9.80665 m/s², ``CONSTANTS_ONE_G`` / ``GRAVITY_MSS``) with zero bias,
the gyroscope's gain the identity; the gyroscope's bias is fitted (it drifts with temperature
and the trajectory determines it).

**The start.** A flight's magnetometer readings outline a narrow band of the ellipsoid (the
tilts are small) shifted by the interference (tens of µT against a 50 µT field): the ellipsoid
fit of :mod:`.initial` can start the fit in a wrong minimum. With the autopilot's attitude
estimate in the log, the start is its trajectory instead (turned about down by the field's
declination: the fit's world has the field in its x–z plane) and the magnetometer's gain, bias,
interference coefficients and field direction regressed on it (:func:`held_regression`). The
estimate only starts the fit: the likelihood then moves every rotation (the attitude as a prior
in the likelihood is not done).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .held_blocks import Held
from .model import LEVER, SLICES, STANDARD_GRAVITY, Data, State

__all__ = [
    "AUTOPILOT_BLOCKS",
    "attitude_start",
    "autopilot_held",
    "held_regression",
    "quaternion_rotations",
]

Array = NDArray[np.float64]

#: The blocks held for a flight log.
AUTOPILOT_BLOCKS = ("accel.gain", "accel.bias", "gyro.gain")


def autopilot_held(
    autopilot: str, gravity: float = STANDARD_GRAVITY, *, source: str | None = None
) -> Held:
    """The blocks of :data:`AUTOPILOT_BLOCKS` at the calibration of ``autopilot`` (its name,
    for the record; ``source`` says otherwise, e.g. nominal values for raw readings): the
    accelerometer's gain ``gravity·I`` (its readings' units per unit of gravity), bias zero,
    the gyroscope's gain the identity (rad/s)."""
    mask = np.zeros(LEVER.stop, dtype=bool)
    mask[SLICES["accel"]] = True
    mask[22:31] = True  # the gyroscope's gain (:data:`.model.SLICES`)
    values = {
        "accel.gain": (gravity * np.eye(3)).ravel(),
        "accel.bias": np.zeros(3),
        "gyro.gain": np.eye(3).ravel(),
    }
    where = source or f"{autopilot}'s calibration (the log's values)"
    return Held(AUTOPILOT_BLOCKS, values, mask, where)


def quaternion_rotations(q: Array) -> Array:
    """World → body rotation matrices (n, 3, 3) from body → NED quaternions (scalar first)."""
    w, x, y, z = np.asarray(q, dtype=float).T
    C = np.empty((len(w), 3, 3))  # body -> world
    C[:, 0, 0] = 1 - 2 * (y * y + z * z)
    C[:, 0, 1] = 2 * (x * y - w * z)
    C[:, 0, 2] = 2 * (x * z + w * y)
    C[:, 1, 0] = 2 * (x * y + w * z)
    C[:, 1, 1] = 1 - 2 * (x * x + z * z)
    C[:, 1, 2] = 2 * (y * z - w * x)
    C[:, 2, 0] = 2 * (x * z - w * y)
    C[:, 2, 1] = 2 * (y * z + w * x)
    C[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return np.transpose(C, (0, 2, 1))


def _direction(h0: Array, x: Array) -> Array:
    """The unit direction ``h0`` moved by ``x`` (2,) in the plane orthogonal to it."""
    e1 = np.cross(h0, [1.0, 0.0, 0.0] if abs(h0[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(h0, e1)
    h = h0 + x[0] * e1 + x[1] * e2
    return np.asarray(h / np.linalg.norm(h), dtype=float)


def held_regression(mag: Array, R: Array, U: Array, h0: Array) -> tuple[Array, Array, Array]:
    """Each magnetometer axis regressed on ``[R_j ĥ, 1, U_j]`` with the rotations ``R`` held,
    from the field's direction ``h0``: (β (4+k, 3), the design X, ĥ). The linear parameters
    eliminated (variable projection), the field's two angles by Levenberg–Marquardt on the
    projected residuals."""
    n = len(mag)

    def design(x: Array) -> Array:
        return np.column_stack([R @ _direction(h0, x), np.ones(n), U])

    def projected(x: Array) -> Array:
        X = design(x)
        return np.ravel(mag - X @ np.linalg.lstsq(X, mag, rcond=None)[0])

    from scipy.optimize import least_squares  # here: its import costs a calibration 0.2 s

    x = least_squares(projected, np.zeros(2), method="lm", xtol=1e-12, ftol=1e-14).x
    X = design(x)
    beta = np.asarray(np.linalg.lstsq(X, mag, rcond=None)[0], dtype=np.float64)
    return beta, X, _direction(h0, x)


#: Degrees the attitude must turn away from its start (95th percentile) for the start to
#: regress the magnetometer on it; less (a few seconds of hover), the readings are taken as the
#: autopilot calibrated them: gain ``|m| I``, bias zero, the field's direction their mean.
MIN_TURN_DEG = 45.0


def _turned(ned: Array) -> float:
    """The 95th percentile of each attitude's angle from the first (radians)."""
    relative = ned @ ned[0].T
    cos = np.clip((np.trace(relative, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.percentile(np.arccos(cos), 95))


def attitude_start(state: State, data: Data, attitude: Array) -> State:
    """``state`` (the ellipsoids' start) with the trajectory of the autopilot's ``attitude``
    (n, 4: body → NED, scalar first) and the magnetometer's parameters regressed on it (the
    module docstring), or as the autopilot calibrated them when it barely turned
    (:data:`MIN_TURN_DEG`)."""
    ned = quaternion_rotations(attitude)
    body = np.linalg.solve(state.mag_gain, (data.mag - state.mag_bias).T).T
    world = np.einsum("nji,nj->ni", ned, body)
    h0 = np.median(world, axis=0)
    h0 /= max(float(np.linalg.norm(h0)), 1e-300)
    k = len(state.interference)
    U = np.zeros((len(ned), 0)) if data.inputs is None or k == 0 else data.inputs[:, :k]
    if _turned(ned) < np.radians(MIN_TURN_DEG):  # a regression on it would be noise
        strength = float(np.median(np.linalg.norm(data.mag, axis=1)))
        world = np.einsum("nji,nj->ni", ned, data.mag)
        h = np.median(world, axis=0) / max(float(np.linalg.norm(np.median(world, axis=0))), 1e-300)
        gain, beta = strength * np.eye(3), np.zeros((4 + k, 3))
    else:
        beta, _, h = held_regression(data.mag, ned, U, h0)
        gain = beta[:3].T
    if np.linalg.det(gain) < 0:  # (−K, −ĥ) reads the same: the unmirrored one (fieldcal's gauge)
        gain, h = -gain, -h
    declination = float(np.arctan2(h[1], h[0]))
    c, s = np.cos(declination), np.sin(declination)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # fit's world → NED
    out = state.copy()
    out.rotations = ned @ turn
    out.mag_gain = gain
    out.mag_bias = beta[3]
    out.dip = float(np.arctan2(h[2], np.hypot(h[0], h[1])))
    if U.shape[1]:
        out.interference = beta[4 : 4 + k]
    return out
