"""The report's figures of a calibration from continuous motion: trajectory and residuals in time.

A continuous calibration (:mod:`fieldcal.methods.continuous`, ``cal.options["mode"] ==
"continuous"``) has no poses: the pose figures of :mod:`fieldcal.output.report` give way to

- **trajectory**: where the body's "up" pointed (the gravity directions the log visited, in the
  body frame, Mollweide, coloured by time: the identifiability the verdict judges), and the
  turn about each body axis accumulated over time (the calibrated gyroscope's rates, else the
  fitted trajectory's steps), with each axis' total;
- **residuals in time**: per field sensor, ``|raw − (K R_j field + b)|`` at the trajectory's
  kept epochs as a share of the field, with the stretches down-weighted for the body's
  acceleration shaded and their reason in the caption (what poses' "rejected" shows for rests).

matplotlib is passed in (``Figure``): :func:`fieldcal.output.report._figure_class` is the one
place it is imported.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..geometry.frames import GRAVITY
from ..geometry.rotations import log_so3
from ..logs import Log

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure as MplFigure

__all__ = [
    "CAPTIONS",
    "TITLES",
    "downweighted_rows",
    "is_continuous",
    "motion_figures",
    "readable_sphere",
    "rest_rows",
]

Array = NDArray[np.float64]

_LABELS = {"accel": "accelerometer", "mag": "magnetometer"}
_DOWNWEIGHTED = "tab:orange"
#: At most this many epochs are drawn per line (evenly thinned).
_POINTS = 4000

TITLES = {
    "trajectory": "Trajectory and coverage",
    "motion_residuals": "Residuals over time",
}
CAPTIONS = {
    "trajectory": "Left: the body's “up” direction through the log (the gravity directions "
    "the motion visited, in the body frame; colour: time). Directions spread over the whole "
    "sphere determine the accelerometer and the magnetometer. Right: the turn about each body "
    "axis accumulated over time, from the calibrated gyroscope; turns about every axis "
    "determine its gain.",
    "motion_residuals": "Each field sensor's residual at the fitted trajectory, |raw − model| "
    "as a share of its field, over time. Shaded: stretches down-weighted for the body's "
    "acceleration (the hand's motion), each with its reason in the calibration "
    "(options.downweighted); the accelerometer's residual is the body's acceleration there.",
}


def is_continuous(cal: Calibration) -> bool:
    """Whether ``cal`` was made from continuous motion (no poses; a trajectory)."""
    return cal.options.get("mode") == "continuous"


def _time(cal: Calibration, log: Log) -> tuple[Array, str]:
    if log.time is not None:
        return np.asarray(log.time, dtype=float), "time (s)"
    rate = cal.options.get("rate")
    if isinstance(rate, (int, float)) and rate > 0:
        return np.arange(log.n) / float(rate), "time (s, at the rate given)"
    return np.arange(log.n, dtype=float), "sample"


def _epoch_rows(cal: Calibration, log: Log) -> NDArray[np.int64]:
    """Each kept rotation's position among the log's rows (every ``epoch_step`` samples)."""
    step = cal.options.get("epoch_step")
    if not isinstance(step, int) or step < 1:  # files written before epoch_step was recorded
        seconds = float(cal.options.get("epoch_seconds", 0.1))
        rate = cal.options.get("rate") or log.rate or 1.0 / seconds
        step = max(1, round(seconds * float(rate)))
    rows = np.arange(len(cal.rotations)) * step
    return rows[rows < log.n]


def _thin(n: int) -> NDArray[np.int64]:
    return np.unique(np.linspace(0, n - 1, min(n, _POINTS)).astype(np.int64))


def _turns(cal: Calibration, log: Log, t: Array, rows: NDArray[np.int64]) -> tuple[Array, Array]:
    """Accumulated |turn| about each body axis (degrees) and its times: from the calibrated
    gyroscope when the log has one, else from the fitted trajectory's steps."""
    if log.gyro is not None and cal.gyro is not None and log.n > 1:
        rates = cal.correct_gyro(log.gyro)
        mid = 0.5 * (rates[1:] + rates[:-1]) * np.diff(t)[:, None]
        turned = np.vstack([np.zeros(3), np.cumsum(np.abs(mid), axis=0)])
        return t, np.degrees(turned)
    R = np.asarray(cal.rotations)[: len(rows)]
    if len(R) < 2:
        return t[rows], np.zeros((len(rows), 3))
    steps = -log_so3(R[1:] @ np.swapaxes(R[:-1], 1, 2))  # R_{k+1} = Exp(−ω dt) R_k
    turned = np.vstack([np.zeros(3), np.cumsum(np.abs(steps), axis=0)])
    return t[rows], np.degrees(turned)


