"""The calibration's HTML for notebooks (fieldcal.notebook): well-formed, the user's and the
library's text escaped, one coverage dot per pose where gravity points in the body frame."""

from __future__ import annotations

import dataclasses
import re
from html.parser import HTMLParser

from _known import known_calibration

from fieldcal.calibration import Reason, Verdict
from fieldcal.notebook import calibration_html


class _Tags(HTMLParser):
    """Every tag opened and closed, and the text, as a browser's parser reads them."""

    VOID = frozenset({"br", "img", "input", "hr", "meta", "link"})

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.text: list[str] = []
        self.circles: list[dict[str, str | None]] = []

    def handle_starttag(self, tag, attrs):
        if tag == "circle":
            self.circles.append(dict(attrs))
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):
        if tag == "circle":
            self.circles.append(dict(attrs))

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, (self.stack, tag)
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _parse(text: str) -> _Tags:
    parser = _Tags()
    parser.feed(text)
    parser.close()
    assert parser.stack == []  # every element closed, in order
    return parser


def test_reasons_are_escaped_and_the_html_well_formed():
    words = "<script>alert(1)</script> pose 3 & 4"
    cal = dataclasses.replace(
        known_calibration(gyro=True), verdict=Verdict("fail", (Reason("unusable", "fail", words),))
    )
    html = calibration_html(cal)
    assert "<script>" not in html
    parsed = _parse(html)
    text = "".join(parsed.text)
    assert words in text and "verdict: FAIL (unusable)" in text
    assert "gyroscope: raw = gain · v + bias, v in rad/s" in text
    assert "#cf222e" in html  # fail's colour


def test_one_dot_per_pose_where_gravity_points():
    cal = known_calibration()  # poses: level, then two upside down
    parsed = _parse(calibration_html(cal))
    ys = sorted(float(c["cy"]) for c in parsed.circles)
    assert ys == [0.0, 120.0, 120.0]  # +Z down at the top, +Z up at the bottom
    assert "3 poses, method truth" in "".join(parsed.text)
    assert re.search(r"verdict: UNKNOWN", calibration_html(cal))
