"""``fieldcal noise``: each sensor's noise from the still parts of a log (Allan deviation),
and Kalibr / OpenVINS ``imu.yaml``."""

from __future__ import annotations

import json

import click

from .. import _files
from . import library
from .group import check_matplotlib, claim, cli, force_option, open_console, progress_line, read_cal
from .options import POSITIVE, flight_instances, keywords, sensor_columns

__all__ = ["noise"]


def _unit(text: str | None) -> str | float | None:
    """A unit option: a name (``g``, ``deg/s``) or SI units per raw unit (a number)."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        return text


@cli.command()
@click.argument("log", type=click.Path())
@click.option("--cal", "cal_json", help="Analyse the readings as this calibration corrects them.")
@click.option(
    "--still",
    type=click.Choice(["auto", "detect", "all"]),
    default="auto",
    show_default=True,
    help="The still intervals detected, the whole log as one still recording, or auto.",
)
@click.option(
    "--export",
    "export_format",
    type=click.Choice(["kalibr", "openvins"]),
    help="Write Kalibr's imu.yaml or OpenVINS' kalibr_imu_chain.yaml (to -o, else stdout).",
)
@click.option("-o", "--output", help="File for --export (e.g. imu.yaml).")
@click.option("--plot", help="Allan deviation figure: a .png, or .html with the table.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--accel-unit", help="Raw accelerometer unit: g, mg, m/s^2, or m/s^2 per count.")
@click.option("--gyro-unit", help="Raw gyroscope unit: deg/s, rad/s, or rad/s per count.")
@click.option("--rate", type=POSITIVE, help="Sample rate in Hz when there is no time column.")
@sensor_columns
@flight_instances
@click.option("--time-col", help="Time column (s; ms/us/ns recognised).")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
@force_option
def noise(
    log: str,
    cal_json: str | None,
    still: str,
    export_format: str | None,
    output: str | None,
    plot: str | None,
    as_json: bool,
    accel_unit: str | None,
    gyro_unit: str | None,
    rate: float | None,
    quiet: bool,
    force: bool,
    **cols: str | None,
) -> None:
    """Noise of each sensor from the still parts of LOG: Allan deviation, noise density,
    random walk and bias instability; Kalibr / OpenVINS imu.yaml with --export kalibr."""
    if output is not None and export_format is None:
        raise click.UsageError("-o is the file for --export; add --export kalibr")
    inputs = {"log": log, **({"calibration": cal_json} if cal_json else {})}
    claim([output, plot], inputs, force)
    cal = read_cal(cal_json) if cal_json else None
    with progress_line(quiet) as progress:
        if progress is not None:
            progress(f"reading {log} and computing Allan deviations")
        report = library.characterise_noise(
            log,
            cal=cal,
            still=still,
            rate=rate,
            accel_unit=_unit(accel_unit),
            gyro_unit=_unit(gyro_unit),
            **keywords(cols, ["read"]),
        )
        yaml = {"kalibr": report.kalibr_yaml, "openvins": report.openvins_yaml}.get(
            export_format or "", lambda: None
        )()
        if plot is not None:
            check_matplotlib()
            library.write_noise_figure(report, plot)
    if yaml is not None and output is not None:
        _files.write_text(output, yaml)
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=2, allow_nan=False))
    elif yaml is not None and output is None:
        click.echo(yaml, nl=False)
    elif not quiet:
        library.print_noise(open_console(), report)
    if not quiet and not as_json:
        for path in (output, plot):
            if path is not None:
                click.echo(f"wrote {path}", err=output is None and yaml is not None)
