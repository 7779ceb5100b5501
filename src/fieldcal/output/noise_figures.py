"""Figures of a noise characterisation: the Allan deviation of each sensor, with its fit.

:func:`noise_figure` draws one log-log panel per sensor: the Allan deviation of each axis (x
red, y green, z blue) with its confidence band, the fitted model (dashed), the −½ and +½ slope
lines of the white noise and of the random walk (dotted), and the marks N (the −½ line at
τ = 1 s, a circle), K (the +½ line at τ = 3 s, a square) and the bias-instability floor
0.664 B (a triangle at the model's minimum). The fitted τ range is shaded.
:func:`write_noise_figure` writes it as a PNG, or as an HTML page with the figure and the
table of fitted values, atomically (:mod:`fieldcal._files`).

matplotlib is an optional extra (``pip install 'fieldcal[plot]'``), imported in
:func:`_figure_class` only when a figure is drawn; figures are drawn on
:class:`matplotlib.figure.Figure` directly, so the pyplot backend is neither needed nor changed.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._files import write_bytes, write_text
from ..errors import InputError
from ..noise import NoiseFit, NoiseReport
from ..stats.allan import FLICKER

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure as MplFigure

__all__ = ["noise_figure", "write_noise_figure"]

_COLOURS = ("tab:red", "tab:green", "tab:blue")
_NAMES = {"accel": "accelerometer", "gyro": "gyroscope", "mag": "magnetometer"}
_DPI = 100


def _figure_class() -> type[MplFigure]:
    """matplotlib's Figure: the one place matplotlib is imported (it is an optional extra)."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise InputError(
            "the noise figure needs matplotlib; pip install 'fieldcal[plot]'"
        ) from None
    return Figure


def _plain(text: str) -> str:
    """Text drawn literally (``$`` would start matplotlib mathematics)."""
    return text.replace("$", r"\$")


def _panel(ax: Axes, fit: NoiseFit) -> None:
    taus = fit.taus
    lo, hi = fit.tau_range
    ax.axvspan(lo, hi, color="0.93", lw=0, zorder=0, label="τ fitted")
    line = np.geomspace(taus.min(), taus.max(), 200)
    model = fit.model.avar(line)
    for j, colour in enumerate(_COLOURS):
        axis = "xyz"[j]
        ax.fill_between(taus, fit.lower[:, j], fit.upper[:, j], color=colour, alpha=0.15, lw=0)
        ax.plot(taus, fit.adev[:, j], color=colour, lw=1.2, marker=".", ms=3, label=axis)
        ax.plot(line, np.sqrt(model[:, j]), color=colour, lw=1.0, ls="--")
        n, b, k = fit.noise_density[j], fit.bias_instability[j], fit.random_walk[j]
        if n > 0:
            ax.plot(line, n / np.sqrt(line), color=colour, lw=0.6, ls=":")
            ax.plot([1.0], [n], marker="o", color=colour, ms=6, mfc="none")
        if k > 0:
            ax.plot(line, k * np.sqrt(line / 3.0), color=colour, lw=0.6, ls=":")
            ax.plot([3.0], [k], marker="s", color=colour, ms=6, mfc="none")
        if b > 0:
            at = line[int(np.argmin(model[:, j]))]
            ax.plot([at], [b * np.sqrt(FLICKER)], marker="^", color=colour, ms=6, mfc="none")
    ax.set_xscale("log")
    ax.set_yscale("log")
    positive = fit.lower[fit.lower > 0]
    if positive.size:
        ax.set_ylim(bottom=0.5 * float(positive.min()), top=2.0 * float(fit.upper.max()))
    ax.set_xlim(0.8 * float(taus.min()), 1.25 * float(taus.max()))
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.set_xlabel("τ (s)")
    ax.set_ylabel(f"Allan deviation ({_plain(fit.unit)})")
    rows = [
        f"{'xyz'[j]}: N {fit.noise_density[j]:.3g}±{fit.noise_density_std[j]:.2g}  "
        f"K {fit.random_walk[j]:.3g}±{fit.random_walk_std[j]:.2g}  "
        f"B {fit.bias_instability[j]:.3g}±{fit.bias_instability_std[j]:.2g}"
        for j in range(3)
    ]
    ax.set_title(
        f"{_NAMES.get(fit.sensor, fit.sensor)}: N (○ at 1 s), K (□ at 3 s), 0.664 B (△)",
        fontsize=9,
    )
    ax.text(
        0.02,
        0.03,
        "\n".join(_plain(r) for r in rows),
        transform=ax.transAxes,
        fontsize=7,
        family="monospace",
        va="bottom",
    )
    ax.legend(loc="upper right", fontsize=7, frameon=False)


