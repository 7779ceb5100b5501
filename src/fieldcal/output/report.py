"""An HTML report (one self-contained file, figures as base64 PNGs) and optional PNG files.

matplotlib is an optional extra (``pip install 'fieldcal[plot]'``); it is imported only here,
inside :func:`write_report`, so the rest of fieldcal works without it.
"""

from __future__ import annotations

import base64
import html
import io as _io
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..calibration import Calibration

__all__ = ["write_report"]

Array = NDArray[np.float64]
_MAX_POINTS = 2500  # enough to see the shape of a sphere, small enough for a light HTML file


def _pose_rows(cal: Calibration, log: Any) -> list[NDArray[np.int64]]:
    """Row positions (in the loaded log) of each pose, from the calibration's start/stop."""
    rows = []
    last = int(log.index[-1]) + 1 if log.n else 0
    for pose in cal.poses:
        if "start" not in pose or "stop" not in pose:
            continue
        if pose["stop"] > last:
            raise InputError(
                f"{log.path}: the calibration's pose {pose.get('index', len(rows))} ends at row "
                f"{pose['stop']} but the log has {last} rows; give the log it was made from"
            )
        pieces = pose.get("pieces") or [[pose["start"], pose["stop"]]]
        lo, hi = np.searchsorted(log.index, np.asarray(pieces, dtype=np.int64).T)
        pose_rows = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi, strict=True)])
        if pose_rows.size:
            rows.append(pose_rows)
    return rows


def _thin(x: Array, rng: np.random.Generator) -> Array:
    return x if len(x) <= _MAX_POINTS else x[rng.choice(len(x), _MAX_POINTS, replace=False)]


def _sphere_figure(plt: Any, name: str, raw: Array, calibrated: Array, radius: float) -> Any:
    fig, axes = plt.subplots(2, 3, figsize=(11, 7))
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


def _coverage_figure(plt: Any, directions: dict[str, Array]) -> Any:
    fig = plt.figure(figsize=(10, 4.5))
    for k, (name, d) in enumerate(directions.items()):
        ax = fig.add_subplot(1, len(directions), k + 1, projection="mollweide")
        lon = np.arctan2(d[:, 1], d[:, 0])
        lat = np.arcsin(np.clip(d[:, 2], -1, 1))
        ax.scatter(lon, lat, s=30, color="tab:green")
        for i, (x, y) in enumerate(zip(lon, lat, strict=True)):
            ax.annotate(str(i), (x, y), fontsize=7)
        ax.grid(True)
        ax.set_title(f"{name} field direction per pose (sensor frame)", pad=20)
    fig.subplots_adjust(left=0.04, right=0.98, wspace=0.15)
    return fig


def _residual_figure(plt: Any, cal: Calibration) -> Any:
    share = np.array([p.get("share", np.nan) for p in cal.poses], dtype=float)
    fig, ax = plt.subplots(figsize=(10, 3.5))
    n = len(share)
    ax.bar(np.arange(n), 100 * share, color="tab:purple")
    if n:
        ax.axhline(100 / n, color="k", ls="--", lw=1, label="equal share")
        ax.axhline(300 / n, color="tab:red", ls=":", lw=1, label="flag (3x equal)")
        ax.legend()
    ax.set_xlabel("pose")
    ax.set_ylabel("share of the fit cost (%)")
    ax.set_title("per-pose residuals")
    fig.subplots_adjust(bottom=0.15)
    return fig


def _histogram_figure(
    plt: Any, norms: dict[str, Array], dip: Array | None, cal: Calibration
) -> Any:
    panels = len(norms) + (dip is not None)
    fig, axes = plt.subplots(1, panels, figsize=(4 * panels, 3.5))
    axes = np.atleast_1d(axes)
    for ax, (name, values) in zip(axes, norms.items(), strict=False):
        ax.hist(values, bins=60, color="tab:blue")
        ax.set_title(f"|{name}| calibrated, still samples")
    if dip is not None:
        ax = axes[-1]
        ax.hist(dip, bins=60, color="tab:orange")
        if cal.dip_deg is not None:
            ax.axvline(cal.dip_deg, color="k", ls="--", lw=1, label=f"fit {cal.dip_deg:.2f}°")
            ax.legend()
        ax.set_title("dip per still sample (°)")
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.12, wspace=0.25)
    return fig


