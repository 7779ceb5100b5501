"""Predicted errors after calibration in the user's terms: tilt, heading, |a|, |m|.

A corrected reading is ``v̂ = K̂⁻¹ (raw − b̂)`` with ``raw = K v + b + n``. To first order its
error is ``δv = K⁻¹ (n − δK v − δb)``: the parameters' errors (covariance from the fit) and the
pose-level noise ``n ~ N(0, q² I)``, the part of a still reading's error that does not average
away. From ``δv`` (``docs/trust.md``):

- tilt: the angle between the true and corrected gravity directions, ``|(I − vvᵀ) δv|``;
- ``|a|``, ``|m|``: the relative error of the norm, ``vᵀ δv``;

each as an RMS over orientations spread evenly on the sphere (a Fibonacci lattice);

- heading: a tilt-compensated compass heading for a level device (body z down), RMS over
  headings, with the gradient with respect to every gain and bias of both sensors and both
  noise vectors taken by finite differences of the heading formula itself.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..calibration import Accuracy, Calibration, ParameterCovariance

__all__ = ["predict_accuracy"]

Array = NDArray[np.float64]

_ORIENTATIONS = 128
_HEADINGS = 36


def _sphere(n: int) -> Array:
    """``n`` unit vectors spread evenly on the sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


_SPHERE = _sphere(_ORIENTATIONS)
_SPHERE.setflags(write=False)


