"""The group's one error path: exit codes, one-line errors, outputs checked before any
work and written atomically, interrupts, warnings, progress; startup stays light."""

from __future__ import annotations

import itertools
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _cli import run, user_error

import fieldcal


def test_version_and_help():
    assert fieldcal.__version__ in run("--version").output
    for command in ("calibrate", "apply", "export", "simulate", "report", "demo"):
        assert "Usage: " in run(command, "--help").output


def test_version_and_help_load_no_heavy_module():
    # --version and --help import numpy, click and fieldcal's light modules only
    code = (
        "import sys\n"
        "from fieldcal.cli import cli\n"
        "for args in (['--version'], ['--help'], ['calibrate', '--help']):\n"
        "    try:\n"
        "        cli(args, prog_name='fieldcal')\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = ('rich', 'scipy', 'matplotlib', 'fieldcal.pipeline', 'fieldcal.trust.fitting')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy or m in heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


# ----------------------------------------------------------------------------- bad input
def test_missing_file(tmp_path):
    user_error("calibrate", tmp_path / "nope.csv", match="no such file")
    user_error("export", tmp_path / "nope.json", match="no such calibration file")


def test_unreadable_file(tmp_path):
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x81binary")
    user_error("calibrate", tmp_path / "bin.csv", match="not a text file")
    user_error("calibrate", tmp_path, match="is a folder")
    (tmp_path / "bad.json").write_text("{not json")
    user_error("export", tmp_path / "bad.json", match="not a fieldcal calibration")


def test_an_output_is_never_an_input(files, tmp_path):
    """Compared by file identity: the path itself, a hard link and a symbolic link are refused,
    with or without --force, and the input is left as it was."""
    log, cal = tmp_path / "log.csv", tmp_path / "cal.json"
    log.write_bytes(files["session"].read_bytes())
    cal.write_bytes(files["cal"].read_bytes())
    before = {p: p.read_bytes() for p in (log, cal)}
    hard, soft = tmp_path / "hard.csv", tmp_path / "soft.csv"
    os.link(log, hard)
    soft.symlink_to(log)
    for args in (
        ("calibrate", log, "-o", log),
        ("calibrate", log, "-o", hard),
        ("calibrate", log, "-o", soft, "--force"),
        ("apply", cal, log, "-o", log, "--force"),
        ("apply", cal, log, "-o", hard, "--force"),
        ("apply", cal, log, "-o", soft),
        ("apply", cal, log, "-o", cal, "--force"),
        ("export", cal, "-o", cal, "--force"),
        ("report", cal, log, "-o", hard, "--force"),
    ):
        user_error(*args, match="input")
    # a figure of --png that would land on the log (a log may have any suffix)
    (tmp_path / "figs").mkdir()
    figure = tmp_path / "figs" / "timeline.png"
    figure.write_bytes(log.read_bytes())
    user_error(
        "report",
        cal,
        figure,
        "-o",
        tmp_path / "r.html",
        "--png",
        tmp_path / "figs",
        "--force",
        match="is the input log itself",
    )
    user_error("calibrate", log, "-o", hard, "--force", match="same file as the input log")
    assert {p: p.read_bytes() for p in (log, cal)} == before
    assert _no_temporaries(tmp_path)


def test_an_existing_output_needs_force(files, tmp_path):
    log, cal = files["session"], files["cal"]
    old = tmp_path / "old"
    old.write_text("keep me\n")
    pngs = tmp_path / "png"
    pngs.mkdir()
    (pngs / "coverage.png").write_text("keep me\n")
    demo_dir = tmp_path / "demo"
    demo_dir.mkdir()
    (demo_dir / "cal.json").write_text("keep me\n")
    for args in (
        ("calibrate", log, "-o", old),
        ("calibrate", log, "--json", "-o", old),
        ("apply", cal, log, "-o", old),
        ("export", cal, "-o", old),
        ("report", cal, log, "-o", old),
        ("report", cal, log, "-o", tmp_path / "new.html", "--png", pngs),
        ("simulate", "-o", old),
        ("simulate", "-o", tmp_path / "new.csv", "--truth", old),
        ("demo", "--out", demo_dir, "--no-report"),
    ):
        line = user_error(*args, match="exists; pass --force to replace it")
        assert line.startswith("Error: ") and line.endswith("exists; pass --force to replace it")
    assert old.read_text() == "keep me\n" and (demo_dir / "cal.json").read_text() == "keep me\n"
    assert not (tmp_path / "new.csv").exists() and not (tmp_path / "new.html").exists()
    # with --force each is replaced
    run("export", cal, "-o", old, "--format", "matlab", "--force")
    assert "A_accel" in old.read_text()
    run("calibrate", log, "-o", old, "--force", "-q")
    assert json.loads(old.read_text())["schema"] == "fieldcal.calibration"
    run("simulate", "-o", tmp_path / "new.csv", "--truth", old, "--force")
    assert json.loads(old.read_text())["method"] == "truth"
    assert _no_temporaries(tmp_path)


def test_outputs_are_checked_before_any_work(files, tmp_path):
    user_error("calibrate", files["session"], "-o", tmp_path / "nope" / "c.json", match="folder")
    user_error("calibrate", files["session"], "-o", tmp_path, match="is a folder")
    user_error("simulate", "-o", tmp_path / "a", "--truth", tmp_path / "a", match="given twice")
    # an output problem is reported before a bad log is even read
    user_error("calibrate", tmp_path / "missing.csv", "-o", files["cal"], match="--force")


# ----------------------------------------------------------------------------- files (issue #10)
def _no_temporaries(folder):
    return [p.name for p in Path(folder).rglob("*") if p.name.endswith(".part")] == []


def _interrupt_on(monkeypatch, target, name, after=0):
    """Make ``target.name`` raise KeyboardInterrupt on its call number ``after + 1``."""
    real = getattr(target, name)
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) > after:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(target, name, interrupted)


