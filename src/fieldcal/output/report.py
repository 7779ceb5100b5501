"""The HTML report of a calibration on the log it was made from (one self-contained file).

:func:`write_report` writes one HTML page with every figure inlined as a base64 PNG (and, on
request, each figure as a PNG file). From top to bottom the page shows:

1. **Verdict banner**: green *pass*, amber *warn* or red *fail* with the verdict's reasons, one
   per line; grey "no verdict" for a calibration file from fieldcal 0.1, which has none.
2. **Summary**: the log, the columns used, the method, how many poses were found, fitted and
   rejected, and the fit certificate (``J``, degrees of freedom, p-value).
3. **Correction**: per sensor, the matrix firmware applies, ``M = inv(gain)`` (calibrated units
   per raw unit), and the bias ``b`` (raw units), each entry ± its standard error, so that
   ``body = M (raw − b)``. The standard errors of ``M`` come from the gain covariance by the
   delta method (``dM = −M dK M``); the model's gain ``K`` ± its standard errors follows.
4. **Uncertainty and predicted accuracy**: per-sample noise per axis, pose-level noise ± its
   standard error, the reference field norms (the calibrated units), dip ± std,
   misalignment ± std, and the predicted tilt, heading and norm errors.
5. **Timeline**: the raw axes of each sensor against time (the log's time column, else the
   sample number), the still intervals of the poses shaded (fitted green, rejected red and
   hatched) and numbered. Long logs are drawn as a min/max envelope of a few thousand points,
   so short spikes stay visible.
6. **Per-pose residuals**: per sensor, the norm of ``pose mean − model`` in raw units, with the
   error a pose mean is expected to have (``√(tr Σ / n + 3 q²)``: the noise of the mean plus
   the pose-level noise ``q``) as a dashed step and ``q √3`` as a dotted line. Rejected poses
   have no residual (they are not in the fit): they are marked on the axis in red and listed
   with their statistic, p-value and reason in a table below the figure.
7. **Norm histograms**: ``|a|`` and ``|m|`` of the calibrated still samples (rejected poses
   stacked in red), with the expected norm (``|g|``, ``|h|``) as a vertical line, and the dip
   of each still sample against the fitted dip.
8. **Spheres**: raw and calibrated readings projected on the three coordinate planes.
9. **Coverage**: each pose's field direction in the sensor frame (Mollweide), rejected poses in
   red.

A calibration from continuous motion has no poses: its trajectory and coverage, and its
residuals over time with the down-weighted stretches, are drawn instead
(:mod:`fieldcal.output.motion_figures`).

Every piece of text that comes from the user or from a file (paths, column names, pose labels,
verdict reasons) is HTML-escaped, and ``$`` is escaped in figure text so matplotlib does not
read it as mathematics.

matplotlib is an optional extra (``pip install 'fieldcal[plot]'``); it is imported in one place,
:func:`_figure_class`, only when a report is written, so the rest of fieldcal works without it.
Figures are drawn on :class:`matplotlib.figure.Figure` directly, so writing a report neither
needs nor changes the pyplot backend.
"""

from __future__ import annotations

import base64
import io as _io
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from .._files import make_folder, same_file, write_bytes, write_text
from ..calibration import SENSORS, Calibration, SensorCalibration
from ..errors import InputError
from ..logs import Log, load_log
from .motion_figures import CAPTIONS as MOTION_CAPTIONS
from .motion_figures import TITLES as MOTION_TITLES
from .motion_figures import (
    downweighted_rows,
    is_continuous,
    motion_figures,
    readable_sphere,
    rest_rows,
)
from .report_tables import (
    CSS,
    SENSOR_LABELS,
    Pose,
    banner_html,
    correction_html,
    esc,
    plain,
    poses_of,
    rejected_html,
    summary_html,
    uncertainty_html,
    unit_of,
)

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure as MplFigure

__all__ = ["FIGURES", "report_figures", "write_report"]

