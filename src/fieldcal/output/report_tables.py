"""The HTML of a calibration's report, figures aside: the poses as the report lists them
(:class:`Pose`), the numbers formatted with their error bars, the banner, the summary, the
correction, the uncertainty and the rejected poses' tables (:mod:`fieldcal.output.report`
puts them together with the figures)."""

from __future__ import annotations

import html
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..calibration import SENSORS, Calibration, SensorCalibration
from ..errors import InputError
from ..logs import Log
from ..trust.accuracy import temperature_span
from ..trust.wording import banner_headline, certificate_reading, status_shown
from .motion_figures import (
    is_continuous,
)

if TYPE_CHECKING:
    pass


__all__ = [
    "CSS",
    "SENSOR_LABELS",
    "Pose",
    "banner_html",
    "cell_html",
    "correction_html",
    "esc",
    "inverse_gain_std",
    "plain",
    "pm",
    "poses_of",
    "rejected_html",
    "rows_text",
    "summary_html",
    "uncertainty_html",
    "unit_of",
]

Array = NDArray[np.float64]

#: Each sensor as the report names it.
SENSOR_LABELS = {"accel": "accelerometer", "mag": "magnetometer", "gyro": "gyroscope"}


@dataclass(frozen=True)
class Pose:
    """One entry of ``cal.poses`` as the report draws it."""

    position: int  # order in cal.poses: the x position in the pose plots
    index: int  # the caller's pose number (that of RejectedPose.index)
    name: str  # label or number, for axes and tables
    spans: tuple[tuple[int, int], ...]  # kept-row ranges [lo, hi) of the log
    rejected: str | None  # one line "sensor: reason", or None for a fitted pose
    residual: dict[str, Array | None]  # raw units, per sensor
    samples: dict[str, int | None]  # samples behind each sensor's pose mean

    @property
    def rows(self) -> NDArray[np.int64]:
        """Kept-row positions of the pose's samples."""
        if not self.spans:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate([np.arange(a, b) for a, b in self.spans])


def poses_of(cal: Calibration, log: Log | None) -> list[Pose]:
    """The poses of ``cal`` with their rows in ``log`` (from ``start``/``stop`` or ``pieces``);
    without a log, the poses alone (no rows)."""
    last = int(log.index[-1]) + 1 if log is not None and log.n else 0
    reasons = {r.index: f"{r.sensor}: {r.reason}" for r in cal.rejected}
    out = []
    for position, pose in enumerate(cal.poses):
        index = int(pose.get("index", position))
        spans: tuple[tuple[int, int], ...] = ()
        if log is not None and "start" in pose and "stop" in pose:
            if pose["stop"] > last:
                raise InputError(
                    f"{log.path}: the calibration's pose {index} ends at row {pose['stop']} but "
                    f"the log has {last} rows; give the log it was made from"
                )
            pieces = pose.get("pieces") or [[pose["start"], pose["stop"]]]
            lo, hi = np.searchsorted(log.index, np.asarray(pieces, dtype=np.int64).T)
            spans = tuple((int(a), int(b)) for a, b in zip(lo, hi, strict=True) if b > a)
        residual: dict[str, Array | None] = {}
        samples: dict[str, int | None] = {}
        for s in SENSORS:
            value = pose.get(f"{s}_residual")
            residual[s] = None if value is None else np.asarray(value, dtype=float)
            count = pose.get(f"{s}_samples", pose.get("samples"))
            samples[s] = None if count is None else int(count)
        rejected = reasons.get(index, pose.get("rejected"))
        out.append(
            Pose(
                position=position,
                index=index,
                name=str(pose.get("label", index)),
                spans=spans,
                rejected=None if rejected is None else str(rejected),
                residual=residual,
                samples=samples,
            )
        )
    return out


def esc(value: object) -> str:
    """User or file text, printed literally in HTML."""
    return html.escape(str(value), quote=True)


def plain(text: str) -> str:
    """User text, printed literally in a figure (``$`` would start matplotlib mathematics)."""
    return text.replace("$", r"\$")


def pm(value: float | None, std: float | None = None, digits: int = 6) -> str:
    """``value ± std`` with the value rounded where the standard error's 2nd digit falls."""
    if value is None or not np.isfinite(value):
        return "n/a"
    if std is None or not np.isfinite(std) or std <= 0:
        return f"{value:.{digits}g}"
    decimals = min(max(1 - math.floor(math.log10(std)), 0), 15)
    return f"{value:.{decimals}f} ± {std:.{decimals}f}"


def unit_of(cal: Calibration, key: str) -> str:
    return str(cal.units.get(key, "as given"))


def inverse_gain_std(sensor: SensorCalibration) -> Array | None:
    """Standard errors of ``M = inv(gain)`` by the delta method, or ``None`` without a
    covariance.

    ``dM = −M dK M``; with row-major vectorisation ``vec(A X B) = (A ⊗ Bᵀ) vec(X)``, so the
    Jacobian of ``vec(M)`` with respect to ``vec(K)`` is ``−(M ⊗ Mᵀ)``.
    """
    cov = sensor.covariance
    names = [f"gain[{j},{k}]" for j in range(3) for k in range(3)]
    if cov is None or not all(n in cov.names for n in names):
        return None
    idx = [cov.index(n) for n in names]
    M = np.linalg.inv(sensor.gain)
    J = -np.kron(M, M.T)
    C = J @ cov.matrix[np.ix_(idx, idx)] @ J.T
    return np.sqrt(np.maximum(np.diag(C), 0.0)).reshape(3, 3)


