"""Which temperature terms the data identify: the span rule and the order test.

**Span rule.** A term of order ``k`` in ``T − T_ref`` needs the poses' temperatures to span at
least ``k · MIN_SPAN_K`` kelvin and to take at least ``k + 2`` distinct values (``RESOLUTION_K``
apart): with less, its coefficient is a guess the pose noise could mimic. Below ``MIN_SPAN_K``
no term is fitted at all (refused: the calibration holds at the mean temperature, verdict code
``temperature_span``). Orders stop at :data:`MAX_ORDER` (PX4's cubic).

**Order test.** Forward selection on the likelihood (Eq. 8's ``J``): starting from no terms,
each round tries one more order for each sensor (the others kept), refitted by
Levenberg-Marquardt from the current optimum, and keeps the most significant addition while
its F-test ``F = ((J₀ − J₁)/3) / (J₁/ν₁)`` (3 coefficients added, ν₁ the larger model's degrees
of freedom) has ``p < ALPHA`` (1 %). The F form (rather than the χ² likelihood ratio) keeps the
test's size when the pose-level noise is not yet estimated: ``J₁/ν₁`` measures the scale. With
no temperature effect, a term is selected in about ``ALPHA`` × (number of sensors) of logs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.special import fdtrc

from ..calibration import Calibration
from ..stats.pose_stats import PoseStats
from ..stats.pose_temperature import PoseTemperature
from .levenberg import levenberg_marquardt
from .pose_model import State, build_problem, residuals, state_from_calibration

__all__ = [
    "ALPHA",
    "MAX_ORDER",
    "MIN_SPAN_K",
    "OrderChoice",
    "allowed_order",
    "choose_orders",
    "refusal",
    "with_temperature_terms",
]

#: Kelvin of span each order needs (order k: k times this).
MIN_SPAN_K = 5.0
#: Two pose temperatures closer than this count as one value.
RESOLUTION_K = 0.5
#: The highest order fitted (PX4 stores cubic polynomials).
MAX_ORDER = 3
#: Significance of each added order (F-test).
ALPHA = 0.01


def allowed_order(temperature: PoseTemperature) -> int:
    """The highest order the poses' temperatures identify (the span rule); 0: none."""
    t = temperature.means
    span = float(t.max() - t.min())
    distinct = len(np.unique(np.round(t / RESOLUTION_K)))
    return int(max(0, min(MAX_ORDER, math.floor(span / MIN_SPAN_K + 1e-9), distinct - 2)))


def refusal(temperature: PoseTemperature) -> str:
    """The one line saying why no temperature term is fitted (span too small)."""
    low, high = temperature.span
    return (
        f"the poses' temperatures span {high - low:.1f} K ({low:.1f} to {high:.1f} °C): "
        f"temperature terms need at least {MIN_SPAN_K:g} K (power the board on cold and record "
        f"poses while it warms); calibrated at the mean temperature {temperature.reference:.1f} °C"
    )


@dataclass(frozen=True)
class OrderChoice:
    """The orders chosen and the tests that chose them.

    Attributes
    ----------
    orders : dict of str to int
        Each sensor's order (missing: 0).
    allowed : int
        The highest order the span rule allows.
    tests : tuple of dict
        One entry per order tried: ``sensor``, ``order``, ``F``, ``dof``, ``p``, ``kept``.
    """

    orders: Mapping[str, int]
    allowed: int
    tests: tuple[dict[str, object], ...] = field(default=())


def _extend(state: State, sensor: str, order: int) -> State:
    """``state`` with one more (zero) order of ``sensor``'s temperature coefficients."""
    out = state.copy()
    old = out.temps.get(sensor, np.zeros((0, 3)))
    out.temps[sensor] = np.vstack([old, np.zeros((order - len(old), 3))])
    return out


