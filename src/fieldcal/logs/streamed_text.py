"""A text log calibrated as it streams (``fieldcal apply`` text in, text out): every input line
copied byte for byte, the calibrated values appended to each data line, a chunk of
:data:`ARROW_MIN_ROWS` lines or more with nothing unusual done by pyarrow in bulk, else numpy's
C parser and one formatting pass, else line by line (which names the problem); see
:mod:`fieldcal.logs.apply` for the whole contract.
"""

from __future__ import annotations

import contextlib
import csv
import functools
import io
import itertools
import re
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
from numpy.typing import NDArray

from .._files import replacing
from ..errors import InputError
from .arrow_parser import float_column, pyarrow_module
from .calibrated_columns import (
    Thermal,
    as_text,
    check_new_columns,
    columns_for_apply,
    corrected,
    reported_columns,
)
from .raw_table import to_float
from .text import parse_numbers
from .text_layout import HEAD_LINES, layout
from .text_lines import _split

if TYPE_CHECKING:
    from ..calibration import Calibration

__all__ = ["ARROW_MIN_ROWS", "PROGRESS_SECONDS", "apply_text"]

Array = NDArray[np.float64]


#: Seconds between two progress reports.
PROGRESS_SECONDS = 1.0


#: Chunks of at least this many data rows have their calibrated values formatted by pyarrow
#: (where it is installed; its import, about 0.1 s, would cost more on a small log).
ARROW_MIN_ROWS = 20_000


def _is_data(line: str) -> bool:
    """Not blank and not a ``#`` comment (the readers' rule); a byte-order mark is ignored."""
    content = line.lstrip("\ufeff").strip()
    return bool(content) and not content.startswith("#")


def _ending(line: str) -> tuple[str, str]:
    body = line.rstrip("\r\n")
    return body, line[len(body) :]


#: Control characters that ``str.split()`` takes for blanks and numpy's parser does not.
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


@dataclass
class _Text:
    """What every chunk of a text log needs: where the sensors' fields are, how to write."""

    cal: Calibration
    src: Path
    delimiter: str | None
    decimal: str
    sep: str
    where: dict[str, list[int]]
    used: dict[str, list[str]]
    thermal: Thermal
    temp_index: int | None = None
    temp_name: str | None = None


@contextlib.contextmanager
def _read_as_text(src: Path) -> Iterator[None]:
    """A file that is not text, or not CSV, refused in one line naming it."""
    try:
        yield
    except UnicodeDecodeError:
        raise InputError(f"{src}: not a text file; give a CSV with a header line") from None
    except csv.Error as exc:
        raise InputError(f"{src}: cannot read it as CSV ({exc}); fix the file") from None


