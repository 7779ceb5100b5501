"""A device's calibrations over time (:meth:`fieldcal.store.Store.drift`): a table of every
parameter with its standard error and a figure of them against time, changes beyond their
uncertainty marked.

Temperature apart from ageing: calibrations with a temperature model have their biases drawn at
one common temperature per sensor (the median of their reference temperatures; the table
compares each pair at theirs, :func:`fieldcal.comparison.common_temperature`), and the
first-order coefficients (bias change per kelvin) get panels of their own."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from rich import box
from rich.table import Table

from ..comparison import parameter_stds, parameter_values, temperature_values
from ..errors import InputError
from ..store import DriftRow

if TYPE_CHECKING:
    from matplotlib.figure import Figure as MplFigure

__all__ = ["GROUPS", "common_temperatures", "drift_figure", "drift_table"]

#: Parameter groups drawn (one panel each) and tabled: label and the names in the covariance.
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("accelerometer scale", tuple(f"accel.gain[{j},{j}]" for j in range(3))),
    ("accelerometer bias", tuple(f"accel.bias[{j}]" for j in range(3))),
    ("magnetometer scale", tuple(f"mag.gain[{j},{j}]" for j in range(3))),
    ("magnetometer bias", tuple(f"mag.bias[{j}]" for j in range(3))),
    ("gyroscope scale", tuple(f"gyro.gain[{j},{j}]" for j in range(3))),
    ("gyroscope bias", tuple(f"gyro.bias[{j}]" for j in range(3))),
    ("dip (°)", ("dip_deg",)),
    ("accelerometer bias per K", tuple(f"accel.temp[1,{j}]" for j in range(3))),
    ("magnetometer bias per K", tuple(f"mag.temp[1,{j}]" for j in range(3))),
    ("gyroscope bias per K", tuple(f"gyro.temp[1,{j}]" for j in range(3))),
)


def common_temperatures(rows: Sequence[DriftRow]) -> dict[str, float]:
    """Per sensor, the temperature (°C) the figure draws its biases at: the median of the
    reference temperatures of the calibrations with a temperature model (none: absent)."""
    out = {}
    for sensor in ("accel", "mag", "gyro"):
        refs = [
            part.temperature.reference
            for row in rows
            if (part := getattr(row.calibration, sensor)) is not None
            and part.temperature is not None
        ]
        if refs:
            out[sensor] = float(np.median(refs))
    return out


def _series(rows: Sequence[DriftRow]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every parameter's values and standard errors per calibration (NaN where absent), each
    calibration read once."""
    at = common_temperatures(rows)
    values = [
        {**parameter_values(row.calibration, at), **temperature_values(row.calibration, at)}
        for row in rows
    ]
    names = sorted({name for v in values for name in v})
    stds = np.array([parameter_stds(row.calibration, names, at) for row in rows])
    out = {}
    for i, name in enumerate(names):
        out[name] = np.array([v.get(name, np.nan) for v in values]), stds[:, i]
    return out


def drift_table(rows: Sequence[DriftRow]) -> Table:
    """One row per calibration: its date, verdict, and the parameters that changed since the
    one before beyond their combined uncertainty (with z)."""
    table = Table(title=f"{rows[0].entry.device}: {len(rows)} calibrations", box=box.SIMPLE)
    for column in ("date (UTC)", "verdict", "dip (°)", "changed since the one before (z)"):
        table.add_column(column)
    for row in rows:
        cal = row.calibration
        dip = "" if cal.dip_deg is None else f"{cal.dip_deg:.2f} ± {cal.dip_std_deg or 0:.2g}"
        if row.since_previous is None:
            changed = row.note or "(first)"
        else:
            moved = row.since_previous.changed
            changed = ", ".join(f"{c.name} ({c.z:+.1f})" for c in moved) or "nothing"
            common = row.since_previous.temperature
            if common:
                at = ", ".join(f"{s} {t:.1f} °C" for s, t in common.items())
                changed += f" (biases compared at {at})"
        verdict = "?" if cal.verdict is None else cal.verdict.level
        table.add_row(row.entry.created.strftime("%Y-%m-%d %H:%M:%S"), verdict, dip, changed)
    return table


def drift_figure(rows: Sequence[DriftRow]) -> MplFigure:
    """Every parameter group against time with 1σ error bars; a calibration whose value moved
    beyond its uncertainty since the one before is ringed in red."""
    try:  # matplotlib is an optional extra: loaded when drawing
        from matplotlib.figure import Figure
    except ImportError:
        raise InputError("the drift plot needs matplotlib; pip install 'fieldcal[plot]'") from None
    series = _series(rows)
    groups = [g for g in GROUPS if g[1][0] in series]
    fig = Figure(figsize=(10, 2.2 * len(groups)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(groups), 1, sharex=True))
    times = [row.entry.created for row in rows]
    at = common_temperatures(rows)
    words = {"accelerometer": "accel", "magnetometer": "mag", "gyroscope": "gyro"}
    for ax, (label, names) in zip(axes, groups, strict=True):
        sensor = words.get(label.split()[0])
        if label.endswith(" bias") and sensor in at:
            label = f"{label} at {at[sensor]:.1f} °C"
        for name in names:
            values, stds = series[name]
            ax.errorbar(times, values, yerr=stds, marker="o", ms=3, capsize=2, label=name)
            moved = [
                k
                for k, row in enumerate(rows)
                if row.since_previous is not None
                and any(c.name == name for c in row.since_previous.changed)
            ]
            if moved:
                ax.plot([times[k] for k in moved], values[moved], "o", mfc="none", mec="red", ms=9)
        ax.set_ylabel(label)
        ax.legend(fontsize=7, ncols=3)
    axes[-1].set_xlabel("calibration date (UTC)")
    return fig