Array = NDArray[np.float64]
_Scalar = TypeVar("_Scalar", bound=np.generic)
_MAX_POINTS = 2500  # enough to see the shape of a sphere, small enough for a light HTML file
_TIMELINE_POINTS = 3000  # per line: the envelope of 1500 buckets
_TIMELINE_LABELS = 40  # pose numbers written over the timeline, at most
_DPI = 90

_SYMBOLS = {"accel": "a", "mag": "m"}
_FITTED, _REJECTED, _DOWNWEIGHTED = "tab:green", "tab:red", "tab:orange"


# ----------------------------------------------------------------------------- figures
def _figure_class() -> type[MplFigure]:
    """matplotlib's Figure: the one place matplotlib is imported (it is an optional extra)."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise InputError("the report needs matplotlib; pip install 'fieldcal[plot]'") from None
    return Figure


def _thin(x: NDArray[_Scalar], rng: np.random.Generator) -> NDArray[_Scalar]:
    return x if len(x) <= _MAX_POINTS else x[rng.choice(len(x), _MAX_POINTS, replace=False)]


def _envelope(x: Array, y: Array) -> tuple[Array, Array]:
    """At most :data:`_TIMELINE_POINTS` points tracing the min and max of ``y`` per bucket."""
    n = len(y)
    if n <= _TIMELINE_POINTS:
        return x, y
    starts = np.linspace(0, n, _TIMELINE_POINTS // 2, endpoint=False).astype(np.int64)
    low = np.minimum.reduceat(y, starts)
    high = np.maximum.reduceat(y, starts)
    return np.repeat(x[starts], 2), np.column_stack([low, high]).ravel()


def _timeline_figure(
    Figure: type[MplFigure],
    log: Log,
    sensors: Sequence[str],
    poses: list[Pose],
    motion: tuple[list[tuple[int, int]], list[tuple[int, int]]] | None = None,
) -> MplFigure:
    """The raw readings against time, the poses' still intervals shaded; for a continuous fit
    (``motion``: the stretches down-weighted for body acceleration, and the rests) those."""
    if log.time is not None:
        x, xlabel = np.asarray(log.time, dtype=float), "time (s)"
    else:
        x, xlabel = np.arange(log.n, dtype=float), "sample (row of the log as loaded)"
    fig = Figure(figsize=(11, 1.2 + 2.2 * len(sensors)))
    axes = fig.subplots(len(sensors), 1, sharex=True, squeeze=False)[:, 0]
    for ax, s in zip(axes, sensors, strict=True):
        raw = getattr(log, s)
        for k, color in enumerate(("tab:red", "tab:green", "tab:blue")):
            ax.plot(*_envelope(x, raw[:, k]), color=color, lw=0.7, label="xyz"[k])
        ax.set_ylabel(f"raw {SENSOR_LABELS[s]}")
        for lo, hi in motion[0] if motion else ():
            ax.axvspan(x[lo], x[hi - 1], color=_DOWNWEIGHTED, alpha=0.25, lw=0)
        for lo, hi in motion[1] if motion else ():
            ax.axvspan(x[lo], x[hi - 1], color=_FITTED, alpha=0.18, lw=0)
        for pose in poses:
            for lo, hi in pose.spans:
                if pose.rejected is None:
                    ax.axvspan(x[lo], x[hi - 1], color=_FITTED, alpha=0.18, lw=0)
                else:
                    ax.axvspan(x[lo], x[hi - 1], facecolor=_REJECTED, alpha=0.3, hatch="//", lw=0)
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
    top = axes[0]
    located = [p for p in poses if p.spans]
    every = max(1, math.ceil(len(located) / _TIMELINE_LABELS))  # crowded logs: fewer numbers
    for k, pose in enumerate(located):
        if k % every and pose.rejected is None:  # rejected poses are always numbered
            continue
        middle = 0.5 * (x[pose.spans[0][0]] + x[pose.spans[-1][1] - 1])
        top.text(
            middle,
            1.02 + 0.09 * ((k // every) % 2),  # two staggered rows, so neighbours do not overlap
            plain(pose.name),
            transform=top.get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=7,
            color=_FITTED if pose.rejected is None else _REJECTED,
        )
    axes[-1].set_xlabel(xlabel)
    if motion is None:
        title = "log timeline: still intervals of fitted poses (green) and rejected ones (red)"
    else:
        down, rests = (len(m) for m in motion)
        title = (
            "log timeline: the motion the calibration was fitted to (no still poses)\nshaded: "
            f"{down} stretch(es) down-weighted for body acceleration (orange), "
            f"{rests} rest(s) (green)"
        )
    fig.suptitle(title, fontsize=11)
    top = 1 - (0.95 if motion is None else 1.15) / fig.get_figheight()
    fig.subplots_adjust(left=0.08, right=0.95, top=top, hspace=0.15)
    return fig


def _expected_error(sensor: SensorCalibration, samples: int | None) -> float:
    """RMS norm of a pose mean's error: ``√(tr Σ / n + 3 q²)`` (NaN without a sample count)."""
    if not samples:
        return float("nan")
    return float(np.sqrt(np.trace(sensor.noise_cov) / samples + 3 * sensor.pose_noise_std**2))