def apply_text(
    cal: Calibration,
    src: Path,
    dst: Path,
    sensors: list[str],
    columns: dict[str, str | Sequence[str] | None],
    chunk_rows: int,
    on_progress: Callable[[str], None] | None,
    decimal: str | None,
    thermal: Thermal,
) -> dict[str, list[str]]:
    """The calibrated columns appended to every data line of a text log ``src``, written to
    ``dst`` (atomically), streamed ``chunk_rows`` lines at a time; the columns used per sensor.
    A file that is not text or not CSV is refused in one line."""
    size = max(src.stat().st_size, 1)
    with (
        _read_as_text(src),
        src.open(newline="", encoding="utf-8") as handle,
        replacing(dst) as temp,
        temp.open("w", newline="", encoding="utf-8") as out,
    ):
        head: list[str] = []
        count = 0
        for line in handle:  # the lines the header is looked for in (the readers' rule)
            head.append(line)
            count += _is_data(line)
            if count == HEAD_LINES:
                break
        if count == 0:
            raise InputError(f"{src}: the file is empty; give a CSV with a header line")
        found = layout(src, [head[0].removeprefix("\ufeff"), *head[1:]], decimal)
        out.writelines(head[: found.header_index])  # preamble, comments, blank lines as they were
        body, ending = _ending(head[found.header_index])
        delimiter = found.delimiter
        header = [h.strip() for h in _split([found.header], delimiter)[0]]
        used = columns_for_apply(str(src), header, sensors, columns)
        where = {s: [header.index(c) for c in cols] for s, cols in used.items()}
        new_names = [f"{c}_cal" for cols in used.values() for c in cols]
        check_new_columns(str(src), header, new_names)
        sep = delimiter or " "
        if delimiter is None:
            names = sep.join(new_names)
        else:  # quoted as the csv module quotes (a name holding the delimiter, a quote)
            buffer = io.StringIO()
            csv.writer(buffer, delimiter=delimiter, lineterminator="").writerow(new_names)
            names = buffer.getvalue()
        out.write(f"{body}{sep}{names}{ending or chr(10)}")

        temp_name = thermal.find(str(src), header)
        index = None if temp_name is None else header.index(temp_name)
        job = _Text(cal, src, delimiter, found.decimal, sep, where, used, thermal, index, temp_name)
        rows_done, last = 0, time.monotonic()
        chars = sum(len(line) for line in head[: found.start])
        for block in _blocks(handle, head[found.start :], chunk_rows):
            bulk = _arrow_block(job, block)
            if bulk is not None:  # written as bytes, the text layer flushed first
                out.flush()
                out.buffer.write(bulk[0])
                rows = bulk[1]
            else:
                text, rows = _chunk(job, _LINE.findall(block), rows_done)
                out.write(text)
            rows_done += rows
            chars += len(block)
            now = time.monotonic()
            if on_progress is not None and now - last >= PROGRESS_SECONDS:
                last = now
                on_progress(f"apply: {rows_done:,} rows ({min(100 * chars / size, 100):.0f} %)")
    return reported_columns(used, temp_name)


