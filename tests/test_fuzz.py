"""Nothing lost, never a traceback: malformed input gives a result or one line, quickly.

A bounded run of the fuzz corpus of ``benchmarks/fuzz.py`` (fixed seeds, a few seconds: no
greedy fits) must find no bug — no traceback or other exception, no hang, no multi-line error
or numpy warning, no result for nonsense (the same columns for both sensors, shuffled pose
labels, a singular or non-finite gain). Property tests add arbitrary bytes as log files and
arbitrary JSON as calibration files. The full corpus and its table are in
``docs/benchmarks.md`` (section fuzz).
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fieldcal
from fieldcal.calibration import Calibration
from fieldcal.errors import InputError
from fieldcal.logs import read_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fuzz

#: Cases per category in CI (the full corpus: fuzz.FULL).
BOUNDED = {"log files": 60, "options": 30, "calibration files": 100, "library calls": 160}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return fuzz.make_base(tmp_path_factory.mktemp("fuzz-base"), seed=7, slow=False)


@pytest.mark.parametrize("category", list(BOUNDED))
def test_bounded_corpus_finds_no_bug(base, category, tmp_path):
    cases = fuzz.build(base, {category: BOUNDED[category]}, seed=7, slow=False)
    results = fuzz.run_cases(cases, tmp_path)
    found = [f"{r.name}: {r.outcome}: {r.detail}" for r in fuzz.bugs(results)]
    assert found == []
    outcomes = {r.outcome for r in results}
    assert "error" in outcomes  # the corpus does reach the checks ...
    assert "ok" in outcomes or category == "calibration files"  # ... and the results


def test_the_classifier_sees_each_kind_of_bug():
    """The harness itself: what it must call a bug, it does."""

    def warns():
        np.log(np.zeros(1))
        return 1

    def raises_type_error():
        raise TypeError("boom")

    def multi_line():
        raise ValueError("first line\nsecond line")

    assert fuzz.library_outcome(warns)[0] == "noisy"
    assert fuzz.library_outcome(raises_type_error)[0] == "traceback"
    assert fuzz.library_outcome(multi_line)[0] == "noisy"
    assert fuzz.library_outcome(lambda: np.linalg.inv(np.zeros((2, 2))))[0] == "traceback"
    assert fuzz.library_outcome(lambda: 1, nonsense=True)[0] == "nonsense"
    assert fuzz.library_outcome(lambda: int("x"))[0] == "error"
    hang = fuzz.Case("library calls", "sleeps", lambda folder: __import__("time").sleep(5))
    hang.timeout = 0.2
    assert [r.outcome for r in fuzz.run_cases([hang], Path("/tmp/fieldcal-test-fuzz"))] == ["hang"]


# ----------------------------------------------------------------------------- properties
@settings(max_examples=100)
@given(st.binary(max_size=400), st.sampled_from([".csv", ".npz", ".parquet", ".txt"]))
def test_any_bytes_as_a_log_read_or_refused_in_one_line(tmp_path_factory, content, suffix):
    path = tmp_path_factory.mktemp("bytes") / f"log{suffix}"
    path.write_bytes(content)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            table = read_table(path)
        except InputError as exc:
            assert "\n" not in str(exc)
        else:
            assert all(len(v) == table.n_rows for v in table.columns.values())


_cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", " ", "nan", "1e400", '"', "1,5", "abc", "\x00", "1e-320"]),
    st.integers(-(10**30), 10**30).map(str),
)


@settings(max_examples=100)
@given(st.lists(st.lists(_cells, min_size=1, max_size=8), min_size=1, max_size=30))
def test_any_csv_cells_load_or_are_refused_in_one_line(tmp_path_factory, rows):
    path = tmp_path_factory.mktemp("cells") / "log.csv"
    text = "ax,ay,az,mx,my,mz\n" + "\n".join(",".join(r) for r in rows) + "\n"
    path.write_text(text, encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            log = fieldcal.logs.load_log(path, drop_nan=bool(len(rows) % 2))
        except InputError as exc:
            assert "\n" not in str(exc)
        else:
            assert np.all(np.isfinite(log.accel)) and np.all(np.abs(log.accel) <= 1e150)


_json = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(-(10**400), 10**400),
        st.sampled_from(["nan", "inf", "-inf", "false", "", "fieldcal.calibration"]),
    ),
    lambda children: (
        st.lists(children, max_size=4)
        | st.dictionaries(st.sampled_from(["gain", "bias", "accel", "x", "level"]), children)
    ),
    max_leaves=20,
)


@pytest.fixture(scope="module")
def document():
    s = fieldcal.simulate("paper", seed=2, n_poses=10, samples=(20, 30))
    return json.loads(fieldcal.calibrate(s.accel, s.mag).to_json())


@settings(max_examples=200)
@given(st.data())
def test_any_change_to_a_calibration_file_reads_or_is_one_line(document, data):
    doc = json.loads(json.dumps(document))
    paths = fuzz._paths(doc)[1:]
    path = paths[data.draw(st.integers(0, len(paths) - 1))]
    node = doc
    for key in path[:-1]:
        node = node[key]
    if data.draw(st.booleans()) and isinstance(node, dict):
        del node[path[-1]]
    else:
        node[path[-1]] = data.draw(_json)
    text = json.dumps(doc, allow_nan=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            cal = Calibration.from_json(text)
        except ValueError as exc:
            assert type(exc) is ValueError and "\n" not in str(exc)
            return
        for name in ("accel", "mag"):
            sensor = cal.sensor(name)
            assert np.all(np.isfinite(sensor.gain)) and np.all(np.isfinite(sensor.bias))
        assert np.all(np.isfinite(cal.correct_mag([[0.3, 0.1, 0.9]])))
        assert Calibration.from_json(cal.to_json()) == cal