def _residual_figure(
    Figure: type[MplFigure], cal: Calibration, sensors: Sequence[str], poses: list[Pose]
) -> MplFigure:
    n = len(poses)
    fig = Figure(figsize=(11, 0.8 + 2.6 * len(sensors)))
    axes = fig.subplots(len(sensors), 1, sharex=True, squeeze=False)[:, 0]
    position = np.arange(n)
    for ax, s in zip(axes, sensors, strict=True):
        sensor = cal.sensor(s)
        norms = np.array(
            [np.nan if (r := p.residual[s]) is None else np.linalg.norm(r) for p in poses]
        )
        ax.bar(position, norms, color="tab:blue", width=0.7, label="|pose mean − model|")
        expected = np.array([_expected_error(sensor, p.samples[s]) for p in poses])
        ax.step(
            position,
            expected,
            where="mid",
            color="k",
            ls="--",
            lw=1,
            label="expected error of a pose mean √(tr Σ/n + 3q²)",
        )
        if sensor.pose_noise_std > 0:
            ax.axhline(
                sensor.pose_noise_std * np.sqrt(3),
                color="tab:orange",
                ls=":",
                lw=1.2,
                label="pose-level noise q√3",
            )
        rejected = [p.position for p in poses if p.rejected is not None]
        for k in rejected:
            ax.axvspan(k - 0.45, k + 0.45, color=_REJECTED, alpha=0.15, lw=0)
        if rejected:
            ax.plot(
                rejected,
                np.zeros(len(rejected)),
                "X",
                color=_REJECTED,
                ms=9,
                clip_on=False,
                transform=ax.get_xaxis_transform(),
                label="rejected (not in the fit; see the table)",
            )
        ax.set_ylim(bottom=0)
        ax.set_ylabel(f"{SENSOR_LABELS[s]}\n(raw units, {plain(unit_of(cal, f'{s}_raw'))})")
    step = max(1, math.ceil(n / 40))
    axes[-1].set_xticks(position[::step], [plain(p.name) for p in poses[::step]], fontsize=7)
    axes[-1].set_xlim(-0.6, n - 0.4)
    axes[-1].set_xlabel("pose")
    height = fig.get_figheight()
    _legend_on_top(fig, axes, height)
    fig.suptitle("per-pose residuals in raw units")
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.55 / height, top=1 - 0.95 / height)
    return fig


