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