def test_interrupted_apply_leaves_the_old_output(files, tmp_path, monkeypatch):
    """Ctrl-C half-way through a streamed apply: exit 130, one line, the previous output intact
    and no temporary file left."""
    import fieldcal.logs.apply as apply_module

    out = tmp_path / "out.csv"
    out.write_text("the previous output\n")
    monkeypatch.setattr(apply_module, "CHUNK_ROWS", 100)
    _interrupt_on(monkeypatch, fieldcal.Calibration, "correct_mag", after=3)  # after 3 chunks
    result = run("apply", files["cal"], files["session"], "-o", out, "--force", ok=False)
    assert result.exit_code == 130
    assert result.stderr == "Interrupted; nothing was written\n"
    assert out.read_text() == "the previous output\n"
    assert _no_temporaries(tmp_path)


def test_interrupted_calibrate_and_simulate(files, tmp_path, monkeypatch):
    import fieldcal.pipeline

    old = tmp_path / "cal.json"
    old.write_text("{}\n")
    _interrupt_on(monkeypatch, fieldcal.pipeline, "run_log")
    result = run("calibrate", files["session"], "-o", old, "--force", ok=False)
    assert (result.exit_code, result.stderr) == (130, "Interrupted; nothing was written\n")
    assert old.read_text() == "{}\n"
    # interrupted after the first of two files: the message names the one completed
    _interrupt_on(monkeypatch, fieldcal.Calibration, "to_json")
    session, truth = tmp_path / "s.csv", tmp_path / "t.json"
    result = run("simulate", "-o", session, "--truth", truth, ok=False)
    assert result.exit_code == 130
    assert result.stderr == f"Interrupted; completed {session}; nothing else was written\n"
    assert session.is_file() and not truth.exists() and _no_temporaries(tmp_path)


def test_an_error_half_way_leaves_the_old_output(files, tmp_path):
    """A bad value deep in the log stops apply with one line; the old output stays whole."""
    lines = files["session"].read_text().splitlines()
    lines[-3] = "7,1,2,3,oops,5,6"
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out.csv"
    out.write_text("the previous output\n")
    user_error("apply", files["cal"], bad, "-o", out, "--force", match="'oops'")
    assert out.read_text() == "the previous output\n" and _no_temporaries(tmp_path)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("calibrat",), "No such command 'calibrat'"),
        (("calibrate",), "Missing argument 'LOG'"),
        (("--bogus",), "No such option"),
        (("simulate", "--poses", "0"), "--poses"),
        (("simulate", "--seed", "-1"), "--seed"),
        (("simulate", "--rate", "nan"), "--rate"),
        (("simulate", "--preset", "nope"), "--preset"),
        (("demo", "--seed", "x"), "--seed"),
        (("export",), "Missing argument"),
        (("apply", "a.json", "b.csv"), "Missing option '-o'"),
    ],
)
def test_command_usage_errors_are_one_line(args, match):
    user_error(*args, match=match)


