"""Whether to repeat a pose when the board is warmer: the temperature span a calibration's
poses cover against what its temperature terms need.

The span rule (:mod:`fieldcal.likelihood.temperature`): a term of order ``k`` needs the poses'
temperatures to span ``k · MIN_SPAN_K`` kelvin (and ``k + 2`` distinct values); under
``MIN_SPAN_K`` no term is fitted. A warm-up log identifies more when a pose is repeated after
the board has warmed: this module says so, and by how much, when the span is what limits the
terms: none fitted for lack of span, or some sensor's order at the most the span allows.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..calibration import Calibration
from ..likelihood.temperature import MAX_ORDER, MIN_SPAN_K

__all__ = ["temperature_advice", "temperature_span_line"]


def temperature_span_line(record: Mapping[str, object]) -> str | None:
    """The poses' temperature span on one line, e.g. ``"poses at 20.4 to 38.0 °C (17.6 K):
    terms up to order 3; chosen: accel 2, mag 2"``, from ``cal.options["temperature"]``;
    ``None`` when the record has no span."""
    span = record.get("span_c")
    if not isinstance(span, (list, tuple)) or len(span) != 2:
        return None
    low, high = float(span[0]), float(span[1])
    line = f"poses at {low:.1f} to {high:.1f} °C ({high - low:.1f} K)"
    order = record.get("allowed_order", 0)
    allowed = int(order or 0) if isinstance(order, (int, float, str)) else 0
    if high - low < MIN_SPAN_K:
        return line + f": temperature terms need {MIN_SPAN_K:g} K"
    line += f": terms up to order {allowed}"
    orders = record.get("orders")
    if isinstance(orders, Mapping) and orders:
        line += "; chosen: " + ", ".join(f"{s} {k}" for s, k in orders.items())
    elif "orders" in record:
        line += "; none chosen (no temperature effect seen)"
    return line


def temperature_advice(cal: Calibration) -> str | None:
    """ "Repeat a pose when warmer", with the temperature to reach, when the poses' span is
    what limits the temperature terms; ``None`` otherwise (no temperature column, a method
    that fits no terms, or every order below what the span allows: the data need no more).

    Parameters
    ----------
    cal : Calibration
        A calibration from a log with a temperature column (``cal.options["temperature"]``;
        the gyroscope's order from ``cal.options["gyro"]["temperature"]``).

    Returns
    -------
    str or None
        One line, e.g. ``"repeat a pose when the board is warmer: the poses span 3.2 K (21.0
        to 24.2 °C) and temperature terms need 5 K: a pose at 26.0 °C or above (power the
        board on cold and record poses while it warms)"``.
    """
    record = cal.options.get("temperature")
    if not isinstance(record, Mapping) or "note" in record:
        return None
    span = record.get("span_c")
    if not isinstance(span, (list, tuple)) or len(span) != 2:
        return None
    low, high = float(span[0]), float(span[1])
    width = high - low
    order = record.get("allowed_order", 0)
    allowed = int(order or 0) if isinstance(order, (int, float, str)) else 0
    if width < MIN_SPAN_K:
        return (
            f"repeat a pose when the board is warmer: the poses span {width:.1f} K ({low:.1f} "
            f"to {high:.1f} °C) and temperature terms need {MIN_SPAN_K:g} K: a pose at "
            f"{low + MIN_SPAN_K:.1f} °C or above (power the board on cold and record poses "
            "while it warms)"
        )
    orders = dict(record.get("orders") or {})
    gyro = cal.options.get("gyro")
    if isinstance(gyro, Mapping) and isinstance(gyro.get("temperature"), Mapping):
        orders["gyro"] = int(gyro["temperature"].get("order", 0) or 0)
    at_limit = [s for s, k in orders.items() if k and int(k) >= allowed]
    if allowed >= MAX_ORDER or not at_limit:
        return None
    need = (allowed + 1) * MIN_SPAN_K
    return (
        f"repeat a pose when the board is warmer: {', '.join(at_limit)} took order {allowed}, "
        f"the most the poses' {width:.1f} K identify; order {allowed + 1} needs {need:g} K and "
        f"{allowed + 3} distinct pose temperatures: a pose at {low + need:.1f} °C or above"
    )
