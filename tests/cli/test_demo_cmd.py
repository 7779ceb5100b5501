"""``demo``: a simulated session calibrated and compared with its truth."""

from __future__ import annotations

import json
import sys

from _cli import lines_of, run


def test_demo(tmp_path):
    out = run("demo", "--out", tmp_path, "--no-report").output
    assert "truth vs estimate" in out and "δ (accel, Eq. 19) =" in out and "δ (mag" in out
    assert "15 poses found by still detection" in out
    # the clean simulated session passes; the verdict comes right after the simulation line
    assert lines_of(out)[1].startswith("verdict: PASS")  # and the codes of any notes
    assert json.loads((tmp_path / "cal.json").read_text())["verdict"]["level"] == "pass"


def test_demo_without_matplotlib(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if it were not installed
    out = run("demo", "--out", tmp_path).output
    assert "skipped the report" in out and not (tmp_path / "report.html").exists()