def choose_orders(
    stats: PoseStats, body_frame: str, state: State, *, alpha: float = ALPHA
) -> OrderChoice:
    """Forward selection of each sensor's order (see the module docstring).

    Parameters
    ----------
    stats : PoseStats
        Pose statistics with ``temperature`` (its orders are ignored).
    body_frame : {"accel", "mag"}
        The sensor whose gain is symmetric.
    state : State
        The maximum-likelihood optimum without temperature terms (on ``stats``).
    alpha : float
        Significance of each added order.

    Returns
    -------
    OrderChoice
    """
    temperature = stats.temperature
    if temperature is None:
        return OrderChoice({}, 0)
    allowed = allowed_order(temperature)
    orders: dict[str, int] = {}
    base = stats.with_temperature(temperature.with_orders({}))
    problem = build_problem(base, body_frame)
    e = residuals(problem, state)
    cost = float(e.ravel() @ e.ravel())
    tests: list[dict[str, object]] = []
    while True:
        best: tuple[float, str, State, float, dict[str, object]] | None = None
        for s in stats.sensors:
            k = orders.get(s, 0) + 1
            if k > allowed:
                continue
            trial = stats.with_temperature(temperature.with_orders({**orders, s: k}))
            tp = build_problem(trial, body_frame)
            res = levenberg_marquardt(tp, _extend(state, s, k))
            dof = tp.dof
            if dof < 1 or (not res.converged and not np.isfinite(res.cost)):
                continue
            gain = max(cost - res.cost, 0.0)
            F = (gain / 3.0) / max(res.cost / dof, 1e-300)
            p = float(fdtrc(3, dof, F))
            test: dict[str, object] = {"sensor": s, "order": k, "F": F, "dof": dof, "p": p}
            tests.append(test)
            if p < alpha and (best is None or p < best[0]):
                best = (p, s, res.state, res.cost, test)
        if best is None:
            break
        _, s, state, cost, test = best
        test["kept"] = True
        orders[s] = orders.get(s, 0) + 1
    for test in tests:
        test.setdefault("kept", False)
    return OrderChoice(orders, allowed, tuple(tests))


def with_temperature_terms(
    stats: PoseStats,
    means: np.ndarray,
    body_frame: str,
    fit: Callable[[PoseStats], Calibration] | None,
) -> tuple[PoseStats, dict[str, object]]:
    """``stats`` with the poses' mean temperatures and the orders the data choose.

    Parameters
    ----------
    stats : PoseStats
        The pose statistics (no temperature yet).
    means : (N,) array
        Each pose's mean temperature, °C.
    body_frame : {"accel", "mag"}
        The sensor whose gain is symmetric.
    fit : callable or None
        The method's fit on statistics (no temperature terms fitted), giving the optimum the
        order test starts from; ``None`` when the method fits no temperature terms (the
        temperatures are then recorded, no term is fitted).

    Returns
    -------
    PoseStats, dict
        The statistics with ``temperature`` set, and the provenance for ``cal.options``
        (``temperature``: reference, span, allowed and chosen orders, the tests, or why none).
    """
    temperature = PoseTemperature(means)
    low, high = (float(x) for x in temperature.span)
    record: dict[str, object] = {
        "reference_c": temperature.reference,
        "span_c": [low, high],
        "criterion": f"F-test at {ALPHA:g} per added order; order k needs {MIN_SPAN_K:g}k K",
    }
    allowed = allowed_order(temperature)
    record["allowed_order"] = allowed
    if fit is None:
        record["orders"] = {}
        record["note"] = "this method fits no temperature terms; use method 'mle'"
        return stats.with_temperature(temperature), {"temperature": record}
    if high - low < MIN_SPAN_K:
        record["orders"] = {}
        record["refused"] = refusal(temperature)
        return stats.with_temperature(temperature.with_orders({}, refused=True)), {
            "temperature": record
        }
    base = stats.with_temperature(temperature)
    if allowed == 0:
        record["orders"] = {}
        return base, {"temperature": record}
    cal = fit(base)
    problem = build_problem(base, body_frame)
    choice = choose_orders(base, body_frame, state_from_calibration(problem, cal))
    record["orders"] = dict(choice.orders)
    record["tests"] = [dict(t) for t in choice.tests]
    return stats.with_temperature(temperature.with_orders(choice.orders)), {"temperature": record}