def _legend_on_top(fig: MplFigure, axes: Iterable[Axes], height: float) -> None:
    """One legend for all panels, under the title, so it hides no data."""
    entries: dict[str, Artist] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    fig.legend(
        list(entries.values()),
        list(entries),
        loc="upper center",
        bbox_to_anchor=(0.5, 1 - 0.35 / height),
        ncol=min(len(entries), 4),
        fontsize=8,
        frameon=False,
    )


def _sphere_figure(
    Figure: type[MplFigure], name: str, raw: Array, calibrated: Array, radius: float
) -> MplFigure:
    fig = Figure(figsize=(11, 7))
    axes = fig.subplots(2, 3)
    circle = np.linspace(0, 2 * np.pi, 200)
    for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        top, bottom = axes[0, k], axes[1, k]
        top.plot(raw[:, i], raw[:, j], ".", ms=1.5, alpha=0.4, color="tab:red")
        top.set_title(f"raw {'xyz'[i]}-{'xyz'[j]}")
        bottom.plot(calibrated[:, i], calibrated[:, j], ".", ms=1.5, alpha=0.4, color="tab:blue")
        bottom.plot(radius * np.cos(circle), radius * np.sin(circle), "k--", lw=1)
        bottom.set_title(f"calibrated {'xyz'[i]}-{'xyz'[j]} (dashed: ideal sphere)")
        for ax in (top, bottom):
            ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(f"{name}: raw and calibrated readings")
    # fixed margins: constrained layout would double the time of the whole report
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.05, top=0.9, wspace=0.3, hspace=0.3)
    return fig


def _coverage_figure(
    Figure: type[MplFigure], directions: Mapping[str, Array], poses: list[Pose]
) -> MplFigure:
    fig = Figure(figsize=(10, 4.5))
    colors = [_FITTED if p.rejected is None else _REJECTED for p in poses]
    for k, (name, d) in enumerate(directions.items()):
        ax = fig.add_subplot(1, len(directions), k + 1, projection="mollweide")
        lon = np.arctan2(d[:, 1], d[:, 0])
        lat = np.arcsin(np.clip(d[:, 2], -1, 1))
        ax.scatter(lon, lat, s=30, color=colors, zorder=3)
        readable_sphere(ax)
        for pose, x, y in zip(poses, lon, lat, strict=True):
            # beside its dot, on a white ground: readable over the grid and its labels
            ax.annotate(
                plain(pose.name),
                (x, y),
                xytext=(4, 4),
                textcoords="offset points",
                fontsize=7,
                zorder=4,
                bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.8},
            )
        ax.set_title(f"{name} field direction per pose (sensor frame)", pad=20)
    fig.subplots_adjust(left=0.04, right=0.98, wspace=0.15)
    return fig


def _gyro_figure(Figure: type[MplFigure], cal: Calibration) -> MplFigure:
    """Per-segment rotation residuals and the still poses' mean rates against time."""
    fig = Figure(figsize=(10, 3.4), layout="constrained")
    left, right = fig.subplots(1, 2)
    residual = [seg.get("residual_deg", np.nan) for seg in cal.gyro_segments]
    left.bar(np.arange(1, len(residual) + 1), residual, color=_FITTED)
    left.set_xlabel("motion segment")
    left.set_ylabel("rotation residual (°)")
    info = cal.options.get("gyro", {})
    times, rates = info.get("pose_time"), info.get("pose_bias")
    if times is not None and rates is not None and len(times):
        rates = np.asarray(rates, dtype=float)
        for j, axis in enumerate("xyz"):
            right.plot(times, rates[:, j], "o-", ms=3, label=f"ω{axis} raw")
        right.legend(fontsize=8)
    right.set_xlabel("time (s)")
    right.set_ylabel("mean raw rate in each still pose")
    return fig