CSS = (
    "body{font-family:sans-serif;max-width:1100px;margin:auto;padding:0 1em}"
    "th{text-align:left;padding-right:1em;font-weight:600}td{padding-right:1.2em}"
    "table.num td{text-align:right;font-family:monospace}img{max-width:100%}"
    ".verdict{border-left:8px solid;padding:.6em 1em;margin:1em 0;border-radius:4px}"
    ".verdict h2{margin:.1em 0}.verdict ul{margin:.3em 0}"
    ".pass{background:#e3f4e6;border-color:#2e8b3a}.warn{background:#fff3d6;border-color:#e0a000}"
    ".fail{background:#fbe1e1;border-color:#c62828}.none{background:#eceff1;border-color:#78909c}"
    ".caption{color:#444;font-size:90%}"
)


def banner_html(cal: Calibration) -> str:
    verdict = cal.verdict
    if verdict is None:
        return (
            '<div class="verdict none"><h2>no verdict (calibration file from fieldcal 0.1)</h2>'
            "<p>Calibrate the log again with this version to get one.</p></div>"
        )
    reasons = "".join(f"<li>{esc(r.text)}</li>" for r in verdict.reasons)
    body = f"<ul>{reasons}</ul>" if reasons else "<p>no reason for doubt was found</p>"
    headline = banner_headline(cal)
    codes = f'<p class="codes">{esc(verdict.summary)}</p>' if verdict.reasons else ""
    return f'<div class="verdict {esc(verdict.level)}"><h2>{headline}</h2>{codes}{body}</div>'


def summary_html(cal: Calibration, log: Log, poses: list[Pose]) -> str:
    rows = [("log", f"{esc(log.path)} ({log.n} rows used, {log.dropped} dropped)")]
    if log.used:
        columns = "; ".join(f"{esc(k)}: {esc(', '.join(v))}" for k, v in log.used.items())
        rows.append(("columns", columns))
    rows.extend(("note", esc(note)) for note in log.notes)
    traj = cal.options.get("trajectory")
    if is_continuous(cal) and isinstance(traj, dict):
        down = len(cal.options.get("downweighted") or [])
        rows.append(
            (
                "motion",
                f"{traj['duration_s']:.4g} s of continuous motion, {traj['epochs']} epochs, "
                f"{100 * traj['gravity_coverage']:.0f} % of gravity directions visited, "
                f"{down} stretch(es) down-weighted for body acceleration (no still poses)",
            )
        )
    else:
        n_rejected = sum(p.rejected is not None for p in poses) or len(cal.rejected)
        found = max(len(poses), cal.n_poses)
        rows.append(("poses", f"{found} found, {cal.n_poses} fitted, {n_rejected} rejected"))
    rows.append(("method", f"{esc(cal.method)} (converged: {'yes' if cal.converged else 'no'})"))
    if cal.message:
        rows.append(("optimiser", esc(cal.message)))
    d = cal.diagnostics
    if d is not None:
        shown = status_shown(cal)
        status = f"; status: {esc(shown)}" if shown else ""
        rows.append(
            (
                "certificate",
                f"J = {d.statistic:.4g}, dof = {d.dof}, p = {d.p_value:.3g} "
                f"({esc(certificate_reading(cal))}){status}",
            )
        )
    ref = cal.field_reference
    if ref is not None:
        text = (
            f"{ref.model} at {ref.place} on {ref.date}: dip {pm(ref.dip_deg, ref.dip_std_deg, 3)}°"
            f" (fitted {pm(cal.dip_deg, cal.dip_std_deg, 3)}°), {ref.intensity / 1000:.2f} µT, "
            f"declination {ref.declination_deg:+.2f}°"
        )
        rows.append(("Earth's field", esc(text)))
    rows.append(("created", f"{esc(cal.created)} by fieldcal {esc(cal.version)}"))
    return "<table>" + "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows) + "</table>"


def cell_html(value: float, std: Array | None, *at: int) -> str:
    return f"<td>{pm(value, None if std is None else float(std[at]))}</td>"


