"""``fieldcal info LOG``: what a flight log holds (every sensor instance, battery, throttle,
attitude, GPS), with each stream's source, samples, rate, unit and frame."""

from __future__ import annotations

from pathlib import Path

import click

from ..errors import InputError
from . import library
from .group import cli

__all__ = ["info"]


@cli.command()
@click.argument("log", type=click.Path())
def info(log: str) -> None:
    """List what flight LOG (.ulg PX4 ULog, .bin ArduPilot DataFlash) holds: each sensor
    instance (choose one with --mag N / --imu N), battery current and voltage, throttle,
    attitude, the GPS position; the default of each marked."""
    path = library.regular_file(log)
    reader = library.FLIGHT_READERS.get(Path(path).suffix.lower())
    if reader is None:
        raise InputError(
            f"{log}: 'fieldcal info' lists a flight log's streams (.ulg, .bin); for other "
            "logs run 'fieldcal calibrate' and read its notes"
        )
    for line in library.info_lines(reader(path)):
        click.echo(line)
