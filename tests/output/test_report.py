"""The HTML report: verdict banner, rejected poses and why, expected norms, escaped user text."""

from __future__ import annotations

import dataclasses
import html
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib", reason="matplotlib (the plot extra) not installed")
matplotlib.use("Agg")

from fieldcal.calibration import Verdict  # noqa: E402
from fieldcal.errors import InputError  # noqa: E402
from fieldcal.logs import load_log, poses_from_log  # noqa: E402
from fieldcal.output.report import FIGURES, write_report  # noqa: E402
from fieldcal.output.report_tables import banner_html, inverse_gain_std  # noqa: E402
from fieldcal.pipeline import calibrate_log  # noqa: E402
from fieldcal.simulation.continuous import simulate_continuous  # noqa: E402

DISTURBED = 4  # the pose whose magnetometer readings are pushed off


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A simulated session with one magnetically disturbed pose, its calibration and report."""
    folder = tmp_path_factory.mktemp("report") / "<b>bold & co"
    folder.mkdir()
    sim = simulate_continuous("paper", seed=4)
    columns = {k: v.copy() for k, v in sim.columns.items()}
    start, stop = sim.segments[DISTURBED]
    sigma = np.sqrt(sim.session.truth.mag.noise_cov[0, 0])
    # 3 per-sample σ on every sample: ~60 σ of the pose mean, as a nearby piece of iron would do
    columns["mx"][start:stop] += 3 * sigma
    dataclasses.replace(sim, columns=columns).write_csv(str(folder / "session.csv"))
    log = load_log(folder / "session.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate_log(log, poses=poses_from_log(log))
    output = folder / "report.html"
    write_report(cal, log, output, png_dir=folder / "png")
    return {"cal": cal, "log": log, "folder": folder, "page": output.read_text(encoding="utf-8")}


def test_the_disturbed_pose_is_rejected(made):
    # the premise of the other tests
    assert [r.index for r in made["cal"].rejected] == [DISTURBED]
    assert made["cal"].poses[DISTURBED]["rejected"].startswith("mag: ")


def test_banner_shows_the_verdict_and_its_reasons_first(made):
    page, verdict = made["page"], made["cal"].verdict
    assert verdict.level == "warn"
    banner = re.search(r'<div class="verdict (\w+)"><h2>([^<]*)</h2>', page)
    assert banner is not None and banner.group(1) == "warn" and "WARN" in banner.group(2)
    assert page.index('class="verdict') < page.index("<h2>Correction")
    for reason in verdict.reasons:
        assert f"<li>{html.escape(reason.text)}</li>" in page
    assert f'<p class="codes">{verdict.summary}</p>' in page  # WARN (rejected, ...)


def test_rejected_pose_is_listed_with_its_reason(made):
    page = made["page"]
    table = page[page.index("<h3>Rejected poses") :]
    (rejected,) = made["cal"].rejected
    assert html.escape(rejected.reason) in table
    pose = made["cal"].poses[DISTURBED]
    assert f"{pose['start']}–{pose['stop']}" in table


def test_expected_norms_and_units_appear(made):
    page, cal = made["page"], made["cal"]
    assert f"{cal.gravity_norm:.6g}" in page and f"{cal.field_strength:.6g}" in page
    assert html.escape(cal.units["accel_calibrated"]) in page
    assert "M = inv(gain)" in page and "bias b (raw units)" in page


def test_user_text_is_escaped(made):
    page = made["page"]
    assert "&lt;b&gt;bold &amp; co" in page
    assert "<b>" not in page and "<script" not in page


def test_figures_are_inlined_and_written(made):
    names = {p.stem for p in (made["folder"] / "png").iterdir()}
    expected = {"timeline", "residuals", "histograms", "accel_sphere", "mag_sphere", "coverage"}
    assert made["cal"].gyro is not None  # the simulated log has a gyroscope: its figure too
    expected.add("gyro")
    assert names == expected
    assert made["page"].count("data:image/png;base64,") == len(expected)


def test_old_files_without_verdict_or_residuals(made, tmp_path):
    old_poses = tuple(
        {k: v for k, v in p.items() if not k.endswith("_residual")} for p in made["cal"].poses
    )
    old = dataclasses.replace(made["cal"], verdict=None, rejected=(), poses=old_poses)
    write_report(old, made["log"], tmp_path / "old.html")
    page = (tmp_path / "old.html").read_text(encoding="utf-8")
    assert "no verdict (calibration file from fieldcal 0.1)" in page
    assert "no per-pose residuals" in page
    # the pose's own rejection note still reaches the table
    assert "magnetic disturbance" in page


def test_fail_banner_escapes_reasons(made):
    verdict = Verdict("fail", ("<i>bad</i> & worse",))
    page = banner_html(dataclasses.replace(made["cal"], verdict=verdict))
    assert 'class="verdict fail"' in page and "<li>&lt;i&gt;bad&lt;/i&gt; &amp; worse</li>" in page


def test_log_shorter_than_the_poses_is_refused(made, tmp_path):
    log = made["log"]
    n = made["cal"].poses[-1]["start"]
    short = dataclasses.replace(
        log, accel=log.accel[:n], mag=log.mag[:n], gyro=None, time=log.time[:n], index=log.index[:n]
    )
    with pytest.raises(InputError, match="give the log it was made from"):
        write_report(made["cal"], short, tmp_path / "x.html")


def test_inverse_gain_errors_follow_the_delta_method(made):
    sensor = made["cal"].mag
    K = sensor.gain
    cov = sensor.covariance
    idx = [cov.index(f"gain[{j},{k}]") for j in range(3) for k in range(3)]
    C = cov.matrix[np.ix_(idx, idx)]
    h = 1e-7
    J = np.empty((9, 9))
    for p in range(9):  # central differences of inv(K) in each entry of K
        step = np.zeros(9)
        step[p] = h
        plus = np.linalg.inv(K + step.reshape(3, 3))
        minus = np.linalg.inv(K - step.reshape(3, 3))
        J[:, p] = (plus - minus).ravel() / (2 * h)
    expected = np.sqrt(np.diag(J @ C @ J.T)).reshape(3, 3)
    np.testing.assert_allclose(inverse_gain_std(sensor), expected, rtol=1e-5)


def test_report_is_written_atomically_and_never_over_its_log(made, tmp_path):
    folder = made["folder"]
    assert {p.stem for p in (folder / "png").iterdir()} <= set(FIGURES)
    assert [p for p in folder.rglob("*.part")] == []
    log_path = Path(made["log"].path)
    before = log_path.read_bytes()
    with pytest.raises(InputError, match="is the input log"):
        write_report(made["cal"], made["log"], log_path)
    assert log_path.read_bytes() == before


def test_plot_returns_the_report_figures(made):
    """``cal.plot(log)`` gives the report's figures themselves: the same names as the PNGs the
    report wrote, each the same picture (equal PNG bytes at the report's resolution); without
    the log, the figures the calibration alone holds the data for."""
    import io

    from matplotlib.figure import Figure

    cal, folder = made["cal"], made["folder"]
    figures = cal.plot(made["log"])
    written = sorted(p.stem for p in (folder / "png").glob("*.png"))
    assert sorted(figures) == written and set(figures) <= set(FIGURES)
    assert all(isinstance(f, Figure) for f in figures.values())
    buffer = io.BytesIO()
    figures["residuals"].savefig(buffer, format="png", dpi=90)
    assert buffer.getvalue() == (folder / "png" / "residuals.png").read_bytes()
    # a path is read with the columns the calibration recorded
    assert sorted(cal.plot(folder / "session.csv")) == written
    alone = cal.plot()
    assert sorted(alone) == ["gyro", "residuals"]
    # drawn from the calibration alone, they are the report's pictures all the same
    for name in alone:
        buffer = io.BytesIO()
        alone[name].savefig(buffer, format="png", dpi=90)
        assert buffer.getvalue() == (folder / "png" / f"{name}.png").read_bytes(), name