def correction_html(cal: Calibration) -> str:
    parts = [
        "<h2>Correction</h2>",
        "<p>Firmware applies <code>body = M (raw − b)</code> with <code>M = inv(gain)</code>. "
        "Each entry ± its standard error; the errors of <code>M</code> come from the gain "
        "covariance by the delta method (<code>dM = −M dK M</code>).</p>",
    ]
    for s in (*SENSORS, "gyro"):
        sensor: SensorCalibration | None = getattr(cal, s)
        if sensor is None:
            continue
        raw, calibrated = esc(unit_of(cal, f"{s}_raw")), esc(unit_of(cal, f"{s}_calibrated"))
        M = np.linalg.inv(sensor.gain)
        M_std = inverse_gain_std(sensor)
        K_std, b_std = sensor.gain_std, sensor.bias_std
        rows = []
        for i in range(3):
            m = "".join(cell_html(M[i, j], M_std, i, j) for j in range(3))
            k = "".join(cell_html(sensor.gain[i, j], K_std, i, j) for j in range(3))
            b = cell_html(sensor.bias[i], b_std, i)
            rows.append(f"<tr><th>{'xyz'[i]}</th>{m}{b}<td></td>{k}</tr>")
        parts.append(
            f"<h3>{SENSOR_LABELS[s]}</h3><p>raw units: {raw}; calibrated units: {calibrated}</p>"
            '<table class="num"><tr><th></th><th colspan="3">M = inv(gain) (calibrated per raw '
            'unit)</th><th>bias b (raw units)</th><th></th><th colspan="3">gain K (model: raw = '
            "K v + b)</th></tr>" + "".join(rows) + "</table>"
        )
        if M_std is None:
            parts.append("<p>no parameter covariance: standard errors are not available</p>")
    return "".join(parts)


def uncertainty_html(cal: Calibration) -> str:
    rows = []
    for s in SENSORS:
        sensor: SensorCalibration | None = getattr(cal, s)
        if sensor is None:
            continue
        raw = esc(unit_of(cal, f"{s}_raw"))
        sigma = np.sqrt(np.maximum(np.diag(sensor.noise_cov), 0.0))
        se = None
        if sensor.noise_cov_std is not None:  # se(σ) = se(σ²) / 2σ
            se = np.diag(sensor.noise_cov_std) / np.maximum(2 * sigma, 1e-300)
        noise = ", ".join(pm(sigma[k], None if se is None else se[k], 4) for k in range(3))
        rows.append(
            (
                f"{SENSOR_LABELS[s]} noise per sample",
                f"{noise} (raw units {raw}, per axis; source: {esc(sensor.noise_source)})",
            )
        )
        rows.append(
            (
                f"{SENSOR_LABELS[s]} pose-level noise q",
                f"{pm(sensor.pose_noise_std, sensor.pose_noise_std_se, 4)} (raw units {raw}, "
                "per axis)",
            )
        )
    if cal.gravity_norm is not None:
        rows.append(("|g| (calibrated accelerometer unit)", f"{cal.gravity_norm:.6g}"))
    if cal.field_strength is not None:
        rows.append(("|h| (calibrated magnetometer unit)", f"{cal.field_strength:.6g}"))
    if cal.dip_deg is not None:
        rows.append(("dip", f"{pm(cal.dip_deg, cal.dip_std_deg, 4)}° (positive below horizon)"))
    if cal.misalignment_deg is not None:
        rows.append(
            (
                "misalignment between the sensors",
                f"{pm(cal.misalignment_deg, cal.misalignment_std_deg, 4)}°",
            )
        )
    acc = cal.accuracy
    if acc is not None:
        for label, value, scale, unit in (
            ("predicted tilt error (1σ)", acc.tilt_deg, 1.0, "°"),
            ("predicted heading error (1σ, level device)", acc.heading_deg, 1.0, "°"),
            ("predicted |a| error (1σ, relative)", acc.accel_norm_rel, 100.0, " %"),
            ("predicted |m| error (1σ, relative)", acc.mag_norm_rel, 100.0, " %"),
        ):
            if value is not None:
                rows.append((label, f"{value * scale:.3g}{unit}"))
        span = temperature_span(cal)
        if span is not None:
            rows.append(
                (
                    "predicted over the logged temperatures",
                    f"{span[0]:.1f}–{span[1]:.1f} °C (the temperature terms' uncertainty included)",
                )
            )
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<h2>Uncertainty and predicted accuracy</h2><table>{body}</table>"


def rejected_html(cal: Calibration, poses: list[Pose]) -> str:
    by_index = {p.index: p for p in poses}
    rows = []
    listed = set()
    for r in cal.rejected:
        pose = by_index.get(r.index)
        listed.add(r.index)
        rows.append(
            (
                pose.name if pose is not None else str(r.index),
                rows_text(cal, r.index),
                r.sensor,
                f"{r.statistic:.3g}",
                f"{r.p_value:.2g}",
                r.reason,
            )
        )
    for pose in poses:  # files that list a pose as rejected without a RejectedPose
        if pose.rejected is not None and pose.index not in listed:
            sensor, _, reason = pose.rejected.partition(": ")
            rows.append((pose.name, rows_text(cal, pose.index), sensor, "", "", reason))
    if not rows:
        return "<p>No pose was rejected.</p>"
    head = "".join(
        f"<th>{h}</th>"
        for h in ("pose", "rows", "sensor", "statistic", "p-value", "reason (and the fix)")
    )
    body = "".join("<tr>" + "".join(f"<td>{esc(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<h3>Rejected poses</h3><table><tr>{head}</tr>{body}</table>"


def rows_text(cal: Calibration, index: int) -> str:
    for pose in cal.poses:
        if int(pose.get("index", -1)) == index and "start" in pose and "stop" in pose:
            return f"{pose['start']}–{pose['stop']}"
    return ""
