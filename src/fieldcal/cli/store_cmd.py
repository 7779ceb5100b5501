"""``fieldcal store``: calibrations over time, a folder of calibration files by device and
date (add, list, drift)."""

from __future__ import annotations

import os

import click

from .. import _files
from ..errors import InputError
from . import library
from .group import Command, claim, cli, force_option, open_console, read_cal
from .options import POSITIVE

__all__ = ["store", "store_add", "store_drift", "store_list"]

#: The store's folder when --store is not given: $FIELDCAL_STORE, else ./fieldcal-store.
_STORE_ENV = "FIELDCAL_STORE"


def _store_option(f: Command) -> Command:
    decorated: Command = click.option(
        "--store",
        "store_dir",
        help=f"The store's folder [default: ${_STORE_ENV}, else ./fieldcal-store].",
    )(f)
    return decorated


def _open_store(store_dir: str | None) -> library.Store:
    folder = store_dir or os.environ.get(_STORE_ENV) or "fieldcal-store"
    return library.Store(folder)


@cli.group()
def store() -> None:
    """Calibrations over time: a folder of calibration files by device and date."""


@store.command("add")
@click.argument("cal_json", type=click.Path())
@click.option("--device", help="The device's id (letters, digits, . _ -) [default: from the file].")
@_store_option
def store_add(cal_json: str, device: str | None, store_dir: str | None) -> None:
    """Keep CAL_JSON in the store under its device and date."""
    cal = read_cal(cal_json)
    device = device or cal.options.get("device")
    if not device:
        raise InputError(f"{cal_json}: no device id in the file; give --device ID")
    path = _open_store(store_dir).add(cal, device=device)
    click.echo(f"stored {cal_json} as {path}")


@store.command("list")
@click.argument("device", required=False)
@_store_option
def store_list(device: str | None, store_dir: str | None) -> None:
    """The devices and how many calibrations each has; with DEVICE, its calibrations."""
    opened = _open_store(store_dir)
    if device is None:
        for name in opened.devices():
            entries = opened.entries(name)
            click.echo(
                f"{name}: {len(entries)} calibration(s), latest {entries[-1].created:%Y-%m-%d}"
            )
        return
    rows = opened.drift(device)
    open_console().print(library.drift_table(rows))


@store.command("drift")
@click.argument("device")
@click.option(
    "--sigmas",
    type=POSITIVE,
    default=3.0,
    show_default=True,
    help="A change is flagged beyond this many combined standard errors.",
)
@click.option("--plot", help="Also draw every parameter against time (.png).")
@_store_option
@force_option
def store_drift(
    device: str, sigmas: float, plot: str | None, store_dir: str | None, force: bool
) -> None:
    """Every calibration of DEVICE against the one before: the parameters that changed
    beyond their uncertainty; --plot draws them over time with error bars."""
    claim([plot], {}, force)
    rows = _open_store(store_dir).drift(device, sigmas=sigmas)
    open_console().print(library.drift_table(rows))
    if plot is not None:
        figure = library.drift_figure(rows)
        with _files.replacing(plot) as temp:
            figure.savefig(temp, format="png", dpi=90)
        click.echo(f"wrote {plot}")