def _temperature_series(cal: Calibration) -> dict[str, tuple[Any, Array, Array]]:
    """Per sensor with a temperature model: the model, each fitted pose's temperature and the
    bias that pose shows (the model's bias at its temperature plus its residual; the
    gyroscope's: its still poses' mean rates)."""
    out: dict[str, tuple[Any, Array, Array]] = {}
    for s in SENSORS:
        sensor = getattr(cal, s)
        model = None if sensor is None else sensor.temperature
        rows = [p for p in cal.poses if "temperature" in p and f"{s}_residual" in p]
        if model is None or not rows:
            continue
        t = np.array([float(p["temperature"]) for p in rows])
        residual = np.array([p[f"{s}_residual"] for p in rows], dtype=float)
        out[s] = model, t, np.asarray(sensor.bias) + model.shift(t) + residual
    gyro = cal.gyro
    info = cal.options.get("gyro", {})
    thermal = info.get("temperature", {}) if isinstance(info, Mapping) else {}
    temps, bias = thermal.get("pose_temperature_c"), info.get("pose_bias")
    if gyro is not None and gyro.temperature is not None and temps and bias:
        out["gyro"] = gyro.temperature, np.asarray(temps, float), np.asarray(bias, float)
    return out


def _temperature_figure(Figure: type[MplFigure], cal: Calibration) -> MplFigure | None:
    """Each sensor's bias against temperature: the poses' biases (dots) and the fitted
    polynomial over the span seen (line), per axis; None without a temperature model."""
    series = _temperature_series(cal)
    if not series:
        return None
    fig = Figure(figsize=(10, 2.8 * len(series)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(series), 1))
    names = {**SENSOR_LABELS, "gyro": "gyroscope"}
    for ax, (s, (model, t, bias)) in zip(axes, series.items(), strict=True):
        grid = np.linspace(model.span[0], model.span[1], 100)
        curve = np.asarray(getattr(cal, s).bias) + model.shift(grid)
        for j, axis in enumerate("xyz"):
            line = ax.plot(grid, curve[:, j], "-", label=f"{axis}: fitted")[0]
            ax.plot(t, bias[:, j], "o", ms=3, color=line.get_color(), label=f"{axis}: poses")
        how = f"order {model.order}" if model.order else "no terms"
        ax.set_title(f"{names[s]} bias ({how}, T_ref {model.reference:.1f} °C)", fontsize=9)
        ax.set_ylabel("bias (raw units)")
        ax.legend(fontsize=7, ncols=3)
    axes[-1].set_xlabel("die temperature (°C)")
    return fig


def _histogram_figure(
    Figure: type[MplFigure],
    norms: Mapping[str, tuple[Array, Array]],
    expected: Mapping[str, float],
    dip: Array | None,
    cal: Calibration,
    which: str = "",
) -> MplFigure:
    """Norm (and dip) histograms of the calibrated samples: the fitted poses' still samples,
    or ``which`` (a continuous fit: "every sample", the motion included)."""
    samples = which or "still samples"
    fitted_label = "all samples" if which else "fitted poses"
    panels = len(norms) + (dip is not None)
    fig = Figure(figsize=(4 * panels, 3.5))
    axes = np.atleast_1d(fig.subplots(1, panels))
    for ax, (s, (fitted, rejected)) in zip(axes, norms.items(), strict=False):
        symbol = _SYMBOLS[s]
        target = expected[s]
        # the range of the fitted poses (and the target): rejected ones may lie far off
        span = np.concatenate([fitted, [target]]) if fitted.size else np.array([target])
        lo, hi = float(span.min()), float(span.max())
        pad = 0.05 * (hi - lo) or 0.01 * abs(target) or 0.01
        edges = np.linspace(lo - pad, hi + pad, 61)
        ax.hist(fitted, bins=edges, color="tab:blue", label=fitted_label)
        if rejected.size:
            outside = int(np.count_nonzero((rejected < edges[0]) | (rejected > edges[-1])))
            label = "rejected poses" + (f" ({outside} samples off the axis)" if outside else "")
            # an outline, so a large rejected pose does not hide the fitted ones
            ax.hist(rejected, bins=edges, color=_REJECTED, histtype="step", lw=1.2, label=label)
        ref = "g" if s == "accel" else "h"
        ax.axvline(target, color="k", ls="--", lw=1.2, label=f"expected |{ref}| = {target:.6g}")
        ax.set_title(f"|{symbol}| calibrated, {samples}")
        ax.legend(fontsize=7)
    if dip is not None:
        ax = axes[-1]
        ax.hist(dip, bins=60, color="tab:orange")
        if cal.dip_deg is not None:
            ax.axvline(cal.dip_deg, color="k", ls="--", lw=1, label=f"fit {cal.dip_deg:.2f}°")
            ax.legend(fontsize=7)
        ax.set_title("dip of every sample (°)" if which else "dip per still sample (°)")
    width = fig.get_figwidth()  # margins in inches, so one panel keeps its tick labels
    fig.subplots_adjust(left=0.6 / width, right=1 - 0.1 / width, bottom=0.12, wspace=0.3)
    return fig


