"""The one exception type for the user's mistakes (fieldcal.errors): a ValueError for library
callers, a one-line ``Error:`` and exit 2 on the command line."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from fieldcal.cli import cli
from fieldcal.errors import InputError


def test_input_error_is_a_value_error():
    assert issubclass(InputError, ValueError)
    with pytest.raises(ValueError, match="the fix"):
        raise InputError("a problem; the fix")


def test_the_command_line_turns_it_into_one_line_and_exit_2(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    result = CliRunner().invoke(cli, ["calibrate", str(empty)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: ")
    assert "Traceback" not in result.output
