"""check_poses: a method's minimum of poses and of distinct orientations, refused with the
fix in one line."""

from __future__ import annotations

import numpy as np
import pytest
from _logs import _csv

import fieldcal
from fieldcal.errors import InputError
from fieldcal.logs import load_log, poses_from_log
from fieldcal.methods import METHODS
from fieldcal.methods.enough_poses import check_poses


def _labelled(tmp_path, n_poses, repeat=None):
    """A log of ``n_poses`` rests grouped by a pose column; ``repeat``: every rest is the
    first one's orientation again (the same pose held ``n_poses`` times)."""
    s = fieldcal.simulate("paper", seed=4, n_poses=n_poses, samples=(20, 20))
    accel = [s.accel[0 if repeat else i] for i in range(n_poses)]
    mag = [s.mag[0 if repeat else i] for i in range(n_poses)]
    a, m = np.concatenate(accel), np.concatenate(mag)
    columns = {f"a{c}": a[:, j] for j, c in enumerate("xyz")}
    columns.update({f"m{c}": m[:, j] for j, c in enumerate("xyz")})
    columns["pose"] = np.repeat(np.arange(n_poses, dtype=float), 20)
    log = load_log(_csv(tmp_path / "poses.csv", columns))
    return log, poses_from_log(log)


def test_enough_poses_pass(tmp_path):
    log, poses = _labelled(tmp_path, 14)
    assert check_poses(poses, "mle", log, None) is None


def test_too_few_poses_name_the_method_its_minimum_and_the_fix(tmp_path):
    log, poses = _labelled(tmp_path, 5)
    need = METHODS["mle"].min_poses_for(2)
    with pytest.raises(InputError) as refused:
        check_poses(poses, "mle", log, None)
    text = str(refused.value)
    assert text.startswith(f"5 pose(s) found; the mle method needs at least {need}")
    assert "\n" not in text and "further orientations" in text


def test_one_orientation_held_many_times_is_refused(tmp_path):
    log, poses = _labelled(tmp_path, 14, repeat=True)
    with pytest.raises(InputError):
        check_poses(poses, "mle", log, None)