def _level(n: int) -> Array:
    """World → body rotations of a level device at ``n`` headings: yaws about the down axis."""
    psi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    c, s = np.cos(psi), np.sin(psi)
    R = np.zeros((n, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, s, -s, c, 1.0
    return R


_LEVEL = _level(_HEADINGS)
_LEVEL.setflags(write=False)


def _param_block(cov: ParameterCovariance | None, sensor: str) -> Array:
    """(12, 12) covariance of ``vec(K)`` (row-major) and ``b`` of one sensor (zeros if none)."""
    block = None if cov is None else cov.sensor_blocks.get(sensor)
    if block is None or len(block.names) != 12:  # gains and biases, in this order, or nothing
        return np.zeros((12, 12))
    return block.matrix


def _reading_error_cov(cal: Calibration, sensor: str, v: Array) -> Array:
    """(M, 3, 3): covariance of ``δv`` for body vectors ``v`` (M, 3) of unit length."""
    sc = cal.sensor(sensor)
    ref = np.linalg.norm(cal.reference(sensor))
    u = v * ref  # the field in the calibration's units
    G = np.zeros((len(u), 3, 12))  # d(K u + b)/d[vec K, b]
    for j in range(3):
        G[:, j, 3 * j : 3 * j + 3] = u
        G[:, j, 9 + j] = 1.0
    C = G @ _param_block(cal.covariance, sensor) @ G.transpose(0, 2, 1)
    C = C + sc.pose_noise_std**2 * np.eye(3)
    Kinv = np.linalg.inv(sc.gain)
    return np.asarray(Kinv @ C @ Kinv.T / (ref * ref))  # relative to the field's magnitude


def _norm_and_direction(cal: Calibration, sensor: str) -> tuple[float, float]:
    v = _SPHERE
    C = _reading_error_cov(cal, sensor, v)
    radial = np.einsum("ni,nij,nj->n", v, C, v)
    perp = np.trace(C, axis1=1, axis2=2) - radial
    return float(np.sqrt(radial.mean())), float(np.degrees(np.sqrt(max(perp.mean(), 0.0))))


def _heading(a: Array, m: Array) -> Array:
    """Heading (rad) of the body x axis from body-frame specific force and field, (..., 3).

    North in the body frame is ``(d × m) × d = m |d|² − d (d·m)`` with ``d = −a`` the down
    direction (the field's horizontal part): scale does not change its heading, so nothing is
    normalised."""
    d0, d1, d2 = -a[..., 0], -a[..., 1], -a[..., 2]
    m0, m1, m2 = m[..., 0], m[..., 1], m[..., 2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    dm = d0 * m0 + d1 * m1 + d2 * m2
    return np.asarray(np.arctan2(d1 * dm - m1 * dd, m0 * dd - d0 * dm))


def _heading_error(cal: Calibration) -> float | None:
    if cal.accel is None or cal.mag is None or cal.gravity is None or cal.magnetic is None:
        return None
    raw = {
        name: (_LEVEL @ cal.reference(name)) @ cal.sensor(name).gain.T + cal.sensor(name).bias
        for name in ("accel", "mag")
    }
    # parameters: vec K_a, b_a, vec K_m, b_m (24), then noise n_a, n_m (6)
    base = {n: (cal.sensor(n).gain, cal.sensor(n).bias) for n in ("accel", "mag")}
    # one step per sensor, in its own raw units (the two gains may differ by 10^4): each
    # sensor's parameter and noise rows are perturbed by its step and divided by it below
    steps = np.ones(31)
    # corrected readings (31, H, 3) per sensor: unperturbed, then one row per parameter
    corrected = {}
    for k, name in enumerate(("accel", "mag")):
        K, b = base[name]
        step = 1e-6 * float(np.abs(K).max())
        steps[1 + 12 * k : 13 + 12 * k] = step
        steps[25 + 3 * k : 28 + 3 * k] = step
        # one solve gives the corrected readings and K⁻¹ (the right-hand sides' last columns)
        solved = np.linalg.solve(K, np.column_stack([(raw[name] - b).T, np.eye(3)]))
        u, Kinv = solved[:, :_HEADINGS].T, solved[:, _HEADINGS:]
        rows = np.broadcast_to(u, (31, _HEADINGS, 3)).copy()
        # a gain entry K[j, l] + s: Sherman-Morrison, u − s K⁻¹e_j u_l / (1 + s K⁻¹[l, j])
        j, col = np.divmod(np.arange(9), 3)
        denom = 1.0 + step * Kinv[col, j]
        first = 1 + 12 * k
        along = step * u[:, col].T / denom[:, None]  # (9, H): s u_l / (1 + s K⁻¹[l, j])
        rows[first : first + 9] -= along[:, :, None] * Kinv[:, j].T[:, None, :]
        # a bias b_j + s moves the reading by −s K⁻¹e_j, a noise n_j + s by +s K⁻¹e_j
        rows[first + 9 : first + 12] -= step * Kinv.T[:, None, :]
        rows[25 + 3 * k : 28 + 3 * k] += step * Kinv.T[:, None, :]
        corrected[name] = rows
    both = _heading(corrected["accel"], corrected["mag"])
    wrapped = np.remainder(both[1:] - both[0] + np.pi, 2.0 * np.pi) - np.pi
    J = (wrapped / steps[1:, None]).T  # (H, 30)
    C = np.zeros((30, 30))
    C[:12, :12] = _param_block(cal.covariance, "accel")
    C[12:24, 12:24] = _param_block(cal.covariance, "mag")
    if cal.covariance is not None:  # the two sensors' parameters are correlated through the poses
        names = [f"accel.gain[{j},{k}]" for j in range(3) for k in range(3)]
        names += [f"accel.bias[{j}]" for j in range(3)]
        other = [n.replace("accel", "mag") for n in names]
        if all(n in cal.covariance.names for n in names + other):
            ia = [cal.covariance.index(n) for n in names]
            im = [cal.covariance.index(n) for n in other]
            C[:12, 12:24] = cal.covariance.matrix[np.ix_(ia, im)]
            C[12:24, :12] = C[:12, 12:24].T
    C[24:27, 24:27] = np.eye(3) * cal.sensor("accel").pose_noise_std ** 2
    C[27:30, 27:30] = np.eye(3) * cal.sensor("mag").pose_noise_std ** 2
    var = np.einsum("hp,hp->h", J @ C, J)
    return float(np.degrees(np.sqrt(max(var.mean(), 0.0))))


def predict_accuracy(cal: Calibration) -> Accuracy:
    """The predicted 1σ (RMS) errors of :class:`~fieldcal.calibration.Accuracy` for ``cal``."""
    accel_norm = tilt = mag_norm = None
    if cal.accel is not None and cal.gravity is not None:
        accel_norm, tilt = _norm_and_direction(cal, "accel")
    if cal.mag is not None and cal.magnetic is not None:
        mag_norm, _ = _norm_and_direction(cal, "mag")
    return Accuracy(
        tilt_deg=tilt,
        heading_deg=_heading_error(cal),
        accel_norm_rel=accel_norm,
        mag_norm_rel=mag_norm,
    )
