"""A device's calibrations over time (:meth:`fieldcal.store.Store.drift`): a table of every
parameter with its standard error and a figure of them against time, changes beyond their
uncertainty marked."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from rich import box
from rich.table import Table

from ..comparison import parameter_values
from ..errors import InputError
from ..store import DriftRow

if TYPE_CHECKING:
    from matplotlib.figure import Figure as MplFigure

__all__ = ["GROUPS", "drift_figure", "drift_table"]

#: Parameter groups drawn (one panel each) and tabled: label and the names in the covariance.
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("accelerometer scale", tuple(f"accel.gain[{j},{j}]" for j in range(3))),
    ("accelerometer bias", tuple(f"accel.bias[{j}]" for j in range(3))),
    ("magnetometer scale", tuple(f"mag.gain[{j},{j}]" for j in range(3))),
    ("magnetometer bias", tuple(f"mag.bias[{j}]" for j in range(3))),
    ("gyroscope scale", tuple(f"gyro.gain[{j},{j}]" for j in range(3))),
    ("gyroscope bias", tuple(f"gyro.bias[{j}]" for j in range(3))),
    ("dip (°)", ("dip_deg",)),
)


def _series(rows: Sequence[DriftRow]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every parameter's values and standard errors per calibration (NaN where absent), each
    calibration read once."""
    values = [parameter_values(row.calibration) for row in rows]
    names = {name for v in values for name in v}
    out = {}
    for name in names:
        stds = [
            c.std(name)
            if (c := row.calibration.covariance) is not None and name in c.names
            else np.nan
            for row in rows
        ]
        out[name] = np.array([v.get(name, np.nan) for v in values]), np.array(stds)
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
            changed = "(first)"
        else:
            moved = row.since_previous.changed
            changed = ", ".join(f"{c.name} ({c.z:+.1f})" for c in moved) or "nothing"
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
    for ax, (label, names) in zip(axes, groups, strict=True):
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
