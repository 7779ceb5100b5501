"""Poses grouped by a pose column: a column whose labels come in runs (one run per pose, as
loggers and ``fieldcal simulate`` write them) is grouped without sorting or gathering the rows,
with the very poses the general path (sort the labels, gather each label's rows) gives."""

from __future__ import annotations

import dataclasses
from unittest import mock

import numpy as np
import pytest

import fieldcal
from fieldcal.errors import InputError
from fieldcal.logs import load_log, poses_from_log
from fieldcal.logs import pose_finding as pose_finding_module


@pytest.fixture(scope="module")
def table1(tmp_path_factory):
    """A Table 1 session, 15 poses of 40 samples, labelled 0..14 in runs."""
    path = tmp_path_factory.mktemp("column") / "table1.csv"
    fieldcal.simulate("paper", seed=5, samples=(40, 40)).write_csv(path)
    return load_log(path)


def _sorted_path(log):
    """The poses the general path gives (the shortcut for labels in runs turned off)."""
    with mock.patch.object(pose_finding_module, "_label_runs", return_value=None):
        return poses_from_log(log)


def _assert_same(a, b):
    assert a.entries == b.entries and a.source == b.source == "column"
    for sensor in ("accel", "mag"):
        x, y = getattr(a, sensor), getattr(b, sensor)
        assert len(x) == len(y)
        assert all(np.array_equal(p, q) for p, q in zip(x, y, strict=True))
        assert np.array_equal(a.means(sensor), b.means(sensor))


def _relabelled(log, labels):
    return dataclasses.replace(log, pose=labels)


def _cases(log):
    pose = np.asarray(log.pose)
    return {
        "as written": pose,
        "halves": pose / 2,  # labels that are not whole numbers
        "whole numbers": pose.astype(np.int64),
        "text with blanks": np.array([f" p{int(v)} " for v in pose]),
        # 0.0 and -0.0 are one label, as np.unique has them
        "signed zeros": np.where((pose == 0) & (np.arange(len(pose)) % 2 == 0), -0.0, pose),
    }


@pytest.mark.parametrize("case", ["as written", "halves", "whole numbers", "text with blanks",
                                  "signed zeros"])  # fmt: skip
def test_labels_in_runs_give_the_sorted_paths_poses(table1, case):
    log = _relabelled(table1, _cases(table1)[case])
    found = poses_from_log(log)
    # the shortcut is taken: the poses' samples are views of the log's rows (the sorted path
    # gathers copies)
    assert np.shares_memory(found.accel[3], log.accel)
    assert not np.shares_memory(_sorted_path(log).accel[3], log.accel)
    assert found.n == 15 and [e["samples"] for e in found.entries] == [40] * 15
    _assert_same(found, _sorted_path(log))


def test_a_label_that_comes_back_takes_the_sorted_path(table1):
    pose = np.asarray(table1.pose).copy()
    pose[:20] = 14.0  # pose 14's label also on the first rows: its rows are not one run
    log = _relabelled(table1, pose)
    assert pose_finding_module._label_runs(log, pose) is None
    found = poses_from_log(log)
    assert not np.shares_memory(found.accel[0], log.accel)
    assert found.entries[0]["label"] == "14" and found.entries[0]["samples"] == 60
    _assert_same(found, _sorted_path(log))


def test_unlabelled_rows_take_the_sorted_path(table1):
    pose = np.asarray(table1.pose).copy()
    pose[::7] = np.nan
    log = _relabelled(table1, pose)
    _assert_same(poses_from_log(log), _sorted_path(log))


def test_every_row_its_own_label_is_still_refused_for_a_continuous_log(table1):
    log = _relabelled(table1, np.arange(table1.n, dtype=float))
    with pytest.raises(InputError, match="gives every row its own label"):
        poses_from_log(log)