#: A line with its ending as the file reads it with ``newline=""`` (``\n``, ``\r\n``, ``\r``).
_LINE = re.compile(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+$")


def _blocks(handle: TextIO, first: list[str], chunk_rows: int) -> Iterator[str]:
    """The text after the header in blocks of whole lines, about ``chunk_rows`` lines each
    (read by size: the first lines' mean length), the lines already read first."""
    size = max(chunk_rows * max(sum(map(len, first)) // max(len(first), 1), 1), 1)
    pending = "".join(first)
    while True:
        more = handle.read(max(size - len(pending), 1)) if len(pending) < size else ""
        text = pending + more
        pending = ""
        if not text:
            return
        if more and not text.endswith("\n"):
            text += handle.readline()  # the line cut by the size, whole
        yield text


def _arrow_block(job: _Text, block: str) -> tuple[bytes, int] | None:
    """The output of a block of lines as bytes, the lines parsed, their values formatted and
    the lines joined with them by pyarrow, and its number of rows; None unless every line is
    a data line of the header's fields of numbers pyarrow reads as numpy's parser does (no
    quote, comment, blank line, ``(``; one kind of line ending; a decimal point; at least
    :data:`ARROW_MIN_ROWS` lines; pyarrow installed): :func:`_chunk` does the rest."""
    if job.delimiter is None or job.decimal != "." or any(c in block for c in '"#('):
        return None
    n_lf, n_cr = block.count("\n"), block.count("\r")
    eol = "\n" if n_cr == 0 else "\r\n" if n_cr == block.count("\r\n") == n_lf else None
    if eol is None or n_lf + 1 < ARROW_MIN_ROWS or not block.isascii():
        return None
    pa, pc, pa_csv = pyarrow_module(), pyarrow_module("pyarrow.compute"), _csv_module()
    if pa is None or pc is None or pa_csv is None or not _formats_as_repr():
        return None
    ended = block.endswith(eol)
    raw = block.encode("ascii") + (b"" if ended else eol.encode("ascii"))
    idx = [i for cols in job.where.values() for i in cols]
    if job.temp_index is not None:  # the rows' temperatures, last
        idx.append(job.temp_index)
    numbers = _arrow_numbers(pa, pa_csv, raw, job, idx)
    if numbers is None:
        return None
    lines = _line_array(pa, pc, raw, len(eol))
    if lines is None or len(lines) != len(numbers):
        return None  # a blank line pyarrow skipped
    texts = _arrow_texts(pa, pc, _fixed(job, numbers))
    # (scalars from buffers: pyarrow's own would import pandas)
    empty, sep, ending = _strings(pa, ["", job.sep, eol])
    joined = pc.binary_join_element_wise(lines, *texts, sep)
    joined = pc.binary_join_element_wise(joined, empty, ending)  # the line ending after
    _, offsets, data = joined.buffers()
    end = int(np.frombuffer(offsets, dtype=np.int32, count=len(joined) + 1)[-1])
    out = memoryview(data)[: end if ended else end - len(eol)]
    return bytes(out), len(numbers)


def _csv_module() -> ModuleType | None:
    return pyarrow_module("pyarrow.csv")


def _arrow_numbers(pa: Any, pa_csv: Any, raw: bytes, job: _Text, idx: list[int]) -> Array | None:
    """The fields ``idx`` of every line of ``raw`` (rows x fields), empty fields NaN; None when
    pyarrow refuses a line (a field it does not read as a number, another count of fields)."""
    first = raw[: raw.index(b"\n")].decode("ascii").rstrip("\r")
    width = max(1 + max(idx), len(_split([first], job.delimiter)[0]))
    names = [f"f{i}" for i in range(width)]
    try:
        table = pa_csv.read_csv(
            pa.BufferReader(raw),
            read_options=pa_csv.ReadOptions(column_names=names),
            parse_options=pa_csv.ParseOptions(
                delimiter=job.delimiter, quote_char=False, double_quote=False,
                newlines_in_values=False, ignore_empty_lines=False,
            ),
            convert_options=pa_csv.ConvertOptions(
                include_columns=[names[i] for i in idx],
                column_types={names[i]: pa.float64() for i in idx},
                null_values=[""],
                strings_can_be_null=False,
            ),
        )  # fmt: skip
    except (pa.ArrowException, ValueError):
        return None
    out = np.empty((table.num_rows, len(idx)))
    for k, i in enumerate(idx):
        out[:, k] = float_column(table.column(names[i]))
    return out


def _line_array(pa: Any, pc: Any, raw: bytes, eol: int) -> Any:
    """The lines of ``raw`` (each ended) as a pyarrow string array without their endings."""
    ends = np.flatnonzero(np.frombuffer(raw, dtype=np.uint8) == 10) + 1
    if len(raw) >= 2**31:
        return None
    offsets = np.zeros(len(ends) + 1, dtype=np.int32)
    offsets[1:] = ends
    lines = pa.Array.from_buffers(
        pa.string(), len(ends), [None, pa.py_buffer(offsets), pa.py_buffer(raw)]
    )
    return pc.utf8_slice_codeunits(lines, 0, -eol)


def _fixed(job: _Text, numbers: Array) -> list[Array]:
    """The calibrated columns of the parsed fields (the sensors', then the temperature)."""
    fixed: list[Array] = []
    k = 0
    t = job.thermal.values(numbers[:, -1] if job.temp_index is not None else None, job.temp_name)
    for sensor, cols in job.where.items():
        fixed += list(corrected(job.cal, sensor, numbers[:, k : k + len(cols)], t).T)
        k += len(cols)
    return fixed


def _chunk(job: _Text, chunk: list[str], first_row: int) -> tuple[str, int]:
    """The output text of a chunk of lines and its number of data rows: every line as it was,
    the calibrated values after each data line. Vectorised; lines numpy does not parse exactly
    as the csv module and ``float`` do are done line by line (:func:`_tails`)."""
    joined = "".join(chunk)
    fast = _fast_chunk(job, joined)
    if fast is not None:
        return fast
    split = [(*_ending(line), _is_data(line)) for line in chunk]
    tails = iter(_tails(job, split, first_row))
    text = "".join(
        f"{body}{job.sep}{next(tails)}{ending}" if is_data else body + ending
        for body, ending, is_data in split
    )
    return text, sum(is_data for _, _, is_data in split)


def _fast_chunk(job: _Text, joined: str) -> tuple[str, int] | None:
    """:func:`_chunk` for lines with one kind of line ending, no quotes and numbers numpy's
    parser reads; None otherwise."""
    if '"' in joined or (
        job.delimiter is None and (not joined.isascii() or _CONTROL.search(joined))
    ):
        return None  # a quoted delimiter would shift the fields; str.split() knows more blanks
    if job.decimal == "," and "." in joined:
        return None  # a point in a decimal-comma log is named line by line
    n_cr = joined.count("\r")
    if n_cr == 0:
        eol = "\n"
    elif n_cr == joined.count("\r\n") == joined.count("\n"):
        eol = "\r\n"
    else:
        return None  # mixed line endings, or carriage returns alone
    pieces = joined.split(eol)
    ended = pieces[-1] == ""
    if ended:
        pieces.pop()
    everything = "#" not in joined and all(map(str.strip, pieces))
    mask = None if everything else [_is_data(p) for p in pieces]
    data = pieces if mask is None else list(itertools.compress(pieces, mask))
    if not data:
        return joined, 0
    idx = [i for cols in job.where.values() for i in cols]
    if job.temp_index is not None:  # the rows' temperatures, last
        idx.append(job.temp_index)
    numbers = parse_numbers(
        [line.replace(",", ".") for line in data] if job.decimal == "," else data,
        job.delimiter,
        idx,
    )
    if numbers is None or len(numbers) != len(data):
        return None
    fixed = _fixed(job, numbers)
    tails = _bulk_tails(fixed, job.sep, job.decimal) if len(data) >= ARROW_MIN_ROWS else None
    if tails is None:
        values = [column.tolist() for column in fixed]
        tail = (job.sep + "%r") * len(values)  # repr: the shortest text of the same double
        if mask is None and job.decimal == ".":  # one format per line, the line's text included
            text = eol.join(map(("%s" + tail).__mod__, zip(pieces, *values, strict=True)))
            return text + (eol if ended else ""), len(data)
        tails = list(map(tail.__mod__, zip(*values, strict=True)))
        if job.decimal == ",":
            tails = [t.replace(".", ",") for t in tails]
    if mask is None:
        text = eol.join(map(str.__add__, pieces, tails))
    else:
        it = iter(tails)
        text = eol.join(p + next(it) if m else p for p, m in zip(pieces, mask, strict=True))
    return text + (eol if ended else ""), len(data)


def _bulk_tails(columns: list[Array], sep: str, decimal: str) -> list[str] | None:
    """Each row's ``sep value sep value ...``, the values formatted as Python's ``repr`` writes
    them (the shortest text of the same double) but in bulk by pyarrow; None without it.

    pyarrow's shortest digits are Python's; its layout is too for a number written with a
    point and no exponent between 1e-4 and 1e16 (where ``repr`` writes no exponent). The rest
    (zeros and whole numbers, exponents, NaN, infinities) is written by ``repr``. Arrays and
    scalars are made from their buffers: ``pyarrow.array`` and ``pyarrow.scalar`` would import
    pandas, a second's work on a busy machine.
    """
    pa, pc = pyarrow_module(), pyarrow_module("pyarrow.compute")
    if pa is None or pc is None or not _formats_as_repr():
        return None
    return _arrow_tails(pa, pc, columns, sep, decimal)


#: Doubles on which pyarrow's layout is checked against ``repr`` before it is used.
_PROBES = (0.1, -2.5, 1 / 3, 123.456, 1e-4, 0.00012345678901234, 9.87654321e15, 6.02e15, 2 / 3e3)


@functools.cache
def _formats_as_repr() -> bool:
    """Whether this pyarrow writes doubles as ``repr`` does where :func:`_bulk_tails` takes
    its text (another version might not: then ``repr`` writes every value)."""
    pa, pc = pyarrow_module(), pyarrow_module("pyarrow.compute")
    probes = np.array(_PROBES)
    tails = _arrow_tails(pa, pc, [probes], ",", ".")
    return tails == ["," + repr(v) for v in _PROBES]


def _arrow_tails(pa: Any, pc: Any, columns: list[Array], sep: str, decimal: str) -> list[str]:
    # (an empty first piece: a leading separator)
    empty, separator = _strings(pa, ["", sep])
    joined = pc.binary_join_element_wise(empty, *_arrow_texts(pa, pc, columns), separator)
    if decimal == ",":
        joined = pc.replace_substring(joined, ".", ",")
    tails: list[str] = joined.to_pylist()
    return tails


def _arrow_texts(pa: Any, pc: Any, columns: list[Array]) -> list[Any]:
    """Each column's values as ``repr`` writes them, a pyarrow string array each."""
    texts = []
    for column in columns:
        column = np.ascontiguousarray(column, dtype=np.float64)
        n = len(column)
        text = pc.cast(pa.Array.from_buffers(pa.float64(), n, [None, pa.py_buffer(column)]),
                       pa.string())  # fmt: skip
        with np.errstate(invalid="ignore"):
            size = np.abs(column)
            far = (size < 1e-4) | ~(size < 1e16)  # (NaN too)
        bits = pa.py_buffer(np.packbits(far, bitorder="little"))
        odd = pa.Array.from_buffers(pa.bool_(), n, [None, bits])
        odd = pc.or_(odd, pc.invert(pc.match_substring(text, ".")))
        odd = pc.or_(odd, pc.match_substring(text, "e"))
        where = pc.indices_nonzero(odd).to_pylist()
        if where:
            again = _strings(pa, list(map(repr, column[where].tolist())))
            text = pc.replace_with_mask(text, odd, again)
        texts.append(text)
    return texts


def _strings(pa: ModuleType, texts: list[str]) -> Any:
    """A pyarrow string array of ASCII ``texts``, made from its buffers."""
    offsets = np.zeros(len(texts) + 1, dtype=np.int32)
    np.cumsum([len(t) for t in texts], out=offsets[1:])
    data = pa.py_buffer("".join(texts).encode("ascii"))
    return pa.Array.from_buffers(pa.string(), len(texts), [None, pa.py_buffer(offsets), data])


def _tails(job: _Text, chunk: list[tuple[str, str, bool]], first_row: int) -> list[str]:
    """The calibrated values to append to each data line of ``chunk``, as text, line by line
    (the csv module splits the fields; a bad value is named with its column and data row)."""
    bodies = [body for body, _, is_data in chunk if is_data]
    if not bodies:
        return []
    src = job.src
    rows = _split(bodies, job.delimiter)
    if len(rows) != len(bodies):
        raise InputError(
            f"{src}: a quoted field runs over several lines near data row {first_row + 1}; "
            "apply copies the file line by line: write the log as .npz or .parquet"
        )
    texts: list[list[str]] = []
    read: Array | None = None
    if job.temp_index is not None and job.temp_name is not None:
        i = job.temp_index
        if any(len(r) <= i for r in rows):
            short = next(k for k, r in enumerate(rows) if len(r) <= i)
            raise InputError(
                f"{src}: data row {first_row + short + 1} has too few fields; fix the file"
            )
        column = np.array([r[i] for r in rows], dtype=str)
        read = to_float(column, job.temp_name, str(src), first_row, decimal=job.decimal)
    t = job.thermal.values(read, job.temp_name)
    for sensor, idx in job.where.items():
        try:
            raw = np.array([[r[i] for i in idx] for r in rows], dtype=str)
        except IndexError:
            short = next(k for k, r in enumerate(rows) if len(r) <= max(idx))
            raise InputError(
                f"{src}: data row {first_row + short + 1} has too few fields; fix the file"
            ) from None
        values = np.column_stack(
            [
                to_float(raw[:, k], job.used[sensor][k], str(src), first_row, decimal=job.decimal)
                for k in range(3)
            ]
        )
        texts += [as_text(column) for column in corrected(job.cal, sensor, values, t).T]
    tails = [job.sep.join(fields) for fields in zip(*texts, strict=True)]
    return [t.replace(".", ",") for t in tails] if job.decimal == "," else tails
