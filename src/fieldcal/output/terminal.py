"""The terminal summary of a calibration (rich tables), for ``calibrate`` and ``demo``.

The verdict comes first, then what was used, each sensor, the predicted accuracy, the
certificate and the poses. Every line is printed with markup off: paths, column names, labels
and reasons are the user's or the library's text, never rich markup.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from ..calibration import Calibration, SensorCalibration
from ..trust.accuracy import temperature_span
from ..trust.wording import certificate_reading, status_shown

if TYPE_CHECKING:  # the report is only printed here: loading noise is the command's
    from ..noise import NoiseReport

__all__ = [
    "MAX_POSE_ROWS",
    "print_summary",
    "print_truth_comparison",
    "print_verdict",
    "temperature_lines",
]

#: Rows of the pose table printed before the rest is summed up in one line.
MAX_POSE_ROWS = 20

_SOURCES = {
    "scatter": "from the within-pose scatter (Eq. 7)",
    "residuals": "estimated from the fit's residuals (one sample per pose); errors widened",
    "user": "given by the user (--noise)",
}
#: A rule under the header only: the tables fit 80 columns.
_BOX = box.SIMPLE_HEAD
_SENSOR_NAMES = (("accel", "accelerometer"), ("mag", "magnetometer"))


def _say(console: Console, text: str) -> None:
    """One line, literally (no markup, no emoji codes, no highlighting)."""
    console.print(text, markup=False, emoji=False, highlight=False)


def _pm(value: float, std: float | None, fmt: str = ".5g") -> str:
    """``value ± std``, the value to the decimal of the standard error's first digit."""
    if std is None or not np.isfinite(std) or std <= 0:
        return f"{value:{fmt}}"
    if value == 0 or not np.isfinite(value):
        return f"{value:.1g} ± {std:.1g}"
    digits = int(np.floor(np.log10(abs(value))) - np.floor(np.log10(std))) + 1
    return f"{value:.{min(max(digits, 1), 9)}g} ± {std:.1g}"


def print_verdict(console: Console, cal: Calibration) -> None:
    """``verdict: PASS|WARN|FAIL`` with the reasons' codes (``verdict: WARN (accuracy,
    untested)``), then each reason's text on its own line.

    Parameters
    ----------
    console : rich.console.Console
    cal : Calibration
    """
    if cal.verdict is None:
        return
    _say(console, f"verdict: {cal.verdict.summary}")
    for reason in cal.verdict.reasons:
        _say(console, f"  {reason.text}")


def _sensor_table(name: str, sensor: SensorCalibration, v: str = "v") -> Table:
    table = Table(title=f"{name}: raw = gain · {v} + bias", title_justify="left", box=_BOX)
    for column in ("gain x", "gain y", "gain z", "bias"):
        table.add_column(column, justify="right")
    gain_std, bias_std = sensor.gain_std, sensor.bias_std
    for i in range(3):
        gains = [
            _pm(sensor.gain[i, j], None if gain_std is None else gain_std[i, j]) for j in range(3)
        ]
        table.add_row(*gains, _pm(sensor.bias[i], None if bias_std is None else bias_std[i]))
    return table


def _print_sensor(
    console: Console, name: str, sensor: SensorCalibration, poses: bool = True
) -> None:
    """A field sensor's table, its noise and (``poses``: a pose calibration) the pose-level
    noise, its temperature terms."""
    console.print(_sensor_table(name, sensor))
    noise = ", ".join(f"{v:.3g}" for v in np.sqrt(np.diag(sensor.noise_cov)))
    source = _SOURCES.get(sensor.noise_source, sensor.noise_source)
    _say(console, f"  noise std per axis (one raw sample): {noise} — {source}")
    if not poses:  # a continuous fit has no pose means, so no pose-level noise
        for line in temperature_lines(sensor):
            _say(console, line)
        return
    q, se = sensor.pose_noise_std, sensor.pose_noise_std_se
    how = "estimated" if se is not None else "not estimated (given or none)"
    _say(
        console,
        f"  pose-level noise std per axis (raw units): {_pm(q, se, '.3g')} — {how}",
    )
    for line in temperature_lines(sensor):
        _say(console, line)


