"""``fieldcal demo``, ``simulate`` and ``field``: a simulated session calibrated and compared
with its truth, a synthetic log to try the tool on, the Earth's field at a place."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from .. import _files
from ..calibration import Calibration, SensorCalibration
from ..metrics import reconstruction_error
from ..simulation.handwave import simulate_handwave
from ..simulation.session import PRESETS, Preset, Session
from ..simulation.session import simulate as simulate_session
from ..simulation.warmup import simulate_warmup_log
from . import library
from .group import claim, cli, finish, force_option, open_console, progress_line, write_json
from .options import Number, run_calibration

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["demo", "field", "simulate"]


def _deltas(session: Session, cal: Calibration, n_found: int) -> dict[str, float | None]:
    """δ of Eq. 19 per sensor, when the poses found are the simulated ones."""
    truth = session.truth
    if n_found != truth.n_poses or truth.accel is None or truth.mag is None:
        return {"accel": None, "mag": None}
    true_a, true_m = truth.predicted_means()
    est_a, est_m = cal.predicted_means()
    if true_a is None or true_m is None or est_a is None or est_m is None:
        return {"accel": None, "mag": None}
    counts = session.counts
    return {
        "accel": reconstruction_error(true_a, est_a, truth.accel.noise_cov, counts),
        "mag": reconstruction_error(true_m, est_m, truth.mag.noise_cov, counts),
    }


@cli.command()
@click.option(
    "--seed", type=click.IntRange(min=0), default=1, show_default=True, help="Random seed."
)
@click.option("--out", "out_dir", help="Folder for session.csv, cal.json and report.html.")
@click.option("--no-report", is_flag=True, help="Skip the HTML report.")
@click.option(
    "--continuous",
    is_flag=True,
    help="A minute of hand-waving with no rests (accelerometer, magnetometer, gyroscope), "
    "calibrated from the continuous motion.",
)
@force_option
def demo(seed: int, out_dir: str | None, no_report: bool, continuous: bool, force: bool) -> None:
    """Simulate a Table 1 session as a continuous log, find its poses, calibrate, compare
    (--continuous: a hand-waved log with no rests, calibrated from the motion)."""
    with_report = not no_report and importlib.util.find_spec("matplotlib") is not None
    if out_dir:
        names = ["session.csv", "cal.json"] + (["report.html"] if with_report else [])
        claim([Path(out_dir) / name for name in names], {}, force, folders_made=True)
    console = open_console()
    started = time.perf_counter()
    folder = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="fieldcal-demo-"))
    _files.make_folder(folder)
    if continuous:
        _demo_continuous(console, seed, folder, with_report, no_report, started)
        return
    sim = library.simulate_continuous("paper", seed=seed)
    log_path = folder / "session.csv"
    with _files.replacing(log_path) as temp:
        sim.write_csv(str(temp))
    console.print(
        f"simulated a session of the seed paper's Table 1 as a continuous log: "
        f"{sim.session.truth.n_poses} poses, "
        f"{len(sim.columns['t'])} samples at {sim.rate:g} Hz -> {log_path}"
    )
    with progress_line(False) as progress:
        cal, poses, doc, notes = run_calibration(
            library.load_log(log_path), library.LogSettings(), progress
        )
    write_json(folder / "cal.json", doc)
    library.print_summary(console, cal, doc, notes)
    library.print_truth_comparison(
        console, sim.session.truth, cal, _deltas(sim.session, cal, poses.n)
    )
    if not no_report and not with_report:
        console.print(
            "matplotlib is not installed: skipped the report (pip install 'fieldcal[plot]')"
        )
    elif with_report:
        with progress_line(False) as progress:
            if progress is not None:
                progress("drawing the report")
            library.write_report(
                cal, library.load_log(log_path), folder / "report.html", on_progress=progress
            )
        console.print(f"report: {folder / 'report.html'}")
    console.print(f"done in {time.perf_counter() - started:.1f} s; files in {folder}")
    finish(cal, summary_shown=True)


def _demo_continuous(
    console: Console, seed: int, folder: Path, with_report: bool, no_report: bool, started: float
) -> None:
    """``demo --continuous``: a hand-waved minute, calibrated from the motion, compared."""
    sim = simulate_handwave(seed=seed)
    log_path = folder / "session.csv"
    with _files.replacing(log_path) as temp:
        sim.write_csv(str(temp))
    console.print(
        f"simulated a minute of hand-waving with no rests: {sim.n} samples at {sim.rate:g} Hz "
        f"(accelerometer, magnetometer, gyroscope) -> {log_path}"
    )
    with progress_line(False) as progress:
        cal, _, doc, notes = run_calibration(
            library.load_log(log_path), library.LogSettings.of(poses="continuous"), progress
        )
    write_json(folder / "cal.json", doc)
    library.print_summary(console, cal, doc, notes)
    library.print_truth_comparison(console, sim.truth, cal, {})
    if cal.gyro is not None and sim.truth.gyro is not None:
        true_gain = np.asarray(sim.truth.gyro.gain)
        rel = np.linalg.norm(cal.gyro.gain - true_gain) / np.linalg.norm(true_gain)
        console.print(
            f"gyroscope: gain error {100 * rel:.2f} % (Frobenius, relative), bias error "
            f"{np.max(np.abs(cal.gyro.bias - sim.truth.gyro.bias)):.2g} rad/s (largest axis)"
        )
    if with_report:
        with progress_line(False) as progress:
            if progress is not None:
                progress("drawing the report")
            library.write_report(
                cal, library.load_log(log_path), folder / "report.html", on_progress=progress
            )
        console.print(f"report: {folder / 'report.html'}")
    elif not no_report:
        console.print(
            "matplotlib is not installed: skipped the report (pip install 'fieldcal[plot]')"
        )
    console.print(f"done in {time.perf_counter() - started:.1f} s; files in {folder}")
    finish(cal, summary_shown=True)


# ----------------------------------------------------------------------------- simulate
@cli.command()
@click.option(
    "--preset",
    type=click.Choice(list(PRESETS)),
    default="paper",
    show_default=True,
    help="Simulation preset.",
)
@click.option(
    "--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed."
)
@click.option("-o", "--output", default="session.csv", show_default=True, help="Session CSV.")
@click.option("--truth", help="Also write the true calibration as JSON.")
@click.option("--continuous", is_flag=True, help="Time-stamped log with motion between poses.")
@click.option("--poses", type=click.IntRange(1, 1000), help="Number of poses (preset default: 15).")
@click.option(
    "--handheld", is_flag=True, help="Hand-held poses (mostly < 60° tilt) instead of uniform."
)
@click.option(
    "--rate",
    type=Number(10.0, 10_000.0, low_open=False),
    default=100.0,
    show_default=True,
    help="Hz (--continuous).",
)
@click.option(
    "--handwave",
    is_flag=True,
    help="A log waved by hand with no rests (t, ax.., gx.., mx.., rad/s), --seconds long: "
    "calibrated from the motion (calibrate --poses auto or continuous).",
)
@click.option(
    "--warmup",
    is_flag=True,
    help="A warm-up log: still poses joined by motion while the board warms, each bias "
    "drifting with the temperature column `temp` (deg C).",
)
@click.option(
    "--seconds",
    type=Number(5.0, 3600.0, low_open=False),
    default=60.0,
    show_default=True,
    help="--handwave: the log's length in seconds.",
)
@force_option
def simulate(
    preset: str,
    seed: int,
    output: str,
    truth: str | None,
    continuous: bool,
    poses: int | None,
    handheld: bool,
    rate: float,
    handwave: bool,
    warmup: bool,
    seconds: float,
    force: bool,
) -> None:
    """Write a synthetic session to try the tool on: a `pose` column, or a time-stamped log
    (--continuous: motion between still poses; --handwave: waved by hand, no rests;
    --warmup: biases drifting as the board warms)."""
    claim([output, truth], {}, force)
    if sum((continuous, handwave, warmup)) > 1:
        raise click.UsageError("give one of --continuous, --handwave and --warmup")
    if handwave or warmup:
        _simulate_log(seed, output, truth, handwave, seconds, poses, rate)
        return
    extra: Preset = {"n_poses": poses} if poses else {}
    if handheld:
        extra["pose_distribution"] = "handheld"
    if continuous:
        log = library.simulate_continuous(preset, seed=seed, rate=rate, **extra)
        with _files.replacing(output) as temp:
            log.write_csv(str(temp))
        session: Session = log.session
        true_cal = session.truth
        gyro = log.gyro_truth
        if gyro is not None:  # in fieldcal's body frame, as an estimate from the log is
            sensor = SensorCalibration(
                gain=gyro.gain, bias=gyro.bias, noise_cov=gyro.noise_std**2 * np.eye(3)
            )
            true_cal = dataclasses.replace(true_cal, gyro=sensor)
    else:
        session = simulate_session(preset, seed=seed, **extra)
        true_cal = session.truth
        with _files.replacing(output) as temp:
            session.write_csv(temp)
    if truth:
        _files.write_text(truth, true_cal.to_json() + "\n")
    click.echo(f"wrote {output}" + (f" and {truth}" if truth else ""))


def _simulate_log(
    seed: int,
    output: str,
    truth: str | None,
    handwave: bool,
    seconds: float,
    poses: int | None,
    rate: float,
) -> None:
    """``simulate --handwave`` and ``--warmup``: the log, and its truth when asked."""
    if handwave:
        waved = simulate_handwave(seed=seed, seconds=seconds, rate=rate)
        write, true_cal = waved.write_csv, waved.truth
        what = f"{seconds:g} s of hand-waving with no rests at {rate:g} Hz"
    else:
        warm = simulate_warmup_log(seed=seed, n_poses=poses or 18, rate=rate)
        write, true_cal = warm.write_csv, warm.log.session.truth
        t = warm.columns["temp"]
        what = (
            f"a warm-up log: {poses or 18} still poses joined by motion at {rate:g} Hz, "
            f"{t.min():.1f} to {t.max():.1f} °C (column temp), biases drifting with it"
        )
    with _files.replacing(output) as temp:
        write(str(temp))
    if truth:
        _files.write_text(truth, true_cal.to_json() + "\n")
    click.echo(f"wrote {output}: {what}" + (f"; the truth in {truth}" if truth else ""))


# ----------------------------------------------------------------------------- field
@cli.command()
@click.option(
    "--location",
    required=True,
    metavar="LAT,LON[,ALT_M]",
    help="Decimal degrees (north and east positive) and metres above the WGS 84 ellipsoid.",
)
@click.option("--date", metavar="YYYY-MM-DD", help="The date (default: today).")
@click.option("--json", "as_json", is_flag=True, help="Print the values as JSON.")
def field(location: str, date: str | None, as_json: bool) -> None:
    """The Earth's magnetic field expected at --location (World Magnetic Model): dip,
    intensity and declination with their uncertainties, as calibrate --location uses them."""
    ref = library.expected_field(location, date)
    if as_json:
        click.echo(json.dumps(dataclasses.asdict(ref), indent=2))
        return
    east = "east" if ref.declination_deg >= 0 else "west"
    click.echo(
        f"{ref.model} at {ref.place}, {ref.altitude_m:g} m, on {ref.date}:\n"
        f"  dip (inclination)  {ref.dip_deg:+.2f}° ± {ref.dip_std_deg:.2f}° "
        "(positive below the horizon)\n"
        f"  total intensity    {ref.intensity / 1000:.3f} µT ± {ref.intensity_std / 1000:.3f} "
        f"({ref.intensity:.0f} nT)\n"
        f"  declination        {abs(ref.declination_deg):.2f}° {east} ± "
        f"{ref.declination_std_deg:.2f}° (true heading = magnetic heading "
        f"{'+' if ref.declination_deg >= 0 else '-'} {abs(ref.declination_deg):.2f}°)"
    )
