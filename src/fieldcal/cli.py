"""The ``fieldcal`` command: calibrate a log, apply and export the result, simulate, report, demo.

Every mistake in the user's input (file, columns, options, too few or degenerate poses) ends in
a one-line ``Error: ...`` on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console

from . import __version__
from .errors import InputError

__all__ = ["cli", "main"]

_USER_ERRORS = (InputError, ValueError, OSError, np.linalg.LinAlgError)


class _Group(click.Group):
    """A click group whose commands report user errors in one line with exit code 2."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except _USER_ERRORS as exc:
            message = " ".join(str(exc).split()) or type(exc).__name__
            if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in message:
                message = f"{exc.filename}: {message}"
            click.echo(f"Error: {message}", err=True)
            ctx.exit(2)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="fieldcal")
def cli() -> None:
    """Calibrate an accelerometer and a magnetometer together from a log of still poses.

    Start with `fieldcal demo`, then `fieldcal calibrate LOG -o cal.json`.
    """


def main() -> None:
    """Console-script entry point."""
    cli(prog_name="fieldcal")


# ----------------------------------------------------------------------------- helpers
def _console(quiet: bool = False) -> Console:
    return Console(quiet=quiet, highlight=False, soft_wrap=True)


def _read_cal(path: str) -> Any:
    from .calibration import Calibration

    file = Path(path)
    if not file.is_file():
        raise InputError(f"{path}: no such calibration file; write one with `fieldcal calibrate`")
    return Calibration.from_json(file.read_text(encoding="utf-8"))


