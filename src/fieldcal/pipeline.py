"""From a log's poses to a calibration: the checks a log needs, ``fieldcal.calibrate``, the
magnetometer axis map folded back, and the JSON document the ``calibrate`` command writes."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import NoiseSpec, calibrate
from .calibration import Calibration
from .errors import InputError
from .logs import Log, PoseSet
from .logs.poses import poses_orientations
from .methods import get as get_method
from .stats.poses import check_spread, stats_from_means

__all__ = ["calibrate_log", "document", "fold_axes"]

Array = NDArray[np.float64]


def _check_poses(poses: PoseSet, method: str) -> None:
    n = poses.n
    sensors = [(name, getattr(poses, name)) for name in ("accel", "mag")]
    sensors = [(name, samples) for name, samples in sensors if samples is not None]
    need = get_method(method).min_poses_for(len(sensors))
    if n < need:
        raise InputError(
            f"{n} pose(s) found; the {method} method needs at least {need}"
            + (
                " (the 6N readings must outnumber the 3N pose angles plus 22 sensor parameters)"
                if len(sensors) == 2
                else ""
            )
            + f": hold the device still in {need - n} or more further orientations"
        )
    means = {name: np.array([p.mean(axis=0) for p in samples]) for name, samples in sensors}
    try:
        check_spread(stats_from_means(means.get("accel"), means.get("mag")))
    except ValueError as exc:
        raise InputError(str(exc)) from None
    # one sensor alone: 9 unknowns (symmetric gain and bias), one constraint per orientation
    need = max(need, 8 if len(sensors) == 2 else 9)
    distinct = len(set(poses_orientations(poses)))
    if distinct < need:
        raise InputError(
            f"the {n} poses show only {distinct} distinct orientations (closer than 3° count as "
            f"one); {'a joint' if len(sensors) == 2 else 'a single-sensor'} calibration needs at "
            f"least {need}: add poses tilted between the axes (e.g. resting on the edges and "
            "corners of a box), not only with each axis up and down"
        )


def fold_axes(cal: Calibration, P: Array, spec: str) -> Calibration:
    """Express a magnetometer calibration fitted on ``P @ raw`` in terms of the raw columns.

    ``P @ raw = K v + b`` means ``raw = Pᵀ K v + Pᵀ b``: the gain becomes ``Pᵀ K`` and the bias
    ``Pᵀ b``, so firmware applies the result to the readings as logged.
    """
    mag = cal.mag
    if mag is None:
        return cal
    Pt, A = P.T, np.abs(P.T)
    new = dataclasses.replace(
        mag,
        gain=Pt @ mag.gain,
        bias=Pt @ mag.bias,
        noise_cov=Pt @ mag.noise_cov @ P,
        noise_cov_std=None if mag.noise_cov_std is None else A @ mag.noise_cov_std @ A.T,
    )
    covariance = cal.covariance
    if covariance is not None:
        names = list(covariance.names)
        T = np.eye(len(names))
        # raw parameter (i, ...) = Σ_k Pᵀ[i, k] · fitted parameter (k, ...), per gain column
        triples = [[f"mag.gain[{r},{j}]" for r in range(3)] for j in range(3)]
        triples.append([f"mag.bias[{r}]" for r in range(3)])
        for triple in triples:
            if all(t in names for t in triple):
                idx = [names.index(t) for t in triple]
                T[np.ix_(idx, idx)] = Pt
        covariance = covariance.transformed(T)
    options = {**cal.options, "mag_axes": spec}
    poses = tuple(
        {**row, "mag_residual": list(Pt @ np.asarray(row["mag_residual"]))}
        if "mag_residual" in row
        else row
        for row in cal.poses
    )
    return dataclasses.replace(cal, mag=new, covariance=covariance, options=options, poses=poses)


def calibrate_log(
    log: Log,
    poses: PoseSet,
    *,
    method: str = "mle",
    gravity: float | None = None,
    field_strength: float | None = None,
    noise: NoiseSpec | None = None,
    mag_axes: str | None = None,
    P: Array | None = None,
    mag_mirrored: bool = False,
    **options: Any,
) -> Calibration:
    """Calibrate from the poses and attach each pose's log position to ``cal.poses``.

    ``P`` is the parsed ``mag_axes`` map, already applied to ``log.mag``; it is folded back so
    the calibration applies to the raw columns. Further ``options`` go to
    :func:`fieldcal.calibrate` (``pose_noise``, ``robust``, the method's options). Every pose
    found is listed; a pose the robust fit dropped has ``rejected`` set to the reason.
    """
    _check_poses(poses, method)
    # numpy's errors and warnings stay inside: calibrate says what is wrong in one line
    cal = calibrate(
        poses.accel,
        poses.mag,
        method=method,
        gravity=gravity,
        field_strength=field_strength,
        noise=noise,
        mag_mirrored=mag_mirrored,
        **options,
    )
    if P is not None and mag_axes is not None:
        cal = fold_axes(cal, P, mag_axes)
    fitted = {int(row["index"]): row for row in cal.poses}
    dropped = {r.index: r for r in cal.rejected}
    rows = []
    for i, entry in enumerate(poses.entries):
        row = {**fitted.get(i, {"index": i}), **entry}
        if i in dropped:
            row["rejected"] = f"{dropped[i].sensor}: {dropped[i].reason}"
        rows.append(row)
    options = {**cal.options, "log": log.path, "columns": log.used}
    return dataclasses.replace(cal, poses=tuple(rows), options=options)


def document(cal: Calibration, poses: PoseSet) -> dict[str, Any]:
    """The calibration JSON with the still detection's parameters (``still_detection``)."""
    doc = cal.to_dict()
    if poses.detection is not None:
        doc["still_detection"] = {**poses.detection.to_dict(), "rate_hz": poses.rate}
    return doc
