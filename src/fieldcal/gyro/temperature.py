"""The gyroscope's bias against temperature, from the still poses' mean rates.

At rest the gyroscope reads its bias (the Earth's rotation is below a MEMS part's noise), so
each still pose's mean rate ``p_i`` observes ``b(T_i)`` directly:

    p_i = b + Σ_{k=1..K} c_k (T_i − T_ref)^k + e_i,   e_i ~ N(0, Q/T_i + v I)

(``Q`` the rate noise density, ``T_i`` here the pose's duration, ``v`` the poses' bias wander:
the prior of :func:`fieldcal.gyro.data.drift_line`). ``b`` and the ``c_k`` follow by
generalised least squares; their covariance is the inverse information, widened by ``χ²/ν``
when the poses' χ² rejects the model at 5 % (as the segments' is,
:data:`fieldcal.gyro.uncertainty.WIDEN_P`). The order is chosen as for the other sensors
(:mod:`fieldcal.likelihood.temperature`): the span rule (order ``k`` needs ``5k`` K and ``k + 2``
distinct pose temperatures; under 5 K the terms are refused) and the forward F-test at 1 %,
``F = ((J_{k−1} − J_k)/3) / (J_k/ν_k)``, ``ν_k = 3(N − k − 1)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtrc, fdtrc

from ..calibration import ParameterCovariance
from ..errors import InputError
from ..likelihood.temperature import ALPHA, MIN_SPAN_K, allowed_order, refusal
from ..stats.pose_temperature import PoseTemperature
from ..thermal import TemperatureModel, temperature_names
from .data import drift_line
from .result import BIAS_NAMES, GyroFit
from .uncertainty import WIDEN_P

__all__ = ["BiasTemperature", "fit_bias_temperature", "with_bias_temperature"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class BiasTemperature:
    """The gyroscope's bias against temperature (see the module docstring).

    Attributes
    ----------
    model : TemperatureModel
        ``T_ref``, the coefficients (order 0 when none is selected or the span is refused),
        the span seen.
    bias : (3,) array or None
        ``b``, the bias at ``T_ref`` (raw units), when terms were fitted; ``None`` otherwise
        (the gyroscope's bias is then the poses' weighted mean, as without a temperature).
    covariance : (3(K+1), 3(K+1)) array or None
        Covariance of ``(b, c_1, …, c_K)`` (raw units), with the terms.
    record : dict
        For ``cal.options["gyro"]["temperature"]``: reference, span, each pose's temperature
        (``pose_temperature_c``, beside ``cal.options["gyro"]["pose_bias"]``), allowed and
        chosen order, the tests (``order``, ``F``, ``dof``, ``p``, ``kept``), or why none.
    """

    model: TemperatureModel
    bias: Array | None = None
    covariance: Array | None = None
    record: dict[str, object] = field(default_factory=dict)


def _design(d: Array, order: int) -> Array:
    """(N, 3, 3(K+1)): pose ``i``'s mean rate in terms of ``(b, c_1, …, c_K)``."""
    X = np.zeros((len(d), 3, 3 * (order + 1)))
    for k in range(order + 1):
        X[:, :, 3 * k : 3 * k + 3] = (d**k)[:, None, None] * np.eye(3)
    return X


def _gls(means: Array, inv: Array, X: Array) -> tuple[Array, Array, float]:
    """Generalised least squares: estimate, its covariance (inverse information), χ²."""
    A = np.einsum("nai,nab,nbj->ij", X, inv, X)
    rhs = np.einsum("nai,nab,nb->i", X, inv, means)
    C = np.linalg.inv(A)
    beta = C @ rhs
    res = means - np.einsum("nai,i->na", X, beta)
    return beta, C, float(np.einsum("na,nab,nb->", res, inv, res))