def temperature_lines(sensor: SensorCalibration) -> list[str]:
    """The bias against temperature (``sensor.temperature``): the reference, the span, each
    order's coefficients with their error bars, or why there are none; nothing without a
    temperature column."""
    model = sensor.temperature
    if model is None:
        return []
    low, high = model.span
    head = (
        f"  bias vs temperature: T_ref {model.reference:.1f} °C, poses {low:.1f} to {high:.1f} °C"
    )
    if model.refused:
        return [f"{head}: span too small, no terms (calibrated at T_ref)"]
    if not model.order:
        return [f"{head}: no temperature effect found (no terms)"]
    lines = [f"{head}: bias(T) = bias + Σ c_k (T − T_ref)^k"]
    for k in range(model.order):
        std = None if model.std is None else model.std[k]
        values = ", ".join(
            _pm(model.coefficients[k, j], None if std is None else std[j], ".3g") for j in range(3)
        )
        unit = "K" if k == 0 else f"K^{k + 1}"
        lines.append(f"    c{k + 1} = ({values}) raw units per {unit}")
    return lines


def _print_gyro(console: Console, cal: Calibration) -> None:
    """The gyroscope's table (ω in rad/s), its noise, the bias drift and the motion segments'
    residual angles."""
    gyro = cal.gyro
    assert gyro is not None
    console.print(_sensor_table("gyroscope", gyro, "ω (rad/s)"))
    noise = ", ".join(f"{v:.3g}" for v in np.sqrt(np.diag(gyro.noise_cov)))
    source = gyro.noise_source if cal.method == "continuous" else "from the still poses"
    _say(console, f"  noise std per axis (one raw sample): {noise} — {source}")
    for line in temperature_lines(gyro):
        _say(console, line)
    info = cal.options.get("gyro", {})
    if info.get("drift") is not None:
        p_value = info.get("drift_p_value")
        verdict = (
            ""
            if p_value is None
            else (f" (p = {p_value:.2g}: {'drifts' if p_value < 0.01 else 'no significant drift'})")
        )
        thermal = gyro.temperature is not None and gyro.temperature.order > 0
        where = " beyond the temperature terms" if thermal else ""
        _say(
            console,
            f"  bias drift across the log{where}: {info['drift']:.3g} raw units/s "
            f"({3600 * info['drift']:.3g} per hour){verdict}",
        )
    residuals = [s["residual_deg"] for s in cal.gyro_segments if "residual_deg" in s]
    if residuals:
        _say(
            console,
            f"  {len(residuals)} motion segments ({info.get('method', '?')}): rotation residual "
            f"median {np.median(residuals):.3g}°, largest {np.max(residuals):.3g}°",
        )


def _accuracy_line(cal: Calibration) -> str | None:
    acc = cal.accuracy
    if acc is None:
        return None
    parts = []
    if acc.tilt_deg is not None:
        parts.append(f"tilt {acc.tilt_deg:.3g}°")
    if acc.heading_deg is not None:
        parts.append(f"heading {acc.heading_deg:.3g}°")
    if acc.accel_norm_rel is not None:
        parts.append(f"|a| {100 * acc.accel_norm_rel:.3g} %")
    if acc.mag_norm_rel is not None:
        parts.append(f"|m| {100 * acc.mag_norm_rel:.3g} %")
    if not parts:
        return None
    span = temperature_span(cal)
    over = (
        "orientations"
        if span is None
        else (
            f"orientations and the logged temperatures {span[0]:.1f}–{span[1]:.1f} °C, the "
            "temperature terms' uncertainty included"
        )
    )
    return f"predicted accuracy after calibration (1σ, RMS over {over}): " + ", ".join(parts)


def _certificate_line(cal: Calibration) -> str | None:
    diag = cal.diagnostics
    if diag is None:
        return None
    status = status_shown(cal)
    return (
        f"fit certificate: J = {diag.statistic:.4g}, dof = {diag.dof}, "
        f"p = {diag.p_value:.3g} ({certificate_reading(cal)})"
        + (f"; status: {status}" if status else "")
    )


def _pose_name(index: int, poses: Sequence[Mapping[str, object]]) -> str:
    row = next((p for p in poses if p.get("index") == index), {})
    label = row.get("label")
    where = f", label {label}" if label is not None and str(label) != str(index) else ""
    if label is None and "start" in row:
        stop = row["stop"]
        where = f", rows {row['start']} to {stop - 1 if isinstance(stop, int) else stop}"
    return f"pose {index}{where}"


def _print_rejected(console: Console, cal: Calibration) -> None:
    if not cal.rejected:
        return
    _say(console, f"rejected poses ({len(cal.rejected)}, left out of the fit):")
    for r in cal.rejected:
        _say(
            console,
            f"  {_pose_name(r.index, cal.poses)} ({r.sensor}, p = {r.p_value:.2g}): {r.reason}",
        )