def _summary_html(cal: Calibration) -> str:
    rows = []
    for name in ("accel", "mag"):
        sensor = getattr(cal, name)
        if sensor is None:
            continue
        gain = "<br>".join(" ".join(f"{v:.6g}" for v in row) for row in sensor.gain)
        bias = " ".join(f"{v:.6g}" for v in sensor.bias)
        rows.append(f"<tr><th>{name} gain</th><td><code>{gain}</code></td></tr>")
        rows.append(f"<tr><th>{name} bias</th><td><code>{bias}</code></td></tr>")
        rows.append(
            f"<tr><th>{name} noise source</th><td>{html.escape(sensor.noise_source)}</td></tr>"
        )
    if cal.dip_deg is not None:
        rows.append(f"<tr><th>dip</th><td>{cal.dip_deg:.3f}°</td></tr>")
    if cal.misalignment_deg is not None:
        rows.append(f"<tr><th>misalignment</th><td>{cal.misalignment_deg:.3f}°</td></tr>")
    if cal.diagnostics is not None:
        d = cal.diagnostics
        rows.append(
            f"<tr><th>certificate</th><td>J = {d.statistic:.4g}, dof = {d.dof}, "
            f"p = {d.p_value:.3g}</td></tr>"
        )
    return "<table>" + "".join(rows) + "</table>"


def write_report(
    cal: Calibration, log: Any, output: str | Path, *, png_dir: str | Path | None = None
) -> None:
    """Write the HTML report of ``cal`` on ``log`` (a :class:`fieldcal.io.Log`)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise InputError("the report needs matplotlib; pip install 'fieldcal[plot]'") from None
    rng = np.random.default_rng(0)
    rows = _pose_rows(cal, log)
    still = np.concatenate(rows) if rows else np.arange(log.n)
    figures: dict[str, Any] = {}
    norms: dict[str, Array] = {}
    directions: dict[str, Array] = {}
    corrected: dict[str, Array] = {}
    for name, label in (("accel", "accelerometer"), ("mag", "magnetometer")):
        raw = getattr(log, name)
        if raw is None or getattr(cal, name) is None:
            continue
        fix = cal.correct_accel if name == "accel" else cal.correct_mag
        if raw.shape[0] == 0:
            continue
        calibrated = fix(raw)
        corrected[name] = calibrated
        radius = cal.gravity_norm if name == "accel" else cal.field_strength
        sample = _thin(np.arange(log.n), rng)
        figures[f"{name}_sphere"] = _sphere_figure(
            plt, label, raw[sample], calibrated[sample], radius or 1.0
        )
        norms[name] = np.linalg.norm(calibrated[still], axis=1)
        if rows:
            means = np.array([calibrated[r].mean(axis=0) for r in rows])
            directions[label] = means / np.linalg.norm(means, axis=1, keepdims=True)
    if not corrected:
        raise InputError(
            f"{log.path}: none of the calibrated sensors' columns are in this log; pass "
            "--accel-cols/--mag-cols"
        )
    if directions:
        figures["coverage"] = _coverage_figure(plt, directions)
    if cal.poses and "share" in cal.poses[0]:
        figures["residuals"] = _residual_figure(plt, cal)
    dip = None
    if "accel" in corrected and "mag" in corrected:
        a = corrected["accel"][still]
        m = corrected["mag"][still]
        cos = np.einsum("ni,ni->n", a, m) / (np.linalg.norm(a, axis=1) * np.linalg.norm(m, axis=1))
        dip = np.degrees(np.arcsin(np.clip(-cos, -1, 1)))
    figures["histograms"] = _histogram_figure(plt, norms, dip, cal)

    images = []
    if png_dir is not None:
        Path(png_dir).mkdir(parents=True, exist_ok=True)
    for key, fig in figures.items():
        buffer = _io.BytesIO()
        fig.savefig(buffer, format="png", dpi=90)
        if png_dir is not None:
            (Path(png_dir) / f"{key}.png").write_bytes(buffer.getvalue())
        plt.close(fig)
        encoded = base64.b64encode(buffer.getvalue()).decode("ascii")
        images.append(
            f'<h2>{html.escape(key)}</h2><img alt="{key}" src="data:image/png;base64,{encoded}">'
        )
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>fieldcal report</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "th{text-align:left;padding-right:1em}img{max-width:100%}</style></head><body>"
        f"<h1>fieldcal report: {html.escape(str(log.path))}</h1>"
        f"<p>method {html.escape(cal.method)}, {len(cal.poses)} poses, created "
        f"{html.escape(cal.created)}</p>{_summary_html(cal)}{''.join(images)}</body></html>"
    )
    Path(output).write_text(page, encoding="utf-8")
