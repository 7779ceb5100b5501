"""``fieldcal batch``: calibrate many logs, each on its own, into one summary table."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import click

from ..output import exports
from . import library
from .group import EXIT_FAIL, EXIT_INTERRUPTED, cli, force_option, open_console
from .options import (
    POSES_OPTION,
    check_reference,
    detect_options,
    fit_options,
    keywords,
    log_options,
)

__all__ = ["batch"]

#: Failures listed by name at the end of a batch; the rest are counted (all are in the summary).
_BATCH_SHOWN = 50


@contextmanager
def _batch_bar(quiet: bool, total: int) -> Iterator[Callable[[object], None]]:
    """A progress bar on stderr (logs done, logs/s, time left), or nothing: off with
    ``--quiet`` and when stderr is not a terminal."""
    stream = sys.stderr
    if quiet or stream is None or not stream.isatty():
        yield lambda row: None
        return
    bar = library.Progress(
        library.TextColumn("calibrating"),
        library.BarColumn(),
        library.MofNCompleteColumn(),
        library.TextColumn("{task.fields[rate]}"),
        library.TextColumn("ETA"),
        library.TimeRemainingColumn(),
        console=open_console(stderr=True),
    )
    started = time.perf_counter()
    with bar:
        task = bar.add_task("batch", total=total, rate="")

        def advance(row: object) -> None:
            done = bar.tasks[0].completed + 1
            rate = done / max(time.perf_counter() - started, 1e-9)
            bar.update(task, advance=1, rate=f"{rate:.3g} logs/s")

        yield advance


@cli.command()
@click.argument("logs", nargs=-1, required=True)
@click.option(
    "--out",
    "out_dir",
    required=True,
    help="Folder for <device>/cal.json (and exports) and summary.parquet / summary.csv.",
)
@fit_options
@POSES_OPTION
@log_options
@detect_options
@click.option(
    "--export",
    "export_names",
    multiple=True,
    type=click.Choice(list(exports.FORMATS)),
    help="Also write this format beside each cal.json (repeat for more): cal.h, cal.parm, ...",
)
@click.option("--jobs", "-j", type=click.IntRange(1), help="Worker processes. [default: the cores]")
@click.option(
    "--scheduler",
    envvar="DASK_SCHEDULER_ADDRESS",
    help="Run on this Dask cluster (tcp://HOST:PORT; default: $DASK_SCHEDULER_ADDRESS): the "
    "workers read the logs from a shared path or fsspec URL and write into --out.",
)
@click.option("--resume", is_flag=True, help="Skip the logs whose results --out already holds.")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and the failures.")
@force_option
def batch(
    logs: tuple[str, ...],
    out_dir: str,
    export_names: tuple[str, ...],
    jobs: int | None,
    scheduler: str | None,
    resume: bool,
    quiet: bool,
    force: bool,
    **opts: object,
) -> None:
    """Calibrate every LOG on its own (files, globs, fsspec URLs, manifest .csv files) and
    write one summary table.

    Each log's results go to OUT/<device>/cal.json; OUT/summary.parquet and summary.csv
    hold one row per log (verdict, reasons, dip, gains and biases with their errors, error).
    A log that fails never stops the batch. Exit code 3 when any log fails.
    """
    options = keywords(opts, ["read", "detect", "fit", "trust"])
    check_reference(opts)
    specs = library.expand_logs(logs)
    started = time.perf_counter()
    try:
        with _batch_bar(quiet, len(specs)) as advance:
            result = library.calibrate_many(
                specs,
                out=out_dir,
                jobs=jobs,
                scheduler=scheduler or None,
                exports=export_names,
                resume=resume,
                force=force,
                keep_calibrations=False,
                on_result=advance,
                **options,
            )
    except KeyboardInterrupt:
        click.echo(
            f"Interrupted; the logs finished are kept in {out_dir} (summary.csv lists them); "
            "run the same command with --resume to calibrate the rest",
            err=True,
        )
        click.get_current_context().exit(EXIT_INTERRUPTED)
    seconds = time.perf_counter() - started
    rows = result.rows
    failures = result.failed
    console = open_console()
    if not quiet:
        levels = [r["verdict"] for r in rows]
        errors = sum(1 for r in rows if r["error"])
        console.print(
            f"calibrated {len(rows)} log(s) in {seconds:.1f} s "
            f"({len(rows) / max(seconds, 1e-9):.3g} logs/s): {levels.count('pass')} pass, "
            f"{levels.count('warn')} warn, {levels.count('fail')} fail"
            + (f" ({errors} with an error)" if errors else "")
            + (f"; {result.resumed} kept from an earlier batch" if result.resumed else "")
        )
        console.print("wrote " + ", ".join(str(p) for p in result.files))
    if failures:
        console.print(f"failed ({len(failures)}):")
        for row in failures[:_BATCH_SHOWN]:
            why = row["error"] or row["reasons"] or "verdict fail"
            if row["export_error"]:
                why = f"export failed: {row['export_error']}" + (
                    "" if row["verdict"] != "fail" else f"; verdict fail: {why}"
                )
            console.print(f"  {row['device']} ({row['log']}): {why}")
        if len(failures) > _BATCH_SHOWN:
            console.print(
                f"  ... and {len(failures) - _BATCH_SHOWN} more: the rows with verdict fail "
                "in the summary"
            )
        click.get_current_context().exit(EXIT_FAIL)