_CAPTIONS = {
    "timeline": "Raw readings against time; shaded: the still intervals used as poses (green: "
    "fitted, red hatched: rejected), numbered as in the tables.",
    "residuals": "Norm of each pose mean minus the model's prediction, in raw units. The "
    "dashed line is the error a pose mean is expected to carry; the fit absorbs part of it "
    "(each pose's rotation is fitted too), so residuals of a good fit run well below the line, "
    "and a bar far above it marks a pose that disagrees with the others. Rejected poses are not "
    "in the fit and have no residual: red crosses, listed below with the reason.",
    "histograms": "Norm of the calibrated still samples; dashed: the expected norm (the "
    "reference field's magnitude, i.e. the calibrated unit).",
    "accel_sphere": "Raw (top) and calibrated (bottom) accelerometer readings.",
    "mag_sphere": "Raw (top) and calibrated (bottom) magnetometer readings.",
    "coverage": "Field direction of each pose in the sensor frame (red: rejected). Poses "
    "spread over the sphere determine the calibration best.",
    "temperature": "Each sensor's bias against the die temperature: dots, the bias each pose "
    "shows (its mean minus the model's field part); lines, the fitted polynomial over the "
    "temperatures seen (held at its ends beyond them). docs/methods/temperature.md.",
    **MOTION_CAPTIONS,
    "gyro": "Left: each motion segment's rotation residual after calibration (degrees): the "
    "angle between the rotation the calibrated gyroscope integrates over the motion and the one "
    "the fit finds between the two poses. Right: the gyroscope's mean raw rate in each still "
    "pose against time (its bias and how it drifts).",
}

#: The captions of a continuous fit's figures where the motion, not poses, is drawn.
_CONTINUOUS_CAPTIONS = {
    "timeline": "Raw readings against time: the motion the calibration was fitted to (no "
    "still poses). Shaded orange: stretches down-weighted for body acceleration; green: "
    "rests (the gyroscope's rate under 0.05 rad/s for a second or more).",
    "histograms": "Norm of every calibrated sample, the motion included (body acceleration "
    "widens |a|); dashed: the expected norm (the reference field's magnitude).",
}


def _caption(cal: Calibration, key: str) -> str:
    if is_continuous(cal) and key in _CONTINUOUS_CAPTIONS:
        return _CONTINUOUS_CAPTIONS[key]
    return _CAPTIONS[key]


_TITLES = {
    "timeline": "Timeline of the log",
    "residuals": "Per-pose residuals",
    "histograms": "Norms of calibrated readings",
    "accel_sphere": "Accelerometer readings",
    "mag_sphere": "Magnetometer readings",
    "coverage": "Pose coverage",
    **MOTION_TITLES,
    "gyro": "Gyroscope",
    "temperature": "Bias against temperature",
}
#: The figures a report can hold, in page order: ``--png`` writes ``<name>.png`` for each drawn.
FIGURES = tuple(_TITLES)