def _trajectory_figure(Figure: type[MplFigure], cal: Calibration, log: Log) -> MplFigure:
    t, xlabel = _time(cal, log)
    rows = _epoch_rows(cal, log)
    fig = Figure(figsize=(11, 4.2))
    sphere = fig.add_subplot(1, 2, 1, projection="mollweide")
    up = -(np.asarray(cal.rotations)[: len(rows)] @ GRAVITY)  # gravity's reading: "up", body
    pick = _thin(len(rows))
    lon = np.arctan2(up[pick, 1], up[pick, 0])
    lat = np.arcsin(np.clip(up[pick, 2], -1, 1))
    dots = sphere.scatter(lon, lat, c=t[rows][pick], s=4, cmap="viridis")
    readable_sphere(sphere)
    share = cal.options.get("trajectory", {}).get("gravity_coverage")
    covered = "" if share is None else f": {100 * float(share):.0f} % of directions visited"
    sphere.set_title(f"body's up direction (body frame){covered}", pad=18, fontsize=10)
    fig.colorbar(dots, ax=sphere, orientation="horizontal", fraction=0.05, pad=0.12, label=xlabel)
    ax = fig.add_subplot(1, 2, 2)
    times, turned = _turns(cal, log, t, rows)
    pick = _thin(len(times))
    for k, color in enumerate(("tab:red", "tab:green", "tab:blue")):
        total = float(turned[-1, k]) if len(turned) else 0.0
        ax.plot(times[pick], turned[pick, k], color=color, label=f"about {'xyz'[k]}: {total:.0f}°")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("accumulated |turn| (°)")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("rotation about each body axis", fontsize=10)
    fig.subplots_adjust(left=0.03, right=0.97, bottom=0.14, top=0.88, wspace=0.2)
    return fig


def readable_sphere(ax: Axes) -> None:
    """A Mollweide map's grid that no label collides with: matplotlib writes eleven longitude
    labels along the equator, under the points; here the meridians every 60° are named once,
    below the map, and the latitudes every 30° at its left edge, small."""
    ax.set_xticks(np.radians([-120, -60, 0, 60, 120]))
    ax.set_xticklabels([])
    ax.set_yticks(np.radians([-60, -30, 0, 30, 60]))
    ax.set_yticklabels(["-60°", "-30°", "0°", "30°", "60°"], fontsize=7)
    ax.grid(True, color="0.8", lw=0.6)
    ax.text(
        0.5,
        -0.06,
        "longitude: 0° at the centre, meridians every 60°, ±180° at the edges",
        transform=ax.transAxes,
        ha="center",
        va="top",
        fontsize=7,
        color="0.35",
    )


#: A rest: the gyroscope's rate under this (rad/s), smoothed over half a second, for a second.
_REST_RATE, _REST_SECONDS = 0.05, 1.0


