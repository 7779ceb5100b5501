"""The calibration document's text (``serialize.dumps``): the same JSON as ``json.dumps`` for
any document, laid out one key, one short list or one matrix row a line."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st

import fieldcal
from fieldcal.serialize import dumps

_LEAVES = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text()
)
_DOCS = st.recursive(
    _LEAVES,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=30,
)


@settings(max_examples=300, deadline=None)
@given(_DOCS, st.sampled_from([None, 0, 2, 4]))
def test_any_document_reads_back_as_written(doc: object, indent: int | None) -> None:
    assert json.loads(dumps(doc, indent)) == doc


def test_a_calibration_is_laid_out_a_matrix_row_a_line() -> None:
    s = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(s.accel, s.mag)
    text = cal.to_json()
    assert json.loads(text) == json.loads(json.dumps(cal.to_dict(), indent=2))
    lines = text.splitlines()
    gain = lines.index('    "gain": [')  # the accelerometer's, a 3x3 matrix: three row lines
    assert [line.count(",") for line in lines[gain + 1 : gain + 4]] == [3, 3, 2]
    assert lines[gain + 4] == "    ],"
    assert len(lines) < len(json.dumps(cal.to_dict(), indent=2).splitlines()) / 2
    assert cal.to_json(indent=None).count("\n") == 0


_NUMBERS = (
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
)
_RECORDS = st.lists(
    st.dictionaries(
        st.text(max_size=3), _NUMBERS | st.lists(_NUMBERS, max_size=3) | st.text(max_size=2)
    ),
    min_size=1,
    max_size=4,
)
_MATRICES = st.lists(st.lists(st.lists(_NUMBERS, max_size=3), max_size=3), min_size=1, max_size=4)


@settings(max_examples=300, deadline=None)
@given(_RECORDS | _MATRICES, st.sampled_from([0, 2, 4]))
def test_tables_and_matrices_laid_out_in_one_call_as_entry_by_entry(
    doc: object, indent: int
) -> None:
    """A pose table and the rotations (thousands of entries in samples mode) are laid out from
    one call of the C encoder: the very text the entry-by-entry walk writes."""
    import fieldcal.serialize as serialize

    fast = dumps({"key": doc}, indent)
    saved = serialize._flat_record, serialize._matrices
    serialize._flat_record = serialize._matrices = lambda *args: None
    try:
        assert dumps({"key": doc}, indent) == fast
    finally:
        serialize._flat_record, serialize._matrices = saved
    assert json.loads(fast) == {"key": doc}
