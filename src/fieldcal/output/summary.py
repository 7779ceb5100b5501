"""The human-readable summary of a calibration (rich tables), for ``calibrate`` and ``demo``."""

from __future__ import annotations

from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from ..calibration import Calibration, SensorCalibration

__all__ = ["print_summary", "print_truth_comparison"]

_SOURCES = {
    "scatter": "from the within-pose scatter (Eq. 7)",
    "residuals": "estimated from the fit's residuals (one sample per pose); errors widened",
    "user": "given by the user (--noise)",
}


def _pm(value: float, std: float | None, fmt: str = ".5g") -> str:
    return f"{value:{fmt}}" if std is None or not np.isfinite(std) else f"{value:{fmt}} ± {std:.1g}"


def _sensor_table(name: str, sensor: SensorCalibration) -> Table:
    table = Table(title=f"{name}: raw = gain · v + bias", title_justify="left")
    for column in ("gain x", "gain y", "gain z", "bias"):
        table.add_column(column, justify="right")
    for i in range(3):
        gains = [
            _pm(sensor.gain[i, j], None if sensor.gain_std is None else sensor.gain_std[i, j])
            for j in range(3)
        ]
        bias = _pm(sensor.bias[i], None if sensor.bias_std is None else sensor.bias_std[i])
        table.add_row(*gains, bias)
    return table


def _flags(pose: dict[str, Any], n: int) -> str:
    flags = []
    share = pose.get("share")
    if share is not None and n > 0 and share > 3.0 / n:
        flags.append("high residual")
    if pose.get("pieces"):
        flags.append(f"merged {len(pose['pieces'])} runs")
    return ", ".join(flags)


def print_summary(
    console: Console, cal: Calibration, doc: dict[str, Any], notes: list[str] | None = None
) -> None:
    """Gains and biases ± standard errors, noise, dip, misalignment, certificate, poses."""
    for note in notes or []:
        console.print(note, markup=False)
    for name, sensor in (("accelerometer", cal.accel), ("magnetometer", cal.mag)):
        if sensor is None:
            continue
        console.print(_sensor_table(name, sensor))
        noise = ", ".join(f"{v:.3g}" for v in np.sqrt(np.diag(sensor.noise_cov)))
        source = _SOURCES.get(sensor.noise_source, sensor.noise_source)
        console.print(f"  noise std per axis (one raw sample): {noise} — {source}")
    if cal.dip_deg is not None:
        console.print(
            f"dip angle: {_pm(cal.dip_deg, cal.dip_std_deg, '.3f')}° (positive below the horizon)"
        )
    if cal.misalignment_deg is not None:
        console.print(
            f"misalignment between the sensors: "
            f"{_pm(cal.misalignment_deg, cal.misalignment_std_deg, '.3f')}°"
        )
    diag = cal.diagnostics
    if diag is not None:
        from_residuals = any(
            s is not None and s.noise_source == "residuals" for s in (cal.accel, cal.mag)
        )
        verdict = (
            "not a test: the noise was estimated from these residuals"
            if from_residuals
            else "consistent with the noise"
            if np.isfinite(diag.p_value) and diag.p_value > 0.01
            else "the model does not explain the data to within the noise; check the flagged poses"
            if np.isfinite(diag.p_value)
            else "no degrees of freedom left for a test"
        )
        console.print(
            f"fit certificate: J = {diag.statistic:.4g}, dof = {diag.dof}, "
            f"p = {diag.p_value:.3g} ({verdict})"
            + (f"; status: {diag.status}" if diag.status else "")
        )
    console.print(f"method {cal.method}, {cal.iterations} iterations, converged: {cal.converged}")
    still = doc.get("still_detection")
    if still:
        console.print(
            f"still detection: {still['count']} segments, window {still['window']} samples, "
            f"threshold {still['threshold_std']:.3g} per-axis std "
            f"(noise floor {np.sqrt(still['noise_floor_var'] / 3):.3g})"
        )
    table = Table(
        title="poses (share: the pose's part of the fit's residual cost J)", title_justify="left"
    )
    columns = (
        "#",
        "start",
        "stop",
        "label",
        "orient.",
        "samples",
        "std",
        "share",
        "flags",
    )
    for column in columns:
        table.add_column(column, justify="right")
    n = len(cal.poses)
    for i, pose in enumerate(cal.poses):
        std = pose.get("std")
        share = pose.get("share")
        table.add_row(
            str(i),
            str(pose.get("start", "")),
            str(pose.get("stop", "")),
            str(pose.get("label", "")),
            str(pose.get("orientation", "")),
            str(pose.get("samples", "")),
            "" if std is None else f"{std:.3g}",
            "" if share is None else f"{100 * share:.1f} %",
            _flags(pose, n),
        )
    console.print(table)


def print_truth_comparison(
    console: Console, truth: Calibration, cal: Calibration, deltas: dict[str, float | None]
) -> None:
    """Truth against estimate (gains, biases, dip) and δ of Eq. 19 per sensor."""
    table = Table(title="truth vs estimate", title_justify="left")
    for column in ("quantity", "truth", "estimate", "error"):
        table.add_column(column, justify="right")
    for name in ("accel", "mag"):
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
            console.print(
                f"δ ({name}, Eq. 19): not computed (the poses found differ from the truth)"
            )
        else:
            console.print(f"δ ({name}, Eq. 19) = {delta:.4f} noise standard deviations")