def rest_rows(log: Log) -> list[tuple[int, int]]:
    """The rests of a log with a gyroscope (and time): [first, stop) positions where the
    smoothed angular rate stays under :data:`_REST_RATE` for :data:`_REST_SECONDS` or more."""
    if log.gyro is None or log.time is None or log.n < 3:
        return []
    t = np.asarray(log.time, dtype=float)
    step = float(np.median(np.diff(t))) or 1.0
    k = max(1, round(0.5 / step))
    rate = np.linalg.norm(np.asarray(log.gyro, dtype=float), axis=1)
    smooth = np.convolve(rate, np.ones(k) / k, mode="same")
    still = np.concatenate([[False], smooth < _REST_RATE, [False]])
    edges = np.flatnonzero(np.diff(still.astype(np.int8)))
    least = max(2, round(_REST_SECONDS / step))
    return [
        (int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= least
    ]


def _residuals(cal: Calibration, log: Log, sensor: str, rows: NDArray[np.int64]) -> Array:
    """``|raw − (K R_j field + b)| / |field|`` at the kept epochs."""
    sc = cal.sensor(sensor)
    ref = cal.reference(sensor)
    raw = np.asarray(getattr(log, sensor))[rows]
    predicted = sc.predict(np.asarray(cal.rotations)[: len(rows)], ref)
    body = sc.correct(raw) - sc.correct(predicted)  # in the field's units
    out: Array = np.linalg.norm(body, axis=1) / max(float(np.linalg.norm(ref)), 1e-300)
    return out


def downweighted_rows(cal: Calibration, log: Log) -> list[tuple[int, int]]:
    """The down-weighted stretches as [first, stop) positions among the log's rows."""
    found = cal.options.get("downweighted") or []
    out = []
    for entry in found:
        if not isinstance(entry, Mapping):
            continue
        first = int(np.searchsorted(log.index, int(entry["start"])))
        stop = int(np.searchsorted(log.index, int(entry["stop"]) - 1)) + 1
        if first < stop <= log.n:
            out.append((first, stop))
    return out


def _residual_figure(Figure: type[MplFigure], cal: Calibration, log: Log) -> MplFigure:
    t, xlabel = _time(cal, log)
    rows = _epoch_rows(cal, log)
    sensors = [s for s in ("accel", "mag") if getattr(log, s) is not None and getattr(cal, s)]
    fig = Figure(figsize=(11, 0.9 + 2.2 * max(len(sensors), 1)))
    axes = fig.subplots(max(len(sensors), 1), 1, sharex=True, squeeze=False)[:, 0]
    stretches = downweighted_rows(cal, log)
    pick = _thin(len(rows))
    for ax, s in zip(axes, sensors, strict=False):
        share = 100 * _residuals(cal, log, s, rows)
        ax.plot(t[rows][pick], share[pick], color="tab:blue", lw=0.7)
        for k, (lo, hi) in enumerate(stretches):
            label = "down-weighted (body acceleration)" if k == 0 else None
            ax.axvspan(t[lo], t[hi - 1], color=_DOWNWEIGHTED, alpha=0.25, lw=0, label=label)
        ax.set_ylim(bottom=0)
        ax.set_ylabel(f"{_LABELS[s]}\n|residual| (% of field)")
        if stretches:
            ax.legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel(xlabel)
    count = len(stretches)
    fig.suptitle(f"residuals at the fitted trajectory; {count} stretch(es) down-weighted")
    fig.subplots_adjust(left=0.09, right=0.98, top=1 - 0.5 / fig.get_figheight(), hspace=0.12)
    return fig


def motion_figures(
    Figure: type[MplFigure], cal: Calibration, log: Log | None
) -> dict[str, MplFigure]:
    """The continuous calibration's figures (``trajectory``, ``motion_residuals``) on its log;
    none without the log or the trajectory."""
    if log is None or not is_continuous(cal) or len(cal.rotations) == 0 or log.n == 0:
        return {}
    figures: dict[str, MplFigure] = {"trajectory": _trajectory_figure(Figure, cal, log)}
    if cal.accel is not None or cal.mag is not None:
        figures["motion_residuals"] = _residual_figure(Figure, cal, log)
    return figures