def _flags(pose: Mapping[str, object], n_fitted: int) -> list[str]:
    flags = []
    if pose.get("rejected"):
        flags.append("rejected")
    share = pose.get("share")
    if isinstance(share, (int, float)) and n_fitted > 0 and share > 3.0 / n_fitted:
        flags.append("high residual")
    pieces = pose.get("pieces")
    if isinstance(pieces, (list, tuple)) and pieces:
        flags.append(f"merged {len(pieces)} runs")
    return flags


def _pose_cells(pose: Mapping[str, object], i: int, flags: list[str]) -> dict[str, str]:
    std, share = pose.get("std"), pose.get("share")
    return {
        "#": str(pose.get("index", i)),
        "start": str(pose.get("start", "")),
        "stop": str(pose.get("stop", "")),
        "label": str(pose.get("label", "")),
        "orient.": str(pose.get("orientation", "")),
        "samples": str(pose.get("samples", "")),
        "std": "" if std is None else f"{std:.3g}",
        "share": f"{100 * share:.1f} %" if isinstance(share, (int, float)) else "",
        "flags": ", ".join(flags),
    }


def _print_poses(console: Console, poses: Sequence[Mapping[str, object]]) -> None:
    """The first :data:`MAX_POSE_ROWS` poses as a table, the rest summed up in one line."""
    n_fitted = sum(p.get("share") is not None for p in poses)
    flags = [_flags(p, n_fitted) for p in poses]
    rows = [_pose_cells(p, i, f) for i, (p, f) in enumerate(zip(poses, flags, strict=True))]
    shown = rows[:MAX_POSE_ROWS]
    table = Table(
        title="poses (share: the pose's part of the fit's residual cost J)",
        title_justify="left",
        box=_BOX,
        pad_edge=False,
    )
    # a column no shown pose fills (labels of detected poses) is left out
    columns = [c for c in shown[0] if c in ("#", "flags") or any(r[c] for r in shown)]
    for column in columns:
        # only a label (the user's text, any length) may wrap: numbers and flags stay whole
        table.add_column(column, justify="right", no_wrap=column != "label")
    for row in shown:
        table.add_row(*(Text(row[c]) for c in columns))  # Text: labels are printed literally
    console.print(table)
    rest = flags[MAX_POSE_ROWS:]
    if rest:
        counts: dict[str, int] = {}
        for flag in rest:
            for f in flag:
                kind = "merged" if f.startswith("merged") else f
                counts[kind] = counts.get(kind, 0) + 1
        flagged = ", ".join(f"{n} {kind}" for kind, n in counts.items()) or "none flagged"
        _say(
            console,
            f"… and {len(rest)} more poses ({flagged}); every pose is in the JSON's `poses`",
        )


def print_summary(
    console: Console,
    cal: Calibration,
    doc: Mapping[str, Any],
    notes: Sequence[str] | None = None,
) -> None:
    """The verdict first, then what was used, each sensor, accuracy, certificate and poses.

    Parameters
    ----------
    console : rich.console.Console
        Where to print.
    cal : Calibration
        The result (its ``poses`` rows as :func:`fieldcal.pipeline.calibrate_log` gives them).
    doc : mapping
        The JSON document written (for ``still_detection``).
    notes : sequence of str, optional
        Lines on the input (columns used, how the poses were found, warnings).
    """
    print_verdict(console, cal)
    for note in notes or []:
        _say(console, note)
    for name, label in _SENSOR_NAMES:
        sensor = getattr(cal, name)
        if sensor is not None:
            _print_sensor(console, label, sensor, poses=cal.method != "continuous")
    if cal.gyro is not None:
        _print_gyro(console, cal)
    if cal.dip_deg is not None:
        _say(
            console,
            f"dip angle: {_pm(cal.dip_deg, cal.dip_std_deg, '.3f')}° (positive below the horizon)",
        )
    ref = cal.field_reference
    if ref is not None:
        east = "E" if ref.declination_deg >= 0 else "W"
        dip = _pm(ref.dip_deg, ref.dip_std_deg, ".2f")
        _say(
            console,
            f"{ref.model} at {ref.place} on {ref.date}: dip {dip}°, "
            f"intensity {ref.intensity / 1000:.2f} µT, declination "
            f"{abs(ref.declination_deg):.2f}° {east} (true heading = magnetic heading "
            f"{'+' if ref.declination_deg >= 0 else '-'} {abs(ref.declination_deg):.2f}°)",
        )
    if cal.misalignment_deg is not None:
        _say(
            console,
            "misalignment between the sensors: "
            f"{_pm(cal.misalignment_deg, cal.misalignment_std_deg, '.3f')}°",
        )
    for line in (_accuracy_line(cal), _certificate_line(cal)):
        if line is not None:
            _say(console, line)
    _say(
        console,
        f"method {cal.method}, {cal.iterations} iterations, optimiser converged: {cal.converged}",
    )
    still = doc.get("still_detection")
    if still:
        _say(
            console,
            f"still detection: {still['count']} segments, window {still['window']} samples, "
            f"threshold {still['threshold_std']:.3g} per-axis std "
            f"(noise floor {np.sqrt(still['noise_floor_var'] / 3):.3g})",
        )
    windows = doc.get("pose_windows")
    if windows:
        _say(
            console,
            f"windows: {windows['count']} of {windows['window']} samples; motion inside them "
            f"{100 * windows['motion']:.2g} % of the field (limit {100 * windows['limit']:.2g} %)",
        )
    _print_rejected(console, cal)
    if cal.poses:
        _print_poses(console, cal.poses)


