"""Fitting the magnetometer's interference term (Eq. I1, :mod:`fieldcal.interference`) with the
orientation trajectory held: a second stage after the calibration.

The trajectory is the autopilot's attitude estimate when the log has one (a flight log), else
the continuous-motion fit's rotations (interpolated between its kept epochs). With ``R_j``
held, Eq. I1 is linear in everything else but the field's direction: each magnetometer axis
``r`` regresses on ``[R_j ĥ, 1, u_j]`` — the gain (``A = K_m |h|``, a full 3×3 matrix: it also
takes in any rotation between the magnetometer's and the trajectory's frames), the bias and the
coefficients jointly, by least squares, which is the likelihood's maximum for Gaussian noise of
one variance per axis; the unit direction ``ĥ`` (world frame) alternates with them until it
settles. So the gains and biases are refitted with the term (the first stage's absorbed it),
and only the trajectory is held — what this stage does not do is let the trajectory move with
the term (``docs/flight-logs.md`` says why that is a small loss when the current varies
independently of the orientation, and that the autopilot's estimate may itself have been
pulled by the interference).

Error bars: the residuals of a flight are correlated (the trajectory's errors, body
acceleration, vibration), so the coefficients' standard errors are the sandwich over
contiguous blocks (:data:`BLOCKS`, Bartlett weights over :data:`LAG` neighbours: Newey–West on
the blocks' scores, with the small-sample factor ``B/(B−1)``). The Cramér–Rao bound is the
same regression's for white noise of the variance half the residuals' first differences show
(the sensor's own noise, the slow errors left out): the best a log of this length and
excitation can give.

Identifiability: the term is determined only when the input varies, and independently of the
orientation: the input's span (at least :data:`MIN_SPAN`) and its share not explained by
the field's body-frame direction and a constant (``1 − R²`` at least :data:`MIN_FREE`) are
checked, and when either fails the coefficients are not reported (zeros, ``identifiable``
false) and ``reason`` says what to fly.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..interference import MIN_FREE, MIN_SPAN, InterferenceModel, summarised
from ..methods.continuous.autopilot_aid import held_regression, quaternion_rotations

__all__ = [
    "BLOCKS",
    "FAIL_SHARE",
    "HEATER_SPAN_K",
    "LAG",
    "MIN_FREE",
    "MIN_SPAN",
    "WARN_SHARE",
    "fit_interference",
    "held_trajectory",
    "interference_reasons",
    "quaternion_rotations",
]

Array = NDArray[np.float64]

#: Contiguous blocks the sandwich sums the scores over, and the neighbouring blocks whose
#: scores' covariance it takes in (Bartlett weights). Lags made no difference beyond noise on
#: the simulated flights (benchmarks/flight.py: 94 % coverage with 0, 88 % with 4, the
#: trajectory exact), so none by default.
BLOCKS = 40
LAG = 0
#: ArduPilot's guidance on compassmot's interference, as a share of the Earth's field: "less
#: than 30% ... acceptable", "31% ~ 60% ... grey zone", "higher than 60% you should try moving
#: your APM/PX further up and away from the sources of interference" (ArduPilot/ardupilot_wiki,
#: common/source/docs/common-compass-setup-advanced.rst, "CompassMot", commit 055ae21a).
WARN_SHARE = 0.30
FAIL_SHARE = 0.60
#: A temperature that moves this much during the log gets its own term (a heater).
HEATER_SPAN_K = 5.0


def _sandwich(X: Array, E: Array, blocks: int) -> tuple[Array, Array]:
    """Per axis, the coefficients' covariance (3, p, p): the sandwich over contiguous blocks
    with Bartlett weights over :data:`LAG` neighbouring blocks (Newey–West on the blocks'
    scores: a flight's residuals stay correlated longer than a block); and the white-noise
    bread ``(XᵀX)⁻¹`` (p, p)."""
    bread = np.asarray(np.linalg.inv(X.T @ X), dtype=np.float64)
    edges = np.linspace(0, len(X), blocks + 1).astype(int)
    lag = min(LAG, blocks - 1)
    cov = np.empty((3, X.shape[1], X.shape[1]))
    for r in range(3):
        scores = np.add.reduceat(X * E[:, r : r + 1], edges[:-1], axis=0)
        meat = scores.T @ scores
        for step in range(1, lag + 1):
            across = scores[step:].T @ scores[:-step]
            meat += (1.0 - step / (lag + 1.0)) * (across + across.T)
        cov[r] = bread @ meat @ bread * blocks / (blocks - 1)
    return cov, bread


def fit_interference(
    mag: Array,
    rotations: Array,
    inputs: dict[str, Array],
    *,
    start_gain: Array,
    start_bias: Array,
    temperature: Array | None = None,
    trajectory: str = "",
) -> InterferenceModel:
    """The interference term of a log (the module docstring says how).

    Parameters
    ----------
    mag : (n, 3) array
        Raw magnetometer readings, as logged.
    rotations : (n, 3, 3) array
        World → body rotations at each reading, held.
    inputs : dict
        ``{"current": (n,)}`` (A) or ``{"throttle": (n,)}`` (0–1).
    start_gain, start_bias : arrays
        The first stage's magnetometer gain and bias: the field's world direction starts from
        the readings they correct.
    temperature : (n,) array, optional
        °C; a term of its own when it spans :data:`HEATER_SPAN_K` or more (a heater).
    trajectory : str
        Where ``rotations`` came from, for the record.

    Returns
    -------
    InterferenceModel
    """
    names = list(inputs)[:1]
    columns = [np.asarray(inputs[n], dtype=float) for n in names]
    if temperature is not None and np.ptp(temperature) >= HEATER_SPAN_K:
        names.append("temperature")
        columns.append(np.asarray(temperature, dtype=float))
    U0 = np.column_stack(columns)
    reference = U0.mean(axis=0)
    U = U0 - reference
    body = np.linalg.solve(start_gain, (mag - start_bias).T).T
    world = np.einsum("nji,nj->ni", rotations, body)
    h = np.median(world, axis=0)
    h /= np.linalg.norm(h)
    beta, X, h = held_regression(mag, rotations, U, h)
    E = mag - X @ beta
    blocks = max(2, min(BLOCKS, len(mag) // 20))
    cov, bread = _sandwich(X, E, blocks)
    std = np.sqrt(np.stack([np.diag(c)[4:] for c in cov], axis=1))  # (k, 3)
    white = np.var(np.diff(E, axis=0), axis=0) / 2.0
    crb = np.sqrt(np.outer(np.diag(bread)[4:], white))
    # the share of each input's variance the field's direction and a constant leave free
    Z = X[:, :4]
    fitted = Z @ np.linalg.lstsq(Z, U, rcond=None)[0]
    free = 1.0 - np.sum((fitted - U.mean(axis=0)) ** 2, axis=0) / np.maximum(
        np.sum((U - U.mean(axis=0)) ** 2, axis=0), 1e-300
    )
    A, C = beta[:3].T, beta[4:]
    field = float(np.median(np.linalg.norm(X[:, :3] @ A.T, axis=1)))
    return summarised(names, U0, (C, std, crb), (A, h, field), float(free[0]), trajectory)


def held_trajectory(
    attitude: Array | None, time: Array | None, cal_rotations: Array, epoch_step: int | None
) -> tuple[Array | None, str]:
    """The orientations to hold (n, 3, 3) and where they come from: the autopilot's attitude
    estimate, else the continuous fit's kept rotations interpolated (spherically) to every
    sample; ``(None, why not)`` without either."""
    if attitude is not None:
        return quaternion_rotations(attitude), "the autopilot's attitude estimate"
    if time is None or epoch_step is None or len(cal_rotations) < 2:
        return None, (
            "it needs the orientation at every sample: a flight log with the autopilot's "
            "attitude, or continuous motion with a gyroscope (--poses continuous)"
        )
    from scipy.spatial.transform import Rotation, Slerp  # here: a calibration's import saved

    at = np.asarray(time, dtype=float)[::epoch_step][: len(cal_rotations)]
    keys = Rotation.from_matrix(np.asarray(cal_rotations)[: len(at)])
    clipped = np.clip(time, at[0], at[-1])
    return Slerp(at, keys)(clipped).as_matrix(), "the continuous fit's trajectory"


def interference_reasons(model: InterferenceModel | None) -> list[tuple[str, dict[str, object]]]:
    """The verdict rules' findings on the term (codes of :data:`fieldcal.trust.verdict.
    RULES`): ``interference_not_identifiable``, ``interference`` above :data:`WARN_SHARE`,
    ``interference_unusable`` above :data:`FAIL_SHARE` of the Earth's field."""
    if model is None:
        return []
    name, unit = model.inputs[0], model.units[0]
    if not model.identifiable:
        return [("interference_not_identifiable", {"missing": model.reason, "input": name})]
    values = {
        "share": model.field_share,
        "input": name,
        "peak": float(model.span[0, 1]),
        "unit": unit,
        "heading": model.heading_error_deg,
        "corrected": model.heading_error_corrected_deg,
    }
    if model.field_share > FAIL_SHARE:
        return [("interference_unusable", values)]
    if model.field_share > WARN_SHARE:
        return [("interference", values)]
    return []
