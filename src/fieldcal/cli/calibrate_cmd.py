"""``fieldcal calibrate``, ``apply``, ``export`` and ``report``: a log to a calibration file,
and a calibration file to a calibrated log, a firmware export or the pictures."""

from __future__ import annotations

import inspect
import json
import sys
from pathlib import Path
from typing import Any

import click

from .. import _files
from ..errors import InputError
from ..logs.sniff import is_calibration_json
from ..output import exports
from ..settings import OPTIONS
from . import library
from .group import (
    check_matplotlib,
    claim,
    cli,
    finish,
    force_option,
    open_console,
    progress_line,
    read_cal,
    write_json,
)
from .options import (
    POSES_OPTION,
    Given,
    check_reference,
    detect_options,
    fit_options,
    keywords,
    load,
    log_options,
    reader_options,
    run_calibration,
    settings,
)

__all__ = ["apply", "calibrate", "export", "report"]

#: The calibration file ``calibrate`` writes when neither ``-o`` nor ``--json`` is given.
DEFAULT_OUTPUT = "cal.json"


# ----------------------------------------------------------------------------- calibrate
@cli.command()
@click.argument("log", type=click.Path())
@click.option(
    "-o",
    "--output",
    help=f"Calibration JSON to write. [default: {DEFAULT_OUTPUT}; with --json, only when given]",
)
@fit_options
@POSES_OPTION
@log_options
@detect_options
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print the result as JSON instead of the summary (writes a file only with -o).",
)
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and a fail verdict.")
@force_option
def calibrate(
    log: str,
    output: str | None,
    as_json: bool,
    quiet: bool,
    force: bool,
    **opts: object,
) -> None:
    """Calibrate from LOG (CSV with header, .npz or .parquet) and write the calibration JSON.

    The verdict (PASS, WARN or FAIL, with reasons) comes first. Exit code 3 when it is FAIL;
    the JSON is written all the same.
    """
    if output is None and not as_json:
        output = DEFAULT_OUTPUT
    claim([output], {"log": log}, force)
    # the options given as text are parsed before the slow part, into the settings objects
    chosen = settings(opts, ["detect", "fit", "trust"])
    check_reference(opts)
    with progress_line(quiet) as progress:
        if progress is not None:
            progress(f"reading {log}")
        data = load(log, opts, progress)
        cal, _, doc, notes = run_calibration(data, chosen, progress)
    if output is not None:
        write_json(output, doc)
    if as_json:
        click.echo(json.dumps(doc, indent=2, allow_nan=False))
    elif not quiet:
        console = open_console()
        library.print_summary(console, cal, doc, notes)
        console.print(f"wrote {output}")
    finish(cal, summary_shown=not (as_json or quiet))


def check_order(cal_json: str, log: str, command: str) -> None:
    """Refuse ``CAL_JSON LOG`` given the other way round, naming the order (``apply`` and
    ``report`` take the calibration first)."""
    if is_calibration_json(log) and not is_calibration_json(cal_json):
        raise InputError(
            f"the arguments are swapped: {log} is the calibration JSON and {cal_json} the log; "
            f"give the calibration first: fieldcal {command} {log} {cal_json} ..."
        )


