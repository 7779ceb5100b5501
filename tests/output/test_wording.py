"""One vocabulary (issue 34, item 5): the verdict line, the certificate line and the report's
banner never contradict; a continuous fit's certificate says what it means; ``implausible`` is
never ``status: ok``."""

from __future__ import annotations

import dataclasses

import pytest

import fieldcal
from fieldcal.calibration import Reason, Verdict
from fieldcal.output.report_tables import banner_html
from fieldcal.output.terminal import _certificate_line
from fieldcal.simulation.handwave import simulate_handwave


@pytest.fixture(scope="module")
def static():
    s = fieldcal.simulate("paper", seed=5)
    return fieldcal.calibrate(s.accel, s.mag)


def _with(cal, p, level="pass", codes=()):
    diag = dataclasses.replace(cal.diagnostics, p_value=p, status="ok")
    reasons = tuple(Reason(c, "warn", f"{c} text") for c in codes)
    return dataclasses.replace(cal, diagnostics=diag, verdict=Verdict(level, reasons))


def test_implausible_is_never_status_ok(static):
    cal = _with(static, 9e-119, "warn", ("implausible",))
    line = _certificate_line(cal)
    assert "status: implausible" in line and "status: ok" not in line
    assert "does not explain the data" in line


def test_a_pass_with_a_low_p_does_not_claim_consistency(static):
    cal = _with(static, 0.0086)
    banner, line = banner_html(cal), _certificate_line(cal)
    assert "PASS" in banner and "consistent with its noise" not in banner
    assert "does not explain" not in line  # a PASS beside "does not explain" contradicts
    good = _with(static, 0.4)
    assert "consistent with its noise" in banner_html(good)
    assert "consistent with the noise" in _certificate_line(good)


def test_a_continuous_fit_says_what_its_certificate_means(tmp_path):
    log = simulate_handwave(seed=4, seconds=25.0)
    path = tmp_path / "waved.csv"
    log.write_csv(str(path))
    cal = fieldcal.calibrate_log(str(path), poses="continuous")
    low = dataclasses.replace(cal, diagnostics=dataclasses.replace(cal.diagnostics, p_value=2.5e-5))
    line = _certificate_line(low)
    assert "not a χ² test for a continuous fit" in line and "does not explain" not in line
    if low.verdict.level == "pass":
        assert "the motion determines the calibration" in banner_html(low)
