"""How the CLI tests run ``fieldcal``: through click's CliRunner (never a ``fieldcal`` found on
PATH), with the one-line error checked; a log with a pose column."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from fieldcal.cli import cli


def run(*args, ok=True):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    if ok:
        assert result.exit_code == 0, (result.output, result.exception)
    return result


def user_error(*args, match):
    """Exit code 2, one line on stderr starting with 'Error:', matching, no traceback."""
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 2, (result.output, result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert match in lines[0], lines[0]
    assert "Traceback" not in result.output
    return lines[0]


def pose_csv(path, accel, mag=None, labels=None):
    """A log with a pose column; ``accel`` or ``mag`` may be None for a one-sensor log."""
    first = accel if accel is not None else mag
    counts = [len(a) for a in first]
    labels = labels if labels is not None else np.repeat(np.arange(len(first)), counts)
    cols, header = [labels], "pose"
    if accel is not None:
        cols.append(np.concatenate(accel))
        header += ",ax,ay,az"
    if mag is not None:
        cols.append(np.concatenate(mag))
        header += ",mx,my,mz"
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.10g")
    return path


def lines_of(text):
    return text.splitlines()
