"""Temperature terms of the continuous fit: which orders the log identifies, and their models.

Each sensor's bias may follow ``b + Σ_k c_k (T_j − T_ref)^k`` (:mod:`.model`, issue 26;
``docs/methods/temperature.md``), ``T_ref`` the log's mean temperature. The orders are chosen
as for poses (:mod:`fieldcal.likelihood.temperature`, whose rules are reused): the span rule
(:func:`~fieldcal.likelihood.temperature.allowed_order` on the samples' temperatures: order
``k`` needs ``5k`` K; under 5 K the terms are refused,
:func:`~fieldcal.likelihood.temperature.refusal`) and forward selection at
:data:`~fieldcal.likelihood.temperature.ALPHA` (1 %): each round refits every sensor with one
more order (Levenberg–Marquardt from the current optimum, the weights kept) and keeps the most
significant addition. The statistic is the Wald form of the poses' F-test,
``F = cᵀ C⁻¹ c / 3`` on the 3 added coefficients against ``F(3, ν)``, with ``C`` the sandwich
covariance (Eq. C9): a hand-waved log's residuals are correlated in time, and the likelihood
ratio, which takes them as white, would select terms in far more than 1 % of logs without a
temperature effect. The covariance is estimated from about ``n/b`` independent batches of the
long-run covariance, so the test is Hotelling's: ``F = T² (ν − 2)/(3ν)`` against ``F(3, ν − 2)``,
``T² = cᵀ C⁻¹ c``, ``ν = 1.5 (n/b − 1)`` (the overlapping batch means' degrees of freedom,
Meketon & Schmeiser 1984, not the samples').
"""

from __future__ import annotations

from typing import Any, TypedDict

import numpy as np
from numpy.typing import NDArray
from scipy.special import fdtrc

from ...errors import InputError
from ...likelihood.temperature import ALPHA, MIN_SPAN_K, allowed_order, refusal
from ...stats.pose_temperature import PLAUSIBLE_C, PoseTemperature
from ...thermal import TemperatureModel, temperature_names
from .model import TEMP_SENSORS, Data, State
from .solver import Weights, levenberg_marquardt
from .uncertainty import MIN_BATCHES, sandwich

__all__ = ["OrderTest", "choose_orders", "models", "temperature_record", "with_order"]

Array = NDArray[np.float64]


class OrderTest(TypedDict):
    """One order tried by :func:`choose_orders`: the Wald F statistic of ``sensor``'s
    ``order``-th coefficients, its denominator's degrees of freedom, its p-value and whether
    the order was kept (one entry of ``cal.options["temperature"]["tests"]``)."""

    sensor: str
    order: int
    F: float
    dof: float
    p: float
    kept: bool


def temperature_record(temperature: Array) -> tuple[Array, dict[str, object]]:
    """The samples' temperatures checked: ``T_j − T_ref`` and the provenance for
    ``cal.options["temperature"]`` (reference, span, allowed order by the span rule, the
    criterion, and the refusal when the span is too small)."""
    t = np.asarray(temperature, dtype=float)
    low_ok, high_ok = PLAUSIBLE_C
    if not np.all(np.isfinite(t)) or t.min() < low_ok or t.max() > high_ok:
        raise InputError(
            f"temperature must be finite die temperatures in °C ({low_ok:g} to {high_ok:g}); "
            "check the temperature column (--temp-col) and its unit"
        )
    poses = PoseTemperature(t)
    low, high = (float(x) for x in poses.span)
    record: dict[str, object] = {
        "reference_c": poses.reference,
        "span_c": [low, high],
        "allowed_order": allowed_order(poses),
        "criterion": (
            f"Wald F-test (sandwich covariance) at {ALPHA:g} per added order; order k needs "
            f"{MIN_SPAN_K:g}k K"
        ),
        "orders": {},
    }
    if high - low < MIN_SPAN_K:
        record["refused"] = refusal(poses)
        record["allowed_order"] = 0
    return t - poses.reference, record


def with_order(state: State, sensor: str, order: int) -> State:
    """``state`` with ``sensor``'s temperature coefficients padded with zeros to ``order``."""
    out = state.copy()
    old = out.temps.get(sensor, np.zeros((0, 3)))
    out.temps[sensor] = np.vstack([old, np.zeros((order - len(old), 3))])
    return out


def _wald(state: State, data: Data, w: Weights, sensor: str, batch: int) -> float:
    """``T²/3 = cᵀ C⁻¹ c / 3`` of ``sensor``'s highest-order coefficients (sandwich covariance)."""
    cov, _, _ = sandwich(state, data, w, batch)
    k = len(state.temps[sensor])
    names = [f"{sensor}.{n}" for n in temperature_names(k)[-3:]]
    index = [cov.index(n) for n in names]
    C = np.asarray(cov.matrix)[np.ix_(index, index)]
    c = state.temps[sensor][-1]
    return float(c @ np.linalg.solve(C, c)) / 3.0


def choose_orders(
    state: State, data: Data, w: Weights, allowed: int, batch: int, max_iter: int, tol: float
) -> tuple[State, list[OrderTest]]:
    """Forward selection of each sensor's order (see the module docstring).

    Parameters
    ----------
    state : State
        The optimum without temperature terms.
    data : Data
        The readings, ``temperature`` set (``T_j − T_ref``).
    w : Weights
        The weights of that optimum (kept through the selection).
    allowed : int
        The highest order the span rule allows.
    batch : int
        Samples per batch of the sandwich's long-run covariance.
    max_iter, tol : int, float
        Levenberg–Marquardt's, per trial fit.

    Returns
    -------
    State, list of OrderTest
        The optimum with the orders kept, and one entry per order tried.
    """
    n = len(data.time)
    # the sandwich's long-run covariance rests on about n / b independent batches: its
    # degrees of freedom, not the samples', are the test's denominator's
    b = int(min(max(batch, 1), max(n // MIN_BATCHES, 1)))
    tests: list[OrderTest] = []
    while True:
        best: tuple[float, State, OrderTest] | None = None
        # overlapping batch means: about 3/2 the non-overlapping batches' degrees of freedom
        nu = 1.5 * (n // b - 1)  # Hotelling: T²(ν − 2)/(3ν) ~ F(3, ν − 2)
        dof = nu - 2
        for sensor in TEMP_SENSORS:
            k = len(state.temps.get(sensor, ())) + 1
            if k > allowed or dof < 1:
                continue
            trial, _, _ = levenberg_marquardt(
                with_order(state, sensor, k), data, w, max_iter=max_iter, tol=tol
            )
            F = _wald(trial, data, w, sensor, batch) * dof / nu
            p = float(fdtrc(3, dof, F))
            test = OrderTest(sensor=sensor, order=k, F=F, dof=dof, p=p, kept=False)
            tests.append(test)
            if p < ALPHA and (best is None or p < best[0]):
                best = (p, trial, test)
        if best is None:
            break
        _, state, test = best
        test["kept"] = True
    return state, tests


def models(state: State, record: dict[str, Any]) -> dict[str, TemperatureModel]:
    """Each sensor's :class:`TemperatureModel` (order 0 where no term was kept) from the
    state and :func:`temperature_record`'s record."""
    ref, span, refused = record["reference_c"], np.array(record["span_c"]), "refused" in record
    return {
        s: TemperatureModel(ref, state.temps.get(s, np.zeros((0, 3))), span, refused)
        for s in TEMP_SENSORS
    }
