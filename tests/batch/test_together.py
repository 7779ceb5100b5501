"""Logs calibrated together (``group``): the same rows and files (numbers to 1e-9) as one at a
time, a failing log one failed row, a device named twice kept by the first log, the chunks."""

from __future__ import annotations

from pathlib import Path

import pytest
from _close import assert_same_calibration, assert_same_file, assert_same_rows

import fieldcal
from fieldcal.batch import calibrate_many
from fieldcal.batch.executors import chunks
from fieldcal.batch.job import Task
from fieldcal.errors import InputError

CREATED = "2026-01-02T03:04:05+00:00"


def _log(path: Path, seed: int, *, poses: int = 12, meta: str = "") -> str:
    s = fieldcal.simulate("paper", seed=seed, n_poses=poses, samples=(200, 200))
    s.write_csv(path, preamble=meta)
    return str(path)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """Logs of different layouts (12 and 15 poses, one with 9: every start runs), one that
    cannot be calibrated, and two naming the same device."""
    folder = tmp_path_factory.mktemp("logs")
    out = [_log(folder / f"u{i}.csv", seed=i, poses=(12, 15, 9)[i % 3]) for i in range(5)]
    bad = folder / "bad.csv"
    bad.write_text("ax,ay,az,mx,my,mz\n1,2,3,4,5,6\n")
    out.insert(2, str(bad))
    out.append(_log(folder / "t1.csv", seed=7, meta="# device: TWIN\n"))
    out.append(_log(folder / "t2.csv", seed=8, meta="# device: TWIN\n"))
    return out


@pytest.mark.parametrize("group", [3, 32])
def test_together_is_one_at_a_time(logs: list[str], tmp_path: Path, group: int) -> None:
    one = calibrate_many(logs, out=tmp_path / "one", jobs=1, group=1, created=CREATED)
    many = calibrate_many(logs, out=tmp_path / "many", jobs=1, group=group, created=CREATED)
    assert_same_rows(one.rows, many.rows)
    assert one.calibrations.keys() == many.calibrations.keys()
    for log, cal in one.calibrations.items():
        assert_same_calibration(cal, many.calibrations[log])
    for row in one.rows:
        if not row["error"]:
            a = tmp_path / "one" / row["device"] / "cal.json"
            assert_same_file(a, tmp_path / "many" / row["device"] / "cal.json")
    bad = [r for r in many.rows if r["error"]]
    assert len(bad) == 2 and "bad.csv" in bad[0]["log"]
    # the device two logs name stays the first one's, as one at a time
    assert (
        "t1.csv"
        in fieldcal.Calibration.from_json(
            (tmp_path / "many" / "TWIN" / "cal.json").read_text()
        ).options["log"]
    )
    assert "t1.csv" in bad[1]["error"]
    assert all(r["seconds"] > 0 for r in many.rows if not r["error"])


def test_group_is_checked(logs: list[str]) -> None:
    with pytest.raises(InputError, match="group must be a whole number of logs, at least 1"):
        calibrate_many(logs[:1], jobs=1, group=0)


def test_chunks_keep_the_order_and_feed_every_worker() -> None:
    tasks = [Task(index=i, log=f"{i}.csv", device=None) for i in range(70)]
    parts = chunks(tasks, 32, 1)
    assert [len(c) for c in parts] == [32, 32, 6]
    assert [t.index for c in parts for t in c] == list(range(70))
    assert [len(c) for c in chunks(tasks[:10], 32, 4)] == [3, 3, 3, 1]
    assert [len(c) for c in chunks(tasks[:10], 1, 4)] == [1] * 10


def test_real_recordings_together(shared_data, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Real logs of different shapes (an accelerometer alone, both sensors with a warning, a
    log with too few poses): the same rows and files together as one at a time."""
    folder = shared_data("ck-explorer")
    logs = [str(folder / "acc_log.csv"), str(folder / "acc_mag_log.csv")]
    logs.append(str(shared_data("imucal") / "example_ferraris_session.csv"))
    one = calibrate_many(logs, out=tmp_path / "one", jobs=1, group=1, created=CREATED)
    many = calibrate_many(logs, out=tmp_path / "many", jobs=1, created=CREATED)
    assert_same_rows(one.rows, many.rows)
    assert not many.rows[0]["error"] and not many.rows[1]["error"]
    assert many.rows[2]["error"]  # 14 poses in 6 orientations: refused, one row
    for row in one.rows[:2]:
        a = tmp_path / "one" / row["device"] / "cal.json"
        assert_same_file(a, tmp_path / "many" / row["device"] / "cal.json")


def test_large_logs_go_alone(tmp_path: Path) -> None:
    """A chunk's logs are in memory at once: the chunks hold a byte budget of logs."""
    paths = []
    for i, size in enumerate([10, 10, 70, 10, 10, 10]):
        path = tmp_path / f"{i}.csv"
        path.write_bytes(b"x" * size)
        paths.append(path)
    tasks = [Task(index=i, log=str(p), device=None) for i, p in enumerate(paths)]
    parts = chunks(tasks, 32, 1, budget=40)
    assert [[t.index for t in c] for c in parts] == [[0, 1], [2], [3, 4, 5]]
