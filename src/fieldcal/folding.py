"""A convention folded back into a calibration: a result fitted on mapped readings (the
magnetometer's axis map, an accelerometer that reports gravity, a gyroscope's unit) expressed
in terms of the raw columns as logged, with its covariance, temperature terms and pose
residuals (moved from ``fieldcal.pipeline``, which still exports :func:`fold_axes`)."""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from .calibration import Calibration

__all__ = ["fold_axes"]

Array = NDArray[np.float64]


def fold_axes(
    cal: Calibration, P: Array, spec: str, sensor: str = "mag", option: str | None = None
) -> Calibration:
    """Express a calibration fitted on ``P @ raw`` in terms of the raw columns.

    ``P @ raw = K v + b`` means ``raw = Pᵀ K v + Pᵀ b``: the gain becomes ``Pᵀ K`` and the bias
    ``Pᵀ b``, so firmware applies the result to the readings as logged. Used for the
    magnetometer's axis map (``spec`` recorded as ``options["mag_axes"]``) and for an
    accelerometer that reports gravity (``P = −I``, ``options["accel_sign"]``). The bias's
    temperature terms fold the same way, ``c_k → Pᵀ c_k`` (:mod:`fieldcal.thermal`).
    """
    fitted = getattr(cal, sensor)
    if fitted is None:
        return cal
    Pt, A = P.T, np.abs(P.T)
    new = dataclasses.replace(
        fitted,
        gain=Pt @ fitted.gain,
        bias=Pt @ fitted.bias,
        noise_cov=Pt @ fitted.noise_cov @ P,
        noise_cov_std=None if fitted.noise_cov_std is None else A @ fitted.noise_cov_std @ A.T,
        temperature=None
        if fitted.temperature is None
        else dataclasses.replace(
            fitted.temperature, coefficients=fitted.temperature.coefficients @ P, std=None
        ),
        interference=None  # c_i → Pᵀ c_i, as the temperature terms
        if fitted.interference is None
        else dataclasses.replace(
            fitted.interference,
            coefficients=fitted.interference.coefficients @ P,
            std=fitted.interference.std @ np.abs(P),
            crb=fitted.interference.crb @ np.abs(P),
        ),
    )
    covariance = cal.covariance
    if covariance is not None:
        names = list(covariance.names)
        T = np.eye(len(names))
        # raw parameter (i, ...) = Σ_k Pᵀ[i, k] · fitted parameter (k, ...), per gain column
        triples = [[f"{sensor}.gain[{r},{j}]" for r in range(3)] for j in range(3)]
        triples.append([f"{sensor}.bias[{r}]" for r in range(3)])
        order = 0 if fitted.temperature is None else fitted.temperature.order
        triples += [[f"{sensor}.temp[{k},{r}]" for r in range(3)] for k in range(1, order + 1)]
        inputs = 0 if fitted.interference is None else len(fitted.interference.inputs)
        triples += [[f"{sensor}.interference[{i},{r}]" for r in range(3)] for i in range(inputs)]
        for triple in triples:
            if all(t in names for t in triple):
                idx = [names.index(t) for t in triple]
                T[np.ix_(idx, idx)] = Pt
        covariance = covariance.transformed(T)
    key = f"{sensor}_residual"
    poses = tuple(
        {**row, key: list(Pt @ np.asarray(row[key]))} if key in row else row for row in cal.poses
    )
    if option is None:
        option = "mag_axes" if sensor == "mag" else "accel_sign"
    return dataclasses.replace(
        cal,
        **{sensor: new},
        covariance=covariance,
        options={**cal.options, option: spec},
        poses=poses,
    )
