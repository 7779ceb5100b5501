"""Streaming apply: a log with calibrated columns appended, written as CSV."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .columns import explicit_columns, recognise_columns
from .readers import Table, _data_lines, _sniff_delimiter, _split, read_table, to_float

if TYPE_CHECKING:
    from ..calibration import Calibration

__all__ = ["apply_to_file"]

Array = NDArray[np.float64]


def _format(values: NDArray[np.generic]) -> NDArray[np.str_]:
    return np.char.mod("%.9g", values)


def apply_to_file(
    cal: Calibration,
    src: str | Path,
    dst: str | Path,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    chunk_rows: int = 50_000,
) -> dict[str, list[str]]:
    """Append calibrated columns (``<col>_cal``) to a log and write it to ``dst`` as CSV.

    CSV input is streamed ``chunk_rows`` rows at a time, so files larger than memory work; each
    input line is copied unchanged and the calibrated values follow it. Rows with a missing
    value give ``nan``. Returns the columns used per sensor.
    """
    src, dst = Path(src), Path(dst)
    if dst.resolve() == src.resolve():
        raise InputError(f"{dst}: is the input log itself; write the output to another file")
    sensors = [s for s in ("accel", "mag") if getattr(cal, s) is not None]
    if src.suffix.lower() in (".npz", ".parquet", ".pq"):
        return _apply_table(cal, read_table(src), dst, sensors, accel_cols, mag_cols)
    if not src.exists() or src.is_dir():
        raise InputError(f"{src}: no such file; check the path")
    try:
        return _apply_csv(cal, src, dst, sensors, accel_cols, mag_cols, chunk_rows)
    except UnicodeDecodeError:
        raise InputError(f"{src}: not a text file; give a CSV with a header line") from None


def _apply_csv(
    cal: Calibration,
    src: Path,
    dst: Path,
    sensors: list[str],
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
    chunk_rows: int,
) -> dict[str, list[str]]:
    with src.open(newline="", encoding="utf-8-sig") as handle:
        lines = _data_lines(handle)
        header_line = next(lines, None)
        if header_line is None:
            raise InputError(f"{src}: the file is empty; give a CSV with a header line")
        delimiter = _sniff_delimiter(header_line)
        header = [h.strip() for h in _split([header_line], delimiter)[0]]
        used = _columns_for_apply(str(src), header, sensors, accel_cols, mag_cols)
        where = {s: [header.index(c) for c in cols] for s, cols in used.items()}
        out_delim = delimiter or " "  # keep the input's separator
        new_names = [f"{c}_cal" for s in used for c in used[s]]
        row_number = 0
        with dst.open("w", newline="", encoding="utf-8") as out:
            out.write(out_delim.join([*header, *new_names]) + "\n")
            while True:
                chunk = [line for _, line in zip(range(chunk_rows), lines, strict=False)]
                if not chunk:
                    break
                rows = _split(chunk, delimiter)
                blocks = []
                for sensor, idx in where.items():
                    try:
                        raw = np.array([[r[i] for i in idx] for r in rows], dtype=str)
                    except IndexError:
                        raise InputError(
                            f"{src}: a row near data row {row_number + 1} has too few fields; "
                            "fix the file"
                        ) from None
                    values = np.column_stack(
                        [
                            to_float(raw[:, k], used[sensor][k], str(src), row_number)
                            for k in range(3)
                        ]
                    )
                    fix = cal.correct_accel if sensor == "accel" else cal.correct_mag
                    blocks.append(_format(fix(values)))
                appended = np.concatenate(blocks, axis=1)
                tails = [out_delim.join(v) for v in appended]
                out.writelines(
                    f"{line.rstrip(chr(13) + chr(10))}{out_delim}{tail}\n"
                    for line, tail in zip(chunk, tails, strict=True)
                )
                row_number += len(chunk)
    return used


def _columns_for_apply(
    path: str,
    header: list[str],
    sensors: list[str],
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
) -> dict[str, list[str]]:
    guessed = recognise_columns(header)
    explicit = {"accel": explicit_columns(accel_cols), "mag": explicit_columns(mag_cols)}
    used: dict[str, list[str]] = {}
    for sensor in sensors:
        cols = explicit[sensor] or guessed.get(sensor)
        if cols is None:
            continue
        missing = [c for c in cols if c not in header]
        if missing:
            raise InputError(
                f"{path}: no column {missing[0]!r}; columns found: {', '.join(header)}"
            )
        used[sensor] = cols
    if not used:
        raise InputError(
            f"{path}: no columns for the calibrated sensors ({', '.join(sensors)}) among "
            f"{', '.join(header)}; pass --accel-cols/--mag-cols"
        )
    return used


def _apply_table(
    cal: Calibration,
    table: Table,
    dst: Path,
    sensors: list[str],
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
) -> dict[str, list[str]]:
    used = _columns_for_apply(table.path, table.names, sensors, accel_cols, mag_cols)
    out = {name: table.columns[name] for name in table.names}
    for sensor, cols in used.items():
        raw = np.column_stack([table.numeric(c) for c in cols])
        fixed = cal.correct_accel(raw) if sensor == "accel" else cal.correct_mag(raw)
        for c, column in zip(cols, fixed.T, strict=True):
            out[f"{c}_cal"] = column
    names = list(out)
    text = np.column_stack(
        [_format(v) if v.dtype.kind == "f" else v.astype(str) for v in out.values()]
    )
    with dst.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(names)
        writer.writerows(text.tolist())
    return used
