"""Calibrations in threads taking turns, their LM runs stepped together (issue 24, item 4):
the same results as one at a time, whatever the width, each job's warnings its own, and no
thread left waiting when a job fails."""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

import fieldcal
from fieldcal.likelihood import fleet
from fieldcal.likelihood.levenberg import SERVICE

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from _close import assert_same_calibration
from _small_sets import shots


def _jobs() -> list[Callable[[], object]]:
    """Devices of different layouts and paths: Table 1 (default and the seed's model), 24-shot
    sets (extra starts), one sensor alone, and a set that is refused before any LM run."""
    jobs: list[Callable[[], object]] = []
    for seed in range(4):
        s = fieldcal.simulate("paper", seed=seed)
        jobs.append(lambda s=s: fieldcal.calibrate(s.accel, s.mag))
        jobs.append(lambda s=s: fieldcal.calibrate(s.accel, None))
    s = fieldcal.simulate("paper", seed=9)
    jobs.append(lambda: fieldcal.calibrate(s.accel, s.mag, pose_noise="none", robust=False))
    for seed in range(2):
        accel, mag = shots(24, seed)

        def shot(accel: object = accel, mag: object = mag) -> object:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                cal = fieldcal.calibrate(accel, mag)  # type: ignore[arg-type]
            return cal, sorted({str(w.message) for w in caught})

        jobs.append(shot)
    jobs.insert(3, lambda: fieldcal.calibrate(s.accel[:2], s.mag[:2]))  # too few poses
    return jobs


def _same(a: object, b: object) -> None:
    if isinstance(b, BaseException):
        assert type(a) is type(b) and str(a) == str(b)
    elif isinstance(b, tuple):  # a shot set: (calibration, its warnings)
        assert isinstance(a, tuple) and a[1] == b[1]
        assert_same_calibration(a[0], b[0])
    else:
        assert isinstance(a, fieldcal.Calibration) and isinstance(b, fieldcal.Calibration)
        assert_same_calibration(a, b)


@pytest.fixture(scope="module")
def alone() -> list[object]:
    out: list[object] = []
    for job in _jobs():
        try:
            out.append(job())
        except Exception as exc:
            out.append(exc)
    return out


@pytest.mark.parametrize("width", [2, 5, 32])
def test_the_fleet_gives_each_job_its_result_alone(width: int, alone: list[object]) -> None:
    f = fleet.Fleet(_jobs(), width)
    together = f.run()
    assert len(together) == len(alone)
    for a, b in zip(together, alone, strict=True):
        _same(a, b)
    assert isinstance(together[3], ValueError)  # the refused set is its own failure
    # the runs were stepped together: fewer kernel rounds than runs
    assert f.runs > 0 and f.rounds < f.runs
    assert SERVICE.get() is None  # this thread's solver is untouched


def test_a_job_that_raises_inside_a_run_releases_the_others(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A kernel error reaches the runs it held as their exception: their jobs fail, the
    others finish, nothing hangs."""
    from fieldcal.likelihood import lockstep

    real = lockstep.lockstep

    def broken(requests):  # type: ignore[no-untyped-def]
        if any(r.problem.n == 15 and len(r.problem.sensors) == 1 for r in requests):
            raise RuntimeError("kernel broke")
        return real(requests)

    monkeypatch.setattr(fleet, "lockstep", broken)
    s = fieldcal.simulate("paper", seed=1)
    jobs = [
        lambda: fieldcal.calibrate(s.accel, s.mag),
        lambda: fieldcal.calibrate(s.accel, None),
        lambda: fieldcal.calibrate(s.accel, None),
        lambda: fieldcal.calibrate(s.accel, s.mag),
    ]
    out = fleet.run_together(jobs, 4)
    assert isinstance(out[1], RuntimeError) and isinstance(out[2], RuntimeError)
    assert isinstance(out[0], fieldcal.Calibration) and isinstance(out[3], fieldcal.Calibration)
    assert_same_calibration(out[0], out[3])


def test_each_job_records_its_own_warnings() -> None:
    """Jobs that warn around their LM runs (where the turns change hands), inside their own
    ``catch_warnings``: each records its own warnings only, and the filters it set do not
    leak into the others (job 1 ignores warnings, the others record theirs)."""
    s = fieldcal.simulate("paper", seed=4)

    def job(k: int) -> list[str]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("ignore" if k == 1 else "always")
            warnings.warn(f"job {k} before", UserWarning, stacklevel=1)
            fieldcal.calibrate(s.accel, s.mag)
            warnings.warn(f"job {k} after", UserWarning, stacklevel=1)
        return [str(w.message) for w in caught]

    before = warnings.filters[:]
    out = fleet.run_together([lambda k=k: job(k) for k in range(4)], 4)
    assert out[1] == []
    for k in (0, 2, 3):
        assert out[k] == [f"job {k} before", f"job {k} after"]
    assert warnings.filters == before
