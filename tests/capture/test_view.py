"""The capture view (:mod:`fieldcal.capture.view`) with a temperature column: the temperature
now, the span the captured poses cover, and the advice to repeat a pose when warmer."""

from __future__ import annotations

import io

from rich.console import Console

from fieldcal.capture.feeds import open_source
from fieldcal.capture.live_session import CaptureOptions, CaptureSession, run_capture
from fieldcal.capture.view import LiveView
from fieldcal.simulation.warmup import simulate_warmup_log


def test_a_short_warmup_shows_its_span_and_asks_for_a_warmer_pose(tmp_path):
    w = simulate_warmup_log(seed=4, n_poses=10, span=3.0, rate=50.0)
    path = tmp_path / "warm.csv"
    w.write_csv(str(path))
    console = Console(file=io.StringIO(), width=160, record=True)
    view = LiveView(console, "warm.csv")
    events = []

    def hear(event):
        events.append(event)
        view.event(event)

    session = CaptureSession(CaptureOptions(), tmp_path / "cap", hear)
    run_capture(open_source(path=str(path)), session)
    console.print(view.render(session))
    text = " ".join(console.export_text().split())
    last = float(w.columns["temp"][-1])
    assert f"temperature {last:.1f} °C" in text
    assert "temperature: poses at" in text and "need 5 K" in text
    notes = [e.text for e in events if e.kind == "note"]
    assert any(n.startswith("repeat a pose when the board is warmer") for n in notes)


def test_a_continuous_capture_shows_its_motion_not_an_empty_poses_table(tmp_path):
    """``--poses continuous``: the view's table is the motion covered (issue 34), and no
    line of it asks for still poses."""
    from fieldcal.pipeline import LogSettings
    from fieldcal.simulation.handwave import simulate_handwave

    path = tmp_path / "waved.csv"
    simulate_handwave(seed=6, seconds=20.0).write_csv(str(path))
    console = Console(file=io.StringIO(), width=160, record=True)
    view = LiveView(console, "waved.csv")
    options = CaptureOptions(settings=LogSettings.of(poses="continuous"))
    session = CaptureSession(options, tmp_path / "cap", view.event)
    run_capture(open_source(path=str(path)), session)
    console.print(view.render(session))
    text = " ".join(console.export_text().split())
    assert "motion (no still poses)" in text and "poses (0)" not in text
    assert "record more poses, still" not in text