def report_figures(
    cal: Calibration, log: Log | str | os.PathLike[str] | None = None
) -> dict[str, MplFigure]:
    """The report's figures as matplotlib Figures, by name (:data:`FIGURES`).

    With the ``log`` the calibration was made from (a :class:`~fieldcal.logs.Log`, or its path,
    read with the columns the calibration recorded), every figure of :func:`write_report`;
    without it, those the calibration holds the data for: ``residuals`` (per pose, when the
    calibration has them) and ``gyro`` (with a gyroscope). See :meth:`fieldcal.Calibration.plot`.
    """
    if log is not None and not isinstance(log, Log):
        log = load_log(os.fspath(log), **_recorded_columns(cal))
    return _figures(cal, log)[0]


def _recorded_columns(cal: Calibration) -> dict[str, Any]:
    """The reading options for the columns ``cal.options["columns"]`` names (role → names)."""
    used = cal.options.get("columns") or {}
    options: dict[str, Any] = {}
    for role, names in used.items():
        if role in ("accel", "mag", "gyro"):
            options[f"{role}_cols"] = list(names)
        elif role in ("time", "pose") and names:
            options[f"{role}_col"] = names[0]
    return options


def _figures(cal: Calibration, log: Log | None) -> tuple[dict[str, MplFigure], list[Pose]]:
    """The figures and the poses they were drawn from."""
    Figure = _figure_class()
    poses = poses_of(cal, log)
    figures: dict[str, MplFigure] = {}
    sensors = [s for s in SENSORS if getattr(cal, s) is not None]
    if log is not None:
        sensors = [s for s in sensors if getattr(log, s) is not None and log.n > 0]
        if not sensors:
            raise InputError(
                f"{log.path}: none of the calibrated sensors' columns are in this log; pass "
                "--accel-cols/--mag-cols"
            )
        motion = (downweighted_rows(cal, log), rest_rows(log)) if is_continuous(cal) else None
        figures["timeline"] = _timeline_figure(Figure, log, sensors, poses, motion)
    with_residuals = [s for s in sensors if any(p.residual[s] is not None for p in poses)]
    if with_residuals:
        figures["residuals"] = _residual_figure(Figure, cal, with_residuals, poses)
    if log is not None:
        figures.update(_log_figures(Figure, cal, log, sensors, poses))
    figures.update(motion_figures(Figure, cal, log))  # continuous motion: none otherwise
    if cal.gyro is not None and cal.gyro_segments:
        figures["gyro"] = _gyro_figure(Figure, cal)
    thermal = _temperature_figure(Figure, cal)
    if thermal is not None:
        figures["temperature"] = thermal
    return figures, poses


def _log_figures(
    Figure: type[MplFigure], cal: Calibration, log: Log, sensors: Sequence[str], poses: list[Pose]
) -> dict[str, MplFigure]:
    """The figures of the corrected log: norms and dip, raw and calibrated spheres, coverage."""
    figures: dict[str, MplFigure] = {}
    located = [p for p in poses if p.spans]
    fitted_rows = [p.rows for p in located if p.rejected is None]
    still = np.concatenate(fitted_rows) if fitted_rows else np.arange(log.n)
    rejected_rows = [p.rows for p in located if p.rejected is not None]
    dropped = np.concatenate(rejected_rows) if rejected_rows else np.zeros(0, dtype=np.int64)
    corrected = {s: cal.sensor(s).correct(getattr(log, s)) for s in sensors}
    norms = {
        s: (np.linalg.norm(c[still], axis=1), np.linalg.norm(c[dropped], axis=1))
        for s, c in corrected.items()
    }
    expected = {s: float(np.linalg.norm(cal.reference(s))) for s in sensors}
    dip = None
    if len(sensors) == 2:
        a, m = corrected["accel"][still], corrected["mag"][still]
        cos = np.einsum("ni,ni->n", a, m) / (np.linalg.norm(a, axis=1) * np.linalg.norm(m, axis=1))
        dip = np.degrees(np.arcsin(np.clip(-cos, -1, 1)))
    figures["histograms"] = _histogram_figure(
        Figure, norms, expected, dip, cal, "every sample" if is_continuous(cal) else ""
    )
    sample = _thin(np.arange(log.n), np.random.default_rng(0))
    for s in sensors:
        figures[f"{s}_sphere"] = _sphere_figure(
            Figure, SENSOR_LABELS[s], getattr(log, s)[sample], corrected[s][sample], expected[s]
        )
    if located and len(located) == len(poses):
        directions = {}
        for s in sensors:
            means = np.array([corrected[s][p.rows].mean(axis=0) for p in poses])
            directions[SENSOR_LABELS[s]] = means / np.linalg.norm(means, axis=1, keepdims=True)
        figures["coverage"] = _coverage_figure(Figure, directions, poses)
    return figures