# ----------------------------------------------------------------------------- apply
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.argument("log", type=click.Path())
@click.option(
    "-o",
    "--output",
    required=True,
    help="The log with calibrated columns, in the format of its suffix (.csv, .parquet, .npz).",
)
@reader_options(
    gyro_cols="Gyroscope columns x,y,z (default: recognised); written in rad/s.",
    temp_col="Temperature column (deg C) for a calibration with temperature terms (default: the "
    "one the calibration was fitted with, else recognised).",
)
@click.option(
    "--temperature",
    type=float,
    help="One temperature (deg C) for every row, for a log without a temperature column.",
)
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
@force_option
def apply(
    cal_json: str,
    log: str,
    output: str,
    temperature: float | None,
    quiet: bool,
    force: bool,
    **opts: Any,
) -> None:
    """Append calibrated columns (<col>_cal) to LOG, keeping everything else as it was.

    Each sensor the calibration holds and the log has: accelerometer, magnetometer and
    gyroscope (gx_cal.. in rad/s). The output's suffix names its format; CSV to CSV is
    streamed in chunks, every input line kept byte for byte. A ROS bag gives its table (t,
    ax.., gx.., mx..) with the calibrated columns. A calibration with temperature terms uses
    each row's temperature (the column it was fitted with, --temp-col, or --temperature); one
    with an interference term each row's battery current or throttle (recognised, or
    --current-col/--throttle-col). It takes calibrate's reader options; those it does not need
    (a time or pose column) are noted.
    """
    claim([output], {"calibration": cal_json, "log": log}, force)
    check_order(cal_json, log, "apply")
    reading = applied_reading(opts, quiet)
    library.check_pyarrow(log, output)
    cal = read_cal(cal_json)
    with progress_line(quiet) as progress:
        if progress is not None:
            progress(f"applying the calibration to {log}")
        used = library.apply_to_file(
            cal, log, output, on_progress=progress, temperature=temperature, **reading
        )
    if not quiet:
        cols = "; ".join(f"{s}: {','.join(c)}" for s, c in used.items())
        open_console().print(f"calibrated {cols} -> {output}")


def applied_reading(opts: Given, quiet: bool) -> dict[str, Any]:
    """The reader's options ``apply`` was given that it uses (those of
    :func:`fieldcal.logs.apply.apply_to_file`), by library keyword; those it does not need (a
    time or pose column: every row and column is kept as it is) are noted on stderr, never
    dropped silently."""
    reading = keywords(opts, ["read"])
    takes = inspect.signature(library.apply_to_file).parameters
    unused = [OPTIONS[name].flag for name in reading if name not in takes]
    if unused and not quiet:
        click.echo(f"note: not used by apply: {', '.join(unused)}", err=True)
    return {name: value for name, value in reading.items() if name in takes}


# ----------------------------------------------------------------------------- export
#: What to do with each export once written (``export`` says it after naming the file).
NEXT_STEP = {
    "c-header": "#include it in the firmware and correct each reading with "
    "fieldcal_apply(M, B, raw, out) (docs/microcontroller.md)",
    "c-library": "add fieldcal_cal.c and fieldcal_cal.h to the firmware's build and call "
    "fieldcal_accel/fieldcal_mag/fieldcal_gyro(&FIELDCAL_FACTORY, raw, out) per reading "
    "(docs/microcontroller.md)",
    "matlab": "run it in MATLAB or Octave: it defines the gains, biases and an apply function",
    "magneto": "paste the numbers where Magneto's output goes (its A⁻¹ and b)",
    "json": "read it with fieldcal.Calibration.from_json, or any JSON reader (docs/json-schema.md)",
    "ardupilot": "load it in Mission Planner (Config > Full Parameter List > Load from file) "
    "or MAVProxy (param load FILE), then reboot (docs/ardupilot.md)",
    "px4": "set CAL_*_ID in it to your sensors' device ids, load it in QGroundControl "
    "(Vehicle Setup > Parameters > Tools > Load from file), then reboot (docs/px4.md)",
    "mat": "load it with scipy.io.loadmat or MATLAB's load",
    "kalibr": "give it to Kalibr as the IMU's yaml (--imu), with the readings corrected by "
    "fieldcal apply",
    "openvins": "give it to OpenVINS as kalibr_imu_chain.yaml, fed the columns fieldcal apply "
    "writes (a*_cal, g*_cal)",
}


def _wrote(what: str, fmt: str) -> None:
    """One line on stderr (stdout may carry the export itself): what was written, what next."""
    step = NEXT_STEP.get(fmt)
    click.echo(f"wrote {what} ({fmt})" + (f"; next: {step}" if step else ""), err=True)


_SUFFIXES = ", ".join(f"{f.suffix} {f.name}" for f in exports.FORMATS.values() if f.suffix)