def test_unexpected_errors_are_one_line_bugs(files, monkeypatch):
    import fieldcal.pipeline

    def broken(*args, **kwargs):
        raise KeyError("oops")

    monkeypatch.setattr(fieldcal.pipeline, "run_log", broken)
    result = run("calibrate", files["session"], "--json", ok=False)
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: KeyError: 'oops'; this is a bug")
    assert "FIELDCAL_DEBUG=1" in lines[0] and "Traceback" not in result.output
    # FIELDCAL_DEBUG=1 lets the traceback through
    monkeypatch.setenv("FIELDCAL_DEBUG", "1")
    result = run("calibrate", files["session"], "--json", ok=False)
    assert isinstance(result.exception, KeyError)


def test_runtime_warnings_never_reach_the_terminal(files, tmp_path, monkeypatch):
    import warnings

    import fieldcal.pipeline

    real = fieldcal.pipeline.run_log

    def noisy(*args, **kwargs):
        with np.errstate(all="warn"):
            np.float64(1.0) / np.float64(0.0)  # numpy's RuntimeWarning: divide by zero
        warnings.warn("a note meant for the user", UserWarning, stacklevel=1)
        return real(*args, **kwargs)

    monkeypatch.setattr(fieldcal.pipeline, "run_log", noisy)
    result = run("calibrate", files["session"], "-o", tmp_path / "c.json")
    assert "divide by zero" not in result.output and "RuntimeWarning" not in result.output
    assert "warning: a note meant for the user" in result.stdout


def test_progress_reaches_the_display(disturbed, files, tmp_path, monkeypatch):
    """calibrate passes the library's progress lines (the robust fit's drops) to the status
    line, apply its rows; the status line itself is off when stderr is not a terminal."""
    import contextlib

    import fieldcal.cli.calibrate_cmd
    import fieldcal.logs.apply as apply_module
    import fieldcal.logs.streamed_text as streamed_text

    seen = []

    @contextlib.contextmanager
    def recorder(quiet):
        yield None if quiet else seen.append

    monkeypatch.setattr(fieldcal.cli.calibrate_cmd, "progress_line", recorder)
    run("calibrate", disturbed, "-o", tmp_path / "c.json")
    assert "dropped pose 3 (mag)" in seen and any(s.startswith("calibrating") for s in seen)
    seen.clear()
    monkeypatch.setattr(apply_module, "CHUNK_ROWS", 200)
    monkeypatch.setattr(streamed_text, "PROGRESS_SECONDS", 0.0)
    run("apply", files["cal"], files["session"], "-o", tmp_path / "a.csv")
    # blocks of about 200 lines (cut by bytes at line ends): rows counted up to every data row
    counts = [int(m.replace(",", "")) for m in re.findall(r"apply: ([\d,]+) rows", " ".join(seen))]
    rows = len(Path(files["session"]).read_text().splitlines()) - 1
    assert len(counts) > 10 and counts == sorted(counts) and counts[-1] == rows
    assert all(150 <= b - a <= 250 for a, b in itertools.pairwise([0, *counts[:-1]]))
    seen.clear()
    run("apply", files["cal"], files["session"], "-o", tmp_path / "b.csv", "-q")
    assert seen == []
    # under CliRunner stderr is not a terminal: no status line, nothing on stderr
    monkeypatch.undo()
    assert run("calibrate", files["session"], "-o", tmp_path / "d.json").stderr == ""


def test_python_dash_m_runs_the_command():
    """``python -m fieldcal`` is the command (tests never run a ``fieldcal`` from PATH)."""
    out = subprocess.run(
        [sys.executable, "-m", "fieldcal", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == f"fieldcal, version {fieldcal.__version__}"
    bad = subprocess.run(
        [sys.executable, "-m", "fieldcal", "calibrat"], capture_output=True, text=True
    )
    assert bad.returncode == 2 and bad.stderr.startswith("Error: No such command 'calibrat'")


def test_every_command_is_registered_once_by_its_module():
    import fieldcal.cli as package
    from fieldcal.cli import cli

    expected = {
        "calibrate", "apply", "export", "report", "capture", "plan", "noise", "store",
        "batch", "demo", "simulate", "field", "info",
    }  # fmt: skip
    assert set(cli.commands) == expected
    owners = {name: command.callback.__module__ for name, command in cli.commands.items()}
    assert {m.__name__ for m in package.COMMAND_MODULES} == set(owners.values())
    assert set(cli.commands["store"].commands) == {"add", "list", "drift"}