def write_report(
    cal: Calibration,
    log: Log,
    output: str | Path,
    *,
    png_dir: str | Path | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> None:
    """Write the HTML report of ``cal`` on the log it was made from.

    Parameters
    ----------
    cal : Calibration
        The result, e.g. of :func:`fieldcal.pipeline.calibrate_log` or read from its JSON; its
        poses' ``start``/``stop`` (data-row numbers) locate them in ``log``.
    log : Log
        The log, as loaded by :func:`fieldcal.logs.load_log`.
    output : str or Path
        The HTML file to write (one self-contained page).
    png_dir : str or Path, optional
        Also write each figure there as ``<name>.png`` (``timeline``, ``residuals``,
        ``histograms``, ``accel_sphere``, ``mag_sphere``, ``coverage``, ``gyro``, ``temperature``:
        :data:`FIGURES`).
    on_progress : callable, optional
        Called with one line of text as each figure is drawn (a large log takes seconds).

    Every file is written atomically (a temporary file renamed into place), the PNGs first,
    then the page.

    Raises
    ------
    InputError
        matplotlib is missing, the log has none of the calibrated sensors, it is shorter than
        the calibration's poses (not the log the calibration was made from), or ``output`` is
        the log itself.
    """
    if same_file(output, log.path):
        raise InputError(f"{output}: is the input log {log.path}; write the report to another file")
    figures, poses = _figures(cal, log)
    if png_dir is not None:
        make_folder(png_dir)
    sections = []
    for k, (key, fig) in enumerate(figures.items()):
        if on_progress is not None:
            on_progress(f"report: drawing {_TITLES[key].lower()} ({k + 1} of {len(figures)})")
        buffer = _io.BytesIO()
        fig.savefig(buffer, format="png", dpi=_DPI)
        if png_dir is not None:
            write_bytes(Path(png_dir) / f"{key}.png", buffer.getvalue())
        encoded = base64.b64encode(buffer.getvalue()).decode("ascii")
        section = (
            f"<h2>{_TITLES[key]}</h2><p class='caption'>{_caption(cal, key)}</p>"
            f'<img alt="{_TITLES[key]}" src="data:image/png;base64,{encoded}">'
        )
        if key == "residuals":
            section += rejected_html(cal, poses)
        sections.append(section)
    if "residuals" not in figures and not is_continuous(cal):
        note = (
            "<h2>Per-pose residuals</h2><p>This calibration file has no per-pose residuals "
            "(written by fieldcal 0.1); calibrate the log again to see them.</p>"
        )
        sections.insert(1, note + rejected_html(cal, poses))
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>fieldcal report</title>"
        f"<style>{CSS}</style></head><body>"
        f"<h1>fieldcal report: {esc(log.path)}</h1>"
        f"{banner_html(cal)}{summary_html(cal, log, poses)}{correction_html(cal)}"
        f"{uncertainty_html(cal)}{''.join(sections)}</body></html>"
    )
    write_text(output, page)
