"""The errors a calibration makes on a simulated device, measured against its truth: what
:func:`fieldcal.trust.accuracy.predict_accuracy` predicts, computed directly.

Readings of the true device (``raw = K v + b(T)``, no noise) are corrected by the calibration
at the same temperature; over orientations spread evenly on the sphere (a Fibonacci lattice)
and, for the heading, a level device (body z down) at evenly spaced headings, each at
temperatures spread over the span: the RMS of the tilt error (the angle between the corrected
and the true gravity direction), of the relative errors of ``|a|`` and ``|m|``, and of the
tilt-compensated heading's error. The benchmarks and the tests compare the prediction with it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..geometry.orientations import fibonacci_sphere

__all__ = ["measured_accuracy"]

Array = NDArray[np.float64]
#: ``drift(sensor, temperatures)``: the true bias's change, (n, 3) raw units.
Drift = Callable[[str, Array], Array]


def _heading(a: Array, m: Array) -> Array:
    """The heading of the body x axis from specific force and field (n, 3): north is the
    field's part across the down direction ``d = −a``."""
    d = -a
    north = m * np.sum(d * d, axis=1)[:, None] - d * np.sum(d * m, axis=1)[:, None]
    return np.arctan2(-north[:, 1], north[:, 0])


def _corrected(
    cal: Calibration, truth: Calibration, sensor: str, v: Array, T: Array, drift: Drift
) -> Array:
    """The calibration's correction of the true device's readings of the body-frame field
    values ``v`` (n, 3) at temperatures ``T`` (n,)."""
    true, est = truth.sensor(sensor), cal.sensor(sensor)
    raw = v @ true.gain.T + true.bias + drift(sensor, T)
    if est.temperature is not None:
        raw = raw - est.temperature.shift(T)
    out: Array = np.asarray(np.linalg.solve(est.gain, (raw - est.bias).T).T, dtype=float)
    return out


def measured_accuracy(
    cal: Calibration,
    truth: Calibration,
    span: tuple[float, float] | None = None,
    drift: Drift | None = None,
    *,
    orientations: int = 128,
    headings: int = 36,
    temperatures: int = 9,
) -> dict[str, float]:
    """RMS errors of ``cal`` on the device ``truth`` describes (its gains, biases and field
    values in the same gauge), over orientations, headings and the temperatures of ``span``.

    Parameters
    ----------
    cal, truth : Calibration
        The estimate and the true device (``truth.gravity``/``truth.magnetic``: the true
        fields in its world frame).
    span : (float, float), optional
        The temperatures (°C) to average over; ``None``: one temperature, no drift.
    drift : callable, optional
        ``drift(sensor, T)`` the true biases' change with temperature (raw units).

    Returns
    -------
    dict
        ``tilt_deg``, ``heading_deg``, ``accel_norm_rel``, ``mag_norm_rel`` (those the two
        calibrations hold).
    """
    temps = np.array([0.0]) if span is None else np.linspace(span[0], span[1], temperatures)

    def shift(sensor: str, T: Array) -> Array:
        return np.zeros((len(T), 3)) if drift is None else drift(sensor, T)

    out: dict[str, float] = {}
    v = fibonacci_sphere(orientations)
    grid_v = np.tile(v, (len(temps), 1))
    grid_t = np.repeat(temps, len(v))
    for sensor, norm_key in (("accel", "accel_norm_rel"), ("mag", "mag_norm_rel")):
        if getattr(cal, sensor) is None or getattr(truth, sensor) is None:
            continue
        f_true = float(np.linalg.norm(truth.reference(sensor)))
        f_est = float(np.linalg.norm(cal.reference(sensor)))
        got = _corrected(cal, truth, sensor, f_true * grid_v, grid_t, shift)
        n = np.linalg.norm(got, axis=1)
        out[norm_key] = float(np.sqrt(np.mean((n / f_est - 1.0) ** 2)))
        if sensor == "accel":
            cos = np.clip(np.sum(got / n[:, None] * grid_v, axis=1), -1.0, 1.0)
            out["tilt_deg"] = float(np.degrees(np.sqrt(np.mean(np.arccos(cos) ** 2))))
    if cal.mag is not None and cal.accel is not None and truth.gravity is not None:
        assert truth.magnetic is not None
        psi = np.linspace(0.0, 2 * np.pi, headings, endpoint=False)
        c, s = np.cos(psi), np.sin(psi)
        R = np.zeros((headings, 3, 3))  # world -> body of a level device at each heading
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, s, -s, c, 1.0
        R = np.tile(R, (len(temps), 1, 1))
        T = np.repeat(temps, headings)
        a_true, m_true = R @ truth.gravity, R @ truth.magnetic
        a = _corrected(cal, truth, "accel", a_true, T, shift)
        m = _corrected(cal, truth, "mag", m_true, T, shift)
        err = np.remainder(_heading(a, m) - _heading(a_true, m_true) + np.pi, 2 * np.pi) - np.pi
        out["heading_deg"] = float(np.degrees(np.sqrt(np.mean(err**2))))
    return out
