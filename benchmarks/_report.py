"""Shared plumbing for benchmark scripts: machine description and docs/benchmarks.md sections.

Each benchmark owns one section of ``docs/benchmarks.md`` between
``<!-- BEGIN name -->`` and ``<!-- END name -->`` and rewrites only that section, so the
scripts can be run in any order.
"""

from __future__ import annotations

import datetime as dt
import importlib
import os
import platform
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import scipy

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS_MD = ROOT / "docs" / "benchmarks.md"
FIGURES = ROOT / "docs" / "figures"

HEADER = """# Benchmarks

Every table here is written by a script in `benchmarks/`; the section says which command
produced it, on which machine and when. Times are medians over repeated runs measured side by
side in one process; ratios compare rows of the same run.
"""


def machine() -> str:
    """One line naming the machine, Python, NumPy and SciPy."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores, Python {sys.version.split()[0]}, "
        f"NumPy {np.__version__}, SciPy {scipy.__version__}"
    )


def stamp(command: str) -> str:
    """The provenance lines every section starts with."""
    today = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    return f"Command: `{command}`  \nMachine: {machine()}  \nDate: {today}\n"


def write_section(name: str, markdown: str) -> None:
    """Replace (or append) the section ``name`` of docs/benchmarks.md."""
    BENCHMARKS_MD.parent.mkdir(parents=True, exist_ok=True)
    text = BENCHMARKS_MD.read_text() if BENCHMARKS_MD.exists() else HEADER
    block = f"<!-- BEGIN {name} -->\n{markdown.strip()}\n<!-- END {name} -->"
    pattern = re.compile(
        rf"<!-- BEGIN {re.escape(name)} -->.*?<!-- END {re.escape(name)} -->", re.DOTALL
    )
    text = pattern.sub(lambda _: block, text) if pattern.search(text) else f"{text}\n{block}\n"
    BENCHMARKS_MD.write_text(text)


def pin_blas_threads():
    """Limit BLAS/OpenMP to one thread (small problems are slower, and far less predictable,
    with threading: two concurrent processes made a 5 ms fit take 0.7 s)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1)


def rebind(module: str, attr: str, wrap: Callable[[Any], Any]) -> list[tuple[object, str, Any]]:
    """Replace fieldcal function ``module.attr`` (``Class.method`` allowed) by ``wrap(fn)``
    wherever it was imported by name (``from .evaluate import evaluate``); returns the undo
    list of ``(holder, name, original)``."""
    owner: object = importlib.import_module(module)
    name = attr
    if "." in attr:
        cls, name = attr.split(".")
        owner = getattr(owner, cls)
    fn = getattr(owner, name)
    wrapped = wrap(fn)
    holders = [owner] + [
        m
        for m in list(sys.modules.values())
        if getattr(m, "__name__", "").startswith("fieldcal") and getattr(m, name, None) is fn
    ]
    for holder in holders:
        setattr(holder, name, wrapped)
    return [(holder, name, fn) for holder in holders]
