"""A calibration in a notebook: ``Calibration._repr_html_``.

Below :mod:`fieldcal.calibration` (which calls it), so it takes the calibration untyped.

The verdict first (coloured, with its reasons), then each sensor's gain and bias with their
standard errors and units, the dip, the misalignment, the predicted accuracy, the rejected
poses with their reasons, and a small coverage picture: the direction of gravity in the body
frame in every pose (an equirectangular map, as ``fieldcal capture`` draws it), as inline SVG.
Every text is escaped.
"""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np

__all__ = ["calibration_html"]

_COLOURS = {"pass": "#1a7f37", "warn": "#9a6700", "fail": "#cf222e"}
_WIDTH, _HEIGHT = 240, 120


def _pm(value: float, std: float | None) -> str:
    if std is None or not math.isfinite(std):
        return f"{value:.5g}"
    return f"{value:.5g} ± {std:.2g}"


def _sensor(name: str, sensor: Any, unit: str) -> str:
    gain_std, bias_std = sensor.gain_std, sensor.bias_std
    rows = []
    for i in range(3):
        cells = [
            _pm(sensor.gain[i, j], None if gain_std is None else float(gain_std[i, j]))
            for j in range(3)
        ]
        cells.append(_pm(sensor.bias[i], None if bias_std is None else float(bias_std[i])))
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    head = "".join(f"<th>{h}</th>" for h in ("gain x", "gain y", "gain z", "bias"))
    title = html.escape(f"{name}: raw = gain · v + bias, v in {unit}")
    return f"<table><caption>{title}</caption><tr>{head}</tr>{''.join(rows)}</table>"


def _coverage_svg(cal: Any) -> str:
    """Gravity's direction in the body frame per pose: ``R_i`` maps world to body, and down
    is the world's +z (NED)."""
    down = np.asarray(cal.rotations)[:, :, 2] if len(cal.rotations) else np.zeros((0, 3))
    dots = []
    for d in down:
        azimuth = math.degrees(math.atan2(d[1], d[0])) % 360.0
        elevation = math.degrees(math.asin(float(np.clip(d[2], -1.0, 1.0))))
        x = azimuth / 360.0 * _WIDTH
        y = (90.0 - elevation) / 180.0 * _HEIGHT
        dots.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3" fill="#1a7f37"/>')
    frame = (
        f'<rect x="0" y="0" width="{_WIDTH}" height="{_HEIGHT}" fill="none" stroke="#999"/>'
        f'<line x1="0" y1="{_HEIGHT / 2}" x2="{_WIDTH}" y2="{_HEIGHT / 2}" stroke="#ddd"/>'
    )
    return (
        f'<svg width="{_WIDTH}" height="{_HEIGHT}" viewBox="0 0 {_WIDTH} {_HEIGHT}" '
        f'xmlns="http://www.w3.org/2000/svg" role="img"><title>pose coverage</title>'
        f"{frame}{''.join(dots)}</svg>"
        "<div><small>direction of gravity in the body frame per pose: top +Z down, bottom +Z "
        "up, across the azimuth from +X through +Y</small></div>"
    )


def calibration_html(cal: Any) -> str:
    """The calibration as an HTML fragment (see the module's docstring)."""
    parts = ["<div class='fieldcal-calibration'>"]
    level = "unknown" if cal.verdict is None else cal.verdict.level
    headline = "UNKNOWN" if cal.verdict is None else cal.verdict.summary
    colour = _COLOURS.get(level, "#555")
    parts.append(f"<p style='color:{colour};font-weight:bold'>verdict: {html.escape(headline)}</p>")
    if cal.verdict is not None and cal.verdict.reasons:
        items = "".join(
            f"<li>{html.escape(r.text)} <code>{html.escape(r.code)}</code></li>"
            for r in cal.verdict.reasons
        )
        parts.append(f"<ul>{items}</ul>")
    units = cal.units or {}
    for name, label, unit in (
        ("accel", "accelerometer", units.get("accel_calibrated", "|g| = 1")),
        ("mag", "magnetometer", units.get("mag_calibrated", "|h| = 1")),
        ("gyro", "gyroscope", "rad/s"),
    ):
        sensor = getattr(cal, name)
        if sensor is not None:
            parts.append(_sensor(label, sensor, unit))
    facts = []
    if cal.dip_deg is not None:
        facts.append(f"dip {_pm(cal.dip_deg, cal.dip_std_deg)}° (positive below the horizon)")
    ref = cal.field_reference
    if ref is not None:
        facts.append(
            f"{ref.model} at {ref.place} on {ref.date}: dip {_pm(ref.dip_deg, ref.dip_std_deg)}°, "
            f"{ref.intensity / 1000:.2f} µT, declination {ref.declination_deg:+.2f}°"
        )
    if cal.misalignment_deg is not None:
        facts.append(f"misalignment {_pm(cal.misalignment_deg, cal.misalignment_std_deg)}°")
    acc = cal.accuracy
    if acc is not None:
        if acc.tilt_deg is not None:
            facts.append(f"predicted tilt error {acc.tilt_deg:.3g}°")
        if acc.heading_deg is not None:
            facts.append(f"predicted heading error {acc.heading_deg:.3g}°")
    facts.append(f"{cal.n_poses} poses, method {cal.method}")
    parts.append("<p>" + html.escape("; ".join(facts)) + "</p>")
    if cal.rejected:
        items = "".join(
            f"<li>pose {r.index + 1} ({html.escape(r.sensor)}): {html.escape(r.reason)}</li>"
            for r in cal.rejected
        )
        parts.append(f"<p>rejected poses:</p><ul>{items}</ul>")
    parts.append(_coverage_svg(cal))
    parts.append("</div>")
    return "".join(parts)