def print_truth_comparison(
    console: Console, truth: Calibration, cal: Calibration, deltas: Mapping[str, float | None]
) -> None:
    """Truth against estimate (gains, biases, dip) and δ of Eq. 19 per sensor.

    Parameters
    ----------
    console : rich.console.Console
    truth, cal : Calibration
        The simulated truth and the estimate.
    deltas : mapping
        δ per sensor (``None`` when not computed).
    """
    table = Table(title="truth vs estimate", title_justify="left", box=_BOX)
    for column in ("quantity", "truth", "estimate", "error"):
        table.add_column(column, justify="right")
    for name, _ in _SENSOR_NAMES:
        t, e = getattr(truth, name), getattr(cal, name)
        if t is None or e is None:
            continue
        table.add_row(f"{name} gain (max |Δ|)", "", "", f"{np.max(np.abs(t.gain - e.gain)):.3g}")
        for i in range(3):
            table.add_row(
                f"{name} bias[{i}]",
                f"{t.bias[i]:.5f}",
                f"{e.bias[i]:.5f}",
                f"{e.bias[i] - t.bias[i]:+.2g}",
            )
    if truth.dip_deg is not None and cal.dip_deg is not None:
        table.add_row(
            "dip (°)",
            f"{truth.dip_deg:.3f}",
            f"{cal.dip_deg:.3f}",
            f"{cal.dip_deg - truth.dip_deg:+.3f}",
        )
    console.print(table)
    for name, delta in deltas.items():
        if delta is None:
            _say(
                console, f"δ ({name}, Eq. 19): not computed (the poses found differ from the truth)"
            )
        else:
            _say(console, f"δ ({name}, Eq. 19) = {delta:.4f} noise standard deviations")


def print_noise(console: Console, report: NoiseReport) -> None:
    """A noise report: what was analysed, then per sensor a table of N, K and B per axis with
    their standard errors, in the readings' units, and the notes."""
    _say(
        console,
        f"{report.source}: {report.seconds:.4g} s of still data at {report.rate:.4g} Hz in "
        f"{len(report.stretches)} stretch(es), longest {report.longest:.4g} s ({report.still})",
    )
    labels = {"accel": "accelerometer", "gyro": "gyroscope", "mag": "magnetometer"}
    for name, fit in report.fits.items():
        low, high = fit.tau_range
        table = Table(
            title=f"{labels.get(name, name)} ({fit.unit}), τ fitted {low:.3g}–{high:.3g} s",
            title_justify="left",
            box=_BOX,
        )
        for column in ("axis", f"N ({fit.unit}/√Hz)", f"K ({fit.unit}/s/√Hz)", f"B ({fit.unit})"):
            table.add_column(column, justify="right")
        for j, axis in enumerate("xyz"):
            walk = _pm(fit.random_walk[j], fit.random_walk_std[j], ".3g")
            if not fit.random_walk_resolved[j]:
                walk += " (not resolved)"
            table.add_row(
                axis,
                _pm(fit.noise_density[j], fit.noise_density_std[j], ".3g"),
                walk,
                _pm(fit.bias_instability[j], fit.bias_instability_std[j], ".3g"),
            )
        console.print(table)
    for note in report.notes:
        _say(console, f"note: {note}")
