"""``fieldcal capture`` and ``plan``: calibrate live from a device, told which pose to take
next; the next poses for a calibration file."""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from pathlib import Path

import click

from ..errors import InputError
from ..limits import MOST_PLANNED
from . import library
from .group import claim, cli, finish, force_option, open_console, read_cal
from .options import (
    POSES_OPTION,
    POSITIVE,
    check_reference,
    detect_options,
    fit_options,
    sensor_columns,
    settings,
    target_options,
    targets,
)

__all__ = ["capture", "plan"]

#: The files a capture writes into its folder.
_CAPTURE_FILES = ("log.csv", "cal.json", "report.html")


def _capture_folder(out_dir: str | None, force: bool, inputs: dict[str, str]) -> Path:
    """The capture's folder; its files checked before any line is read."""
    folder = Path(out_dir or time.strftime("capture-%Y%m%d-%H%M%S"))
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a folder; give --out a folder")
    # the recorder makes the folder once the source is open: a wrong port leaves nothing
    claim([folder / name for name in _CAPTURE_FILES], inputs, force, folders_made=True)
    return folder


@cli.command()
@click.option("--port", help="Serial port of the device (e.g. /dev/ttyACM0, COM3); pyserial.")
@click.option(
    "--baud",
    type=click.IntRange(1),
    default=115200,
    show_default=True,
    help="Bits per second of the serial port.",
)
@click.option(
    "--from",
    "from_path",
    help="Read the lines from FILE instead, or from standard input with - (a command's output).",
)
@click.option("--follow", is_flag=True, help="With --from FILE: keep reading as it grows.")
@click.option(
    "--columns",
    help="Names of the fields of bare-number lines, e.g. t,ax,ay,az,mx,my,mz (else the stream "
    "sends a header line).",
)
@click.option(
    "--out",
    "out_dir",
    help="Folder for log.csv, cal.json and report.html [default: capture-DATE-TIME].",
)
@click.option(
    "--until",
    type=click.Choice(["pass"]),
    help="Stop by itself once the verdict is pass and the accuracy targets (--target-*) are met.",
)
@click.option("--plain", is_flag=True, help="One line per event instead of the live view.")
@fit_options
@sensor_columns
@click.option("--time-col", help="Time column (s; ms/us/ns recognised); default: arrival time.")
@POSES_OPTION
@click.option("--decimal", type=click.Choice([".", ","]), help="Decimal mark of the numbers.")
@detect_options
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and a fail verdict.")
@force_option
def capture(
    port: str | None,
    baud: int,
    from_path: str | None,
    follow: bool,
    columns: str | None,
    out_dir: str | None,
    until: str | None,
    plain: bool,
    quiet: bool,
    force: bool,
    **opts: object,
) -> None:
    """Calibrate live from a device: catch each still pose, say which pose to take next.

    With --poses continuous (a log with a gyroscope), turn the device through every
    orientation instead: the rotations covered so far are shown, and the calibration from the
    motion is redone as the log grows.

    Reads CSV lines (a header, or bare numbers with --columns) from a serial port, standard
    input or a file. Stops at the end of the input, when --until is met, on q or Ctrl-C; then
    writes log.csv (every line received, with its arrival time), cal.json and the report into
    --out. Exit code 3 when the final verdict is FAIL.
    """
    if (port is None) == (from_path is None):
        raise click.UsageError("give the device's --port, or --from FILE (- for standard input)")
    if follow and (from_path is None or from_path == "-"):
        raise click.UsageError("--follow is for --from FILE (a file that is still being written)")
    source_name = (
        port if port is not None else ("standard input" if from_path == "-" else from_path)
    )
    if opts.get("poses") in ("windows", "samples"):
        raise click.UsageError(
            "capture finds still poses (--poses auto or still) or calibrates from the motion "
            "(--poses continuous); cut a recorded log into windows or samples with calibrate"
        )
    # the options given as text are parsed before any line is read, into the settings objects
    chosen = settings(opts, ["read", "detect", "fit", "trust"])
    check_reference(opts)
    inputs = {} if from_path in (None, "-") else {"log": str(from_path)}
    folder = _capture_folder(out_dir, force, inputs)
    names = [name.strip() for name in columns.split(",")] if columns else None
    options = library.CaptureOptions(
        columns=None if names is None else tuple(names),
        settings=chosen,
        until=until,
    )
    source = library.open_source(port=port, baud=baud, path=from_path, follow=follow)
    live = not (plain or quiet) and sys.stdout.isatty()
    console = open_console()
    with contextlib.ExitStack() as stack:
        view: library.LiveView | library.PlainView
        if live:
            view = stack.enter_context(library.LiveView(console, str(source_name)))
        else:
            plain_view = library.PlainView(open(os.devnull, "w") if quiet else None)  # noqa: SIM115
            if quiet:
                stack.callback(plain_view.stream.close)
            view = plain_view
        session = library.CaptureSession(options, folder, view.event)
        key = stack.enter_context(library.key_reader(live and from_path != "-"))
        result = library.run_capture(source, session, refresh=view.refresh, key=key)
    written = ", ".join(str(p) for p in result.files)
    if result.error is not None:
        raise InputError(f"{result.error} (kept: {written})")
    cal = result.calibration
    assert cal is not None  # without one, result.error says why
    if not quiet:
        library.print_summary(console, cal, json.loads((folder / "cal.json").read_text()), [])
        console.print(f"wrote {written}")
    finish(cal, summary_shown=not quiet)


# ----------------------------------------------------------------------------- plan
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.option(
    "-n",
    "count",
    type=click.IntRange(1, MOST_PLANNED),
    default=1,
    show_default=True,
    help="How many poses to plan.",
)
@target_options
@click.option("--target-dip", type=POSITIVE, help="Dip standard error (degrees) to reach too.")
@click.option("--json", "as_json", is_flag=True, help="Print the plan as JSON.")
def plan(
    cal_json: str,
    count: int,
    target_dip: float | None,
    as_json: bool,
    **given: float | None,
) -> None:
    """The next poses to take for CAL_JSON: the ones that most reduce the predicted error.

    Each pose is said in words (which axis points down, which way it faces) and predicted
    errors after taking it and the ones before it. With a temperature column, when the poses'
    temperature span limits the temperature terms: repeat a pose when the board is warmer.
    """
    cal = read_cal(cal_json)
    poses = library.plan_poses(cal, count, targets=targets(given, target_dip))
    if as_json:
        click.echo(json.dumps([p.to_dict() for p in poses], indent=2, allow_nan=False))
        return
    console = open_console()
    cannot = library.unreachable(cal, targets(given, target_dip))
    if cannot is not None:  # no pose reaches it: said first, the poses still help
        console.print(f"the target cannot be met: {cannot}")
    elif poses and poses[-1].score > 1.0:
        worst = poses[-1].score
        ratio = f"{worst:.2f}" if worst < 1e4 else f"{worst:.1e}"
        console.print(
            f"the target cannot be met with {len(poses)} more pose(s): the worst predicted error "
            f"is {ratio} times its target; plan more poses (-n) or relax the target"
        )
    for i, pose in enumerate(poses, 1):
        console.print(f"{i}. {pose.words}")
        console.print(f"   then: {library.predicted_line(pose)}")
    advice = library.temperature_advice(cal)  # the poses' temperatures limit the terms
    if advice is not None:
        console.print(advice)
