"""Reports in the words of their mode (issue 34, item 6): a continuous fit's report speaks of
motion (stretches and rests shaded, every sample in the histograms, no "poses found"), both
kinds carry the gyroscope's correction table with its standard errors, and the coverage maps
write no label over the points."""

from __future__ import annotations

import pytest

import fieldcal
from fieldcal.simulation.continuous import simulate_continuous

pytest.importorskip("matplotlib", reason="the report needs matplotlib (fieldcal[plot])")

from fieldcal.output.report import report_figures, write_report


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("logs")
    rests = folder / "rests.csv"
    simulate_continuous("paper", seed=3, n_poses=10).write_csv(str(rests))
    few = folder / "few.csv"
    simulate_continuous("paper", seed=3, n_poses=5).write_csv(str(few))
    return rests, few


def _html(path, tmp_path, **options):
    cal = fieldcal.calibrate_log(str(path), **options)
    out = tmp_path / "r.html"
    write_report(cal, fieldcal.read_log(str(path)), out)
    return cal, out.read_text()


def test_a_continuous_report_speaks_of_motion(logs, tmp_path):
    _, few = logs
    cal, html = _html(few, tmp_path, poses="continuous")
    assert "trajectory" in cal.options
    assert "s of continuous motion" in html and "found, " not in html
    assert "still samples" not in html and "rests (the gyroscope" in html
    assert "<h3>gyroscope</h3>" in html and " ± " in html.split("<h3>gyroscope</h3>")[1][:3000]
    figures = report_figures(cal, fieldcal.read_log(str(few)))
    title = figures["timeline"]._suptitle.get_text()
    assert "no still poses" in title and "5 rest(s)" in title
    hist = figures["histograms"].axes[0].get_title()
    assert "every sample" in hist


def test_a_static_report_has_the_gyroscope_table_too(logs, tmp_path):
    rests, _ = logs
    cal, html = _html(rests, tmp_path)
    assert cal.gyro is not None and "trajectory" not in cal.options
    assert "<h3>gyroscope</h3>" in html and "found, " in html


def test_coverage_labels_are_not_written_over_the_points(logs):
    rests, _ = logs
    cal = fieldcal.calibrate_log(str(rests))
    fig = report_figures(cal, fieldcal.read_log(str(rests)))["coverage"]
    for ax in fig.axes:
        assert all(not t.get_text() for t in ax.get_xticklabels())  # longitude named below
        assert any("longitude" in t.get_text() for t in ax.texts)