def noise_figure(report: NoiseReport, sensors: tuple[str, ...] | None = None) -> MplFigure:
    """The Allan deviation figure of a noise report, one panel per sensor.

    Parameters
    ----------
    report : NoiseReport
        From :func:`fieldcal.noise.characterise_noise`.
    sensors : tuple of str, optional
        The sensors drawn (default every one in the report).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    InputError
        matplotlib is missing, or a sensor asked for is not in the report.
    """
    chosen = tuple(report.fits) if sensors is None else tuple(sensors)
    missing = [s for s in chosen if s not in report.fits]
    if missing or not chosen:
        raise InputError(
            f"no noise fit for {', '.join(missing) or 'any sensor'}; the report has "
            f"{', '.join(report.fits) or 'none'}"
        )
    Figure = _figure_class()
    fig = Figure(figsize=(7.5, 4.2 * len(chosen)))
    axes = fig.subplots(len(chosen), 1, squeeze=False)[:, 0]
    for ax, sensor in zip(axes, chosen, strict=True):
        _panel(ax, report.fits[sensor])
    fig.suptitle(
        _plain(
            f"{report.source}: {report.seconds:.0f} s still in {len(report.stretches)} "
            f"stretch(es) at {report.rate:.4g} Hz"
        ),
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def _png(fig: MplFigure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=_DPI)
    return buffer.getvalue()


def _table(report: NoiseReport) -> str:
    head = (
        "<tr><th>sensor</th><th>axis</th><th>N (unit/√Hz)</th><th>K (unit/s/√Hz)</th>"
        "<th>B (unit)</th><th>τ fitted (s)</th><th>unit</th></tr>"
    )
    rows = []
    for sensor, fit in report.fits.items():
        for j in range(3):
            rows.append(
                "<tr>"
                f"<td>{html.escape(_NAMES.get(sensor, sensor))}</td><td>{'xyz'[j]}</td>"
                f"<td>{fit.noise_density[j]:.4g} ± {fit.noise_density_std[j]:.2g}</td>"
                f"<td>{fit.random_walk[j]:.4g} ± {fit.random_walk_std[j]:.2g}</td>"
                f"<td>{fit.bias_instability[j]:.4g} ± {fit.bias_instability_std[j]:.2g}</td>"
                f"<td>{fit.tau_range[0]:.3g} – {fit.tau_range[1]:.3g}</td>"
                f"<td>{html.escape(fit.unit)}</td></tr>"
            )
    return f"<table>{head}{''.join(rows)}</table>"


def write_noise_figure(report: NoiseReport, output: str | Path) -> None:
    """Write the Allan deviation figure: a PNG, or (``.html``/``.htm``) a page with the figure,
    the table of fitted values, the notes and, when the units allow, the ``imu.yaml`` text.

    The file is written atomically (a temporary file renamed into place).

    Parameters
    ----------
    report : NoiseReport
    output : str or Path
        ``*.png`` or ``*.html``.

    Raises
    ------
    InputError
        Another suffix, or matplotlib is missing.
    """
    path = Path(output)
    suffix = path.suffix.lower()
    if suffix not in (".png", ".html", ".htm"):
        raise InputError(f"{output}: give a .png or .html file for the noise figure")
    data = _png(noise_figure(report))
    if suffix == ".png":
        write_bytes(path, data)
        return
    try:
        yaml = f"<h2>imu.yaml</h2><pre>{html.escape(report.kalibr_yaml())}</pre>"
    except InputError as exc:
        yaml = f"<p>No imu.yaml: {html.escape(str(exc))}</p>"
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in report.notes)
    encoded = base64.b64encode(data).decode("ascii")
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>fieldcal noise</title>"
        "<style>body{font-family:sans-serif;max-width:60em;margin:1em auto}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;"
        "font-size:90%}</style></head><body>"
        f"<h1>fieldcal noise: {html.escape(report.source)}</h1>"
        f"<p>{report.samples} still samples in {len(report.stretches)} stretch(es), "
        f"{report.seconds:.1f} s (the longest {report.longest:.1f} s) at {report.rate:.6g} Hz; "
        "model σ²(τ) = N²/τ + B²·(2 ln 2/π) + K²τ/3 per axis.</p>"
        f"<ul>{notes}</ul>{_table(report)}"
        f'<img alt="Allan deviation" src="data:image/png;base64,{encoded}">{yaml}'
        "</body></html>"
    )
    write_text(path, page)