def _log_options(f: Any) -> Any:
    options = [
        click.option("--accel-cols", help="Accelerometer columns x,y,z (default: recognised)."),
        click.option("--mag-cols", help="Magnetometer columns x,y,z (default: recognised)."),
        click.option("--gyro-cols", help="Gyroscope columns x,y,z (helps still detection)."),
        click.option("--time-col", help="Time column (s; ms/us/ns recognised)."),
        click.option("--pose-col", help="Pose-label column: rows are grouped by it."),
        click.option("--drop-nan", is_flag=True, help="Drop rows with NaN/inf instead of failing."),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _detect_options(f: Any) -> Any:
    options = [
        click.option("--rate", type=float, help="Sample rate in Hz when there is no time column."),
        click.option(
            "--min-still",
            type=float,
            help="Shortest still interval: seconds (samples without time/rate). Default 1 s / 50.",
        ),
        click.option(
            "--window",
            type=float,
            help="Moving-variance window: seconds (samples without time/rate). Default 0.5 s / 25.",
        ),
        click.option("--trim", type=float, help="Cut at each end of an interval (s or samples)."),
        click.option(
            "--still-threshold",
            type=float,
            help="Accelerometer threshold, per-axis std in raw units (default: 3x noise floor).",
        ),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _load(
    log: str,
    accel_cols: Any,
    mag_cols: Any,
    gyro_cols: Any,
    time_col: Any,
    pose_col: Any,
    drop_nan: bool,
) -> Any:
    from .logs.io import load_log

    return load_log(
        log,
        accel_cols=accel_cols,
        mag_cols=mag_cols,
        gyro_cols=gyro_cols,
        time_col=time_col,
        pose_col=pose_col,
        drop_nan=drop_nan,
    )


def _run_calibration(log: Any, opts: dict[str, Any]) -> tuple[Any, Any, dict[str, Any], list[str]]:
    """Poses, calibration and the JSON document for a loaded log."""
    from .logs.io import parse_axes
    from .pipeline import calibrate_log, document, parse_noise, poses_from_log

    notes = [
        "columns used: "
        + "; ".join(f"{role} = {','.join(cols)}" for role, cols in log.used.items())
    ]
    notes += log.notes
    if log.dropped:
        notes.append(f"dropped {log.dropped} row(s) with NaN or inf values")
    P = None
    if opts.get("mag_axes"):
        if log.mag is None:
            raise InputError("--mag-axes given but the log has no magnetometer columns")
        P = parse_axes(opts["mag_axes"])
        log.mag = log.mag @ P.T
        notes.append(
            f"magnetometer axes mapped {opts['mag_axes']} for the fit and folded back into its "
            "gain: apply the result to the raw columns as logged"
        )
    poses = poses_from_log(
        log,
        rate=opts.get("rate"),
        window=opts.get("window"),
        min_still=opts.get("min_still"),
        trim=opts.get("trim"),
        threshold=opts.get("still_threshold"),
    )
    how = (
        f"grouped by the pose column {log.used['pose'][0]!r}"
        if poses.detection is None
        else "found by still detection" + (f" at {poses.rate:g} Hz" if poses.rate else "")
    )
    distinct = len({e["orientation"] for e in poses.entries})
    notes.append(f"{poses.n} poses {how} ({distinct} distinct orientations)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cal = calibrate_log(
            log,
            poses,
            method=opts.get("method", "mle"),
            gravity=opts.get("gravity"),
            field_strength=opts.get("field_strength"),
            noise=parse_noise(opts.get("noise")),
            mag_axes=opts.get("mag_axes"),
            P=P,
            mag_mirrored=bool(opts.get("mag_mirrored")),
        )
    # the library's warnings (an implausible fit, ...) belong in the summary, not as tracebacks
    notes += [f"warning: {' '.join(str(w.message).split())}" for w in caught]
    return cal, poses, document(cal, poses), notes


# ----------------------------------------------------------------------------- calibrate
@cli.command()
@click.argument("log", type=click.Path())
@click.option("-o", "--output", default="cal.json", show_default=True, help="Calibration JSON.")
@click.option(
    "--method",
    type=click.Choice(["mle", "greedy", "ellipsoid"]),
    default="mle",
    show_default=True,
    help="Calibration method.",
)
@click.option("--gravity", type=float, help="|g| for calibrated accel units (e.g. 9.80665).")
@click.option("--field-strength", type=float, help="|h| for calibrated mag units (e.g. 48.5).")
@click.option(
    "--noise",
    help="Noise std of one raw sample: one value, or accel=0.01,mag=0.2 (default: estimated).",
)
@click.option("--mag-axes", help="Magnetometer axis map onto the accelerometer's, e.g. +y+x-z.")
@click.option(
    "--mag-mirrored",
    is_flag=True,
    help="The magnetometer's axes (after --mag-axes) are left-handed relative to the "
    "accelerometer's; static data cannot tell this from the dip's sign.",
)
@_log_options
@_detect_options
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON instead.")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
def calibrate(log: str, output: str, as_json: bool, quiet: bool, **opts: Any) -> None:
    """Calibrate from LOG (CSV with header, .npz or .parquet) and write the calibration JSON."""
    data = _load(
        log,
        opts.pop("accel_cols"),
        opts.pop("mag_cols"),
        opts.pop("gyro_cols"),
        opts.pop("time_col"),
        opts.pop("pose_col"),
        opts.pop("drop_nan"),
    )
    cal, _, doc, notes = _run_calibration(data, opts)
    Path(output).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    if as_json:
        click.echo(json.dumps(doc, indent=2, allow_nan=False))
    elif not quiet:
        from .output.summary import print_summary

        console = _console()
        print_summary(console, cal, doc, notes)
        console.print(f"wrote {output}")


# ----------------------------------------------------------------------------- apply
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.argument("log", type=click.Path())
@click.option("-o", "--output", required=True, help="Output CSV with calibrated columns.")
@click.option("--accel-cols", help="Accelerometer columns x,y,z (default: recognised).")
@click.option("--mag-cols", help="Magnetometer columns x,y,z (default: recognised).")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
def apply(
    cal_json: str, log: str, output: str, accel_cols: Any, mag_cols: Any, quiet: bool
) -> None:
    """Append calibrated columns (<col>_cal) to LOG; large CSV files are streamed."""
    from .logs.io import apply_to_file

    cal = _read_cal(cal_json)
    used = apply_to_file(cal, log, output, accel_cols=accel_cols, mag_cols=mag_cols)
    if not quiet:
        cols = "; ".join(f"{s}: {','.join(c)}" for s, c in used.items())
        _console().print(f"calibrated {cols} -> {output}")


# ----------------------------------------------------------------------------- export
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["c-header", "matlab", "magneto", "json"]),
    default="c-header",
    show_default=True,
    help="Target convention.",
)
@click.option("-o", "--output", help="Write to this file instead of stdout.")
def export(cal_json: str, fmt: str, output: str | None) -> None:
    """Write the calibration for firmware or another tool, its convention stated in the text."""
    from .output.exports import export as render

    text = render(_read_cal(cal_json), fmt)
    if output:
        Path(output).write_text(text if text.endswith("\n") else text + "\n", encoding="utf-8")
    else:
        click.echo(text.rstrip("\n"))