@cli.command()
@click.argument("cal_json", type=click.Path())
@click.option(
    "--format",
    "fmt",
    type=click.Choice(list(exports.FORMATS)),
    help=f"Target convention. [default: from -o's suffix ({_SUFFIXES}), else {exports.DEFAULT}]",
)
@click.option(
    "-o",
    "--output",
    help="Write to this file instead of stdout (c-library: to this folder, made if missing).",
)
@click.option(
    "--sysid",
    type=click.IntRange(1, 255),
    help="px4: the vehicle's MAVLink system id on every line (QGroundControl loads the file "
    "only onto that vehicle). [default: 1]",
)
@click.option(
    "--compid",
    type=click.IntRange(1, 255),
    help="px4: the MAVLink component id on every line. [default: 1]",
)
@click.option(
    "--allow-out-of-range",
    is_flag=True,
    help="ardupilot, px4: write a value outside the range the autopilot accepts, marked by a "
    "comment, instead of refusing the export (one warning line names them).",
)
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and warnings.")
@force_option
def export(
    cal_json: str,
    fmt: str | None,
    output: str | None,
    sysid: int | None,
    compid: int | None,
    allow_out_of_range: bool,
    quiet: bool,
    force: bool,
) -> None:
    """Write the calibration for firmware or another tool, its convention stated in the text;
    say what was written and the next step (on stderr)."""
    options: dict[str, object] = {
        k: v for k, v in (("sysid", sysid), ("compid", compid)) if v is not None
    }
    if allow_out_of_range:
        options["allow_out_of_range"] = True
    if fmt is not None and exports.get(fmt).files is not None:  # a folder of files
        if not output:
            raise InputError(f"the {fmt} format is a folder of files: give -o DIR")
        cal = read_cal(cal_json)
        files = exports.export_files(cal, fmt, **options)
        claim(
            [Path(output) / name for name in files],
            {"calibration": cal_json},
            force,
            folders_made=True,
        )
        _files.make_folder(output)
        # the files are only right together (the C library's .h and .c): all or none
        _files.write_together({Path(output) / name: data for name, data in files.items()})
        if not quiet:
            _wrote(", ".join(str(Path(output) / name) for name in files), fmt)
        return
    claim([output], {"calibration": cal_json}, force)
    if fmt is None:
        by_suffix = exports.for_path(output) if output else None
        fmt = by_suffix.name if by_suffix else exports.DEFAULT
    cal = read_cal(cal_json)
    if exports.get(fmt).binary is not None:  # a binary file (.mat) only goes to -o
        data = exports.export_bytes(cal, fmt, **options)
        if not output:
            raise InputError(f"the {fmt} format is binary: give -o FILE{exports.get(fmt).suffix}")
        _files.write_bytes(output, data)
        if not quiet:
            _wrote(output, fmt)
        return
    text = exports.export(cal, fmt, **options)
    if output:
        _files.write_text(output, text if text.endswith("\n") else text + "\n")
    else:
        click.echo(text.rstrip("\n"))
    if not quiet and (output or sys.stderr.isatty()):  # a pipe's reader wants the text alone
        _wrote(output or "to stdout", fmt)


# ----------------------------------------------------------------------------- report
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.argument("log", type=click.Path())
@click.option("-o", "--output", default="report.html", show_default=True, help="HTML report.")
@click.option("--png", "png_dir", help="Also write each figure as PNG into this folder.")
@log_options
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
@force_option
def report(
    cal_json: str,
    log: str,
    output: str,
    png_dir: str | None,
    quiet: bool,
    force: bool,
    **cols: object,
) -> None:
    """Pictures of the calibration: spheres, pose coverage, residuals, norm and dip histograms."""
    inputs = {"calibration": cal_json, "log": log}
    claim([output], inputs, force)
    if png_dir is not None:
        pngs = [Path(png_dir) / f"{name}.png" for name in library.FIGURES]
        claim(pngs, inputs, force, folders_made=True)
    check_order(cal_json, log, "report")
    check_matplotlib()
    cal = read_cal(cal_json)
    with progress_line(quiet) as progress:
        if progress is not None:
            progress(f"reading {log}")
        data = load(log, cols, progress)
        if progress is not None:
            progress("drawing the report")
        library.write_report(cal, data, output, png_dir=png_dir, on_progress=progress)
    if not quiet:
        click.echo(f"wrote {output}" + (f" and PNGs in {png_dir}" if png_dir else ""))