def fit_bias_temperature(
    means: Array, prior_cov: Array, temperatures: Array, reference: float | None = None
) -> BiasTemperature:
    """The gyroscope's bias polynomial in temperature from the still poses' mean rates.

    Parameters
    ----------
    means : (N, 3) array
        Each still pose's mean raw rate.
    prior_cov : (N, 3, 3) array
        Their covariance about the bias, ``Q/T_i + v I``.
    temperatures : (N,) array
        Each pose's mean temperature, °C.
    reference : float, optional
        ``T_ref`` (°C); by default the mean of ``temperatures`` (give the other sensors' to
        share one reference).

    Returns
    -------
    BiasTemperature
    """
    t = np.asarray(temperatures, dtype=float)
    poses = PoseTemperature(t)
    low, high = (float(x) for x in poses.span)
    ref = poses.reference if reference is None else float(reference)
    allowed = allowed_order(poses)
    record: dict[str, object] = {
        "reference_c": ref,
        "span_c": [low, high],
        "pose_temperature_c": [float(x) for x in t],
        "allowed_order": allowed,
        "criterion": f"F-test at {ALPHA:g} per added order; order k needs {MIN_SPAN_K:g}k K",
    }
    span = np.array([low, high])
    if high - low < MIN_SPAN_K:
        record["order"] = 0
        record["refused"] = refusal(poses)
        return BiasTemperature(TemperatureModel(ref, np.zeros((0, 3)), span, True), record=record)
    d = t - ref
    inv = np.asarray(np.linalg.inv(prior_cov), dtype=float)
    n = len(t)
    beta, C, chi2 = _gls(means, inv, _design(d, 0))
    order, tests = 0, []
    for k in range(1, allowed + 1):
        dof = 3 * (n - k - 1)
        if dof < 1:
            break
        b1, C1, chi1 = _gls(means, inv, _design(d, k))
        F = (max(chi2 - chi1, 0.0) / 3.0) / max(chi1 / dof, 1e-300)
        p = float(fdtrc(3, dof, F))
        kept = p < ALPHA
        tests.append({"order": k, "F": float(F), "dof": dof, "p": p, "kept": kept})
        if not kept:
            break
        order, beta, C, chi2 = k, b1, C1, chi1
    record["order"] = order
    record["tests"] = tests
    if order == 0:
        return BiasTemperature(TemperatureModel(ref, np.zeros((0, 3)), span), record=record)
    dof = 3 * (n - order - 1)
    widen = chi2 / dof if chdtrc(dof, chi2) < WIDEN_P else 1.0
    record["widening"] = float(widen)
    model = TemperatureModel(ref, beta[3:].reshape(order, 3), span)
    return BiasTemperature(model, beta[:3], C * widen, record)


def with_bias_temperature(
    fit: GyroFit, temperature: ArrayLike, reference: float | None = None
) -> GyroFit:
    """``fit`` with its bias against temperature (:func:`fit_bias_temperature` on its still
    poses' means, their prior ``rate_noise / duration + wander² I``).

    With terms, the bias is the one at ``T_ref`` and the covariance's ``gyro.bias[j]`` and
    ``gyro.temp[k,j]`` are this fit's (their correlation with the gain, which the motion
    determines, is not kept); the motion segments already interpolate each pose's own bias, so
    the gain is unchanged.

    Parameters
    ----------
    fit : GyroFit
        The gyroscope's fit (:func:`fieldcal.gyro.fit_gyro`).
    temperature : (N,) array_like
        Each still pose's mean die temperature (°C), in the poses' order.
    reference : float, optional
        ``T_ref`` (°C); by default the mean of ``temperature`` (give the other sensors').

    Returns
    -------
    GyroFit
        With :attr:`GyroFit.temperature` and :attr:`GyroFit.temperature_record`.

    Raises
    ------
    InputError
        Not one finite temperature per still pose.
    """
    n = len(fit.pose_bias)
    t = np.asarray(temperature, dtype=float)
    if t.shape != (n,) or not np.all(np.isfinite(t)) or len(fit.pose_duration) != n:
        raise InputError(f"temperature must be one finite mean temperature per still pose ({n})")
    prior = np.asarray(fit.rate_noise)[None] / np.asarray(fit.pose_duration)[:, None, None]
    prior = prior + fit.bias_wander**2 * np.eye(3)
    thermal = fit_bias_temperature(np.asarray(fit.pose_bias), prior, t, reference)
    changes: dict[str, object] = {
        "temperature": thermal.model,
        "temperature_record": thermal.record,
    }
    if thermal.bias is not None and thermal.covariance is not None:
        cov = fit.covariance
        names = [n for n in cov.names if n not in BIAS_NAMES]
        keep = [cov.index(n) for n in names]
        extra = [*BIAS_NAMES, *(f"gyro.{n}" for n in temperature_names(thermal.model.order))]
        m = len(names)
        matrix = np.zeros((m + len(extra), m + len(extra)))
        matrix[:m, :m] = np.asarray(cov.matrix)[np.ix_(keep, keep)]
        matrix[m:, m:] = thermal.covariance
        changes["bias"] = thermal.bias
        changes["covariance"] = ParameterCovariance((*names, *extra), matrix)
    model = thermal.model
    if model.order > 0 and len(t) >= 3:
        # the drift test asks what the temperature terms leave: the poses' biases less b(T)
        left = np.asarray(fit.pose_bias) - model.shift(t)
        slope, p_value, _, _ = drift_line(
            left, np.asarray(fit.pose_time), np.asarray(fit.pose_duration), fit.rate_noise
        )
        if slope is not None:
            changes.update(
                drift=float(np.linalg.norm(slope)), drift_rate=slope, drift_p_value=p_value
            )
    return dataclasses.replace(fit, **changes)  # type: ignore[arg-type]