# ----------------------------------------------------------------------------- simulate
@cli.command()
@click.option("--preset", default="paper", show_default=True, help="Simulation preset.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("-o", "--output", default="session.csv", show_default=True, help="Session CSV.")
@click.option("--truth", help="Also write the true calibration as JSON.")
@click.option("--continuous", is_flag=True, help="Time-stamped log with motion between poses.")
@click.option("--poses", type=int, help="Number of poses (preset default: 15).")
@click.option(
    "--handheld", is_flag=True, help="Hand-held poses (mostly < 60° tilt) instead of uniform."
)
@click.option("--rate", type=float, default=100.0, show_default=True, help="Hz (--continuous).")
def simulate(
    preset: str,
    seed: int,
    output: str,
    truth: str | None,
    continuous: bool,
    poses: int | None,
    handheld: bool,
    rate: float,
) -> None:
    """Write a synthetic session to try the tool on (a `pose` column, or --continuous)."""
    from .simulation.continuous import simulate_continuous
    from .simulation.session import simulate as draw

    extra: dict[str, Any] = {"n_poses": poses} if poses else {}
    if handheld:
        extra["pose_distribution"] = "handheld"
    if continuous:
        log = simulate_continuous(preset, seed=seed, rate=rate, **extra)
        log.write_csv(output)
        session = log.session
    else:
        session = draw(preset, seed=seed, **extra)
        counts = session.counts
        data = np.column_stack(
            [
                np.repeat(np.arange(len(counts)), counts),
                np.concatenate(session.accel),
                np.concatenate(session.mag),
            ]
        )
        np.savetxt(
            output,
            data,
            delimiter=",",
            header="pose,ax,ay,az,mx,my,mz",
            comments="",
            fmt=["%d"] + ["%.9g"] * 6,
        )
    if truth:
        Path(truth).write_text(session.truth.to_json() + "\n", encoding="utf-8")
    click.echo(f"wrote {output}" + (f" and {truth}" if truth else ""))


# ----------------------------------------------------------------------------- report
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.argument("log", type=click.Path())
@click.option("-o", "--output", default="report.html", show_default=True, help="HTML report.")
@click.option("--png", "png_dir", help="Also write each figure as PNG into this folder.")
@_log_options
def report(cal_json: str, log: str, output: str, png_dir: str | None, **cols: Any) -> None:
    """Pictures of the calibration: spheres, pose coverage, residuals, norm and dip histograms."""
    from .output.report import write_report

    cal = _read_cal(cal_json)
    data = _load(
        log,
        cols["accel_cols"],
        cols["mag_cols"],
        cols["gyro_cols"],
        cols["time_col"],
        cols["pose_col"],
        cols["drop_nan"],
    )
    write_report(cal, data, output, png_dir=png_dir)
    click.echo(f"wrote {output}" + (f" and PNGs in {png_dir}" if png_dir else ""))


# ----------------------------------------------------------------------------- demo
def _deltas(session: Any, cal: Any, n_found: int) -> dict[str, float | None]:
    """δ of Eq. 19 per sensor, when the poses found are the simulated ones."""
    from .metrics import reconstruction_error

    truth = session.truth
    if n_found != truth.n_poses:
        return {"accel": None, "mag": None}
    true_a, true_m = truth.predicted_means()
    est_a, est_m = cal.predicted_means()
    counts = session.counts
    return {
        "accel": reconstruction_error(true_a, est_a, truth.accel.noise_cov, counts),
        "mag": reconstruction_error(true_m, est_m, truth.mag.noise_cov, counts),
    }


@cli.command()
@click.option("--seed", type=int, default=1, show_default=True, help="Random seed.")
@click.option("--out", "out_dir", help="Folder for session.csv, cal.json and report.html.")
@click.option("--no-report", is_flag=True, help="Skip the HTML report.")
def demo(seed: int, out_dir: str | None, no_report: bool) -> None:
    """Simulate a Table 1 session as a continuous log, find its poses, calibrate, compare."""
    from .simulation.continuous import simulate_continuous
    from .logs.io import load_log
    from .output.summary import print_summary, print_truth_comparison

    console = _console()
    started = time.perf_counter()
    folder = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="fieldcal-demo-"))
    folder.mkdir(parents=True, exist_ok=True)
    sim = simulate_continuous("paper", seed=seed)
    log_path = folder / "session.csv"
    sim.write_csv(str(log_path))
    console.print(
        f"simulated a session of the seed paper's Table 1 as a continuous log: "
        f"{sim.session.truth.n_poses} poses, "
        f"{len(sim.columns['t'])} samples at {sim.rate:g} Hz -> {log_path}"
    )
    log = load_log(log_path)
    cal, poses, doc, notes = _run_calibration(log, {"method": "mle"})
    (folder / "cal.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    print_summary(console, cal, doc, notes)
    print_truth_comparison(console, sim.session.truth, cal, _deltas(sim.session, cal, poses.n))
    if not no_report:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            console.print(
                "matplotlib is not installed: skipped the report (pip install 'fieldcal[plot]')"
            )
        else:
            from .output.report import write_report

            write_report(cal, load_log(log_path), folder / "report.html")
            console.print(f"report: {folder / 'report.html'}")
    console.print(f"done in {time.perf_counter() - started:.1f} s; files in {folder}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
