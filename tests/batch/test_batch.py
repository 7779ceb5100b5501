"""``fieldcal batch`` and ``fieldcal.calibrate_many``: each log as ``calibrate`` would do it,
the same files (numbers to 1e-9) from every executor, failures as rows, worker deaths retried once,
resume, atomic files, the manifest checked before any work."""

from __future__ import annotations

import csv
import json
import math
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from _close import assert_same_file, assert_same_rows
from click.testing import CliRunner

import fieldcal
from fieldcal.batch import COLUMNS, calibrate_many, job
from fieldcal.batch.job import CRASH_ENV
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.pipeline import calibrate_log

CREATED = "2026-01-02T03:04:05+00:00"
#: The contract's columns (docs/batch.md); the rest are extra.
REQUIRED = (
    "device",
    "log",
    "verdict",
    "reasons",
    "dip_deg",
    "dip_std_deg",
    "gravity_norm",
    "field_strength",
    "accel.gain[0,0]",
    "accel.gain[0,0]_std",
    "mag.bias[2]",
    "mag.bias[2]_std",
    "accel_pose_noise",
    "mag_pose_noise",
    "rejected_poses",
    "tilt_deg",
    "heading_deg",
    "seconds",
    "fieldcal_version",
    "error",
)


#: Samples per pose: enough that Table 1's noise gives predictions within the default targets
#: (with 80, one of seeds 0-2 predicts a tilt error of 1.7° and warns, code ``accuracy``).
SAMPLES = 300


def _log(path: Path, seed: int, *, poses: int = 12, samples: int = SAMPLES, meta: str = "") -> Path:
    """A simulated session as the ``simulate`` command writes it (a pose column)."""
    s = fieldcal.simulate("paper", seed=seed, n_poses=poses, samples=(samples, samples))
    s.write_csv(path, preamble=meta)
    return path


@pytest.fixture
def logs(tmp_path):
    folder = tmp_path / "logs"
    folder.mkdir()
    return [_log(folder / f"unit{i}.csv", seed=i) for i in range(3)]


def test_each_log_is_calibrated_as_calibrate_does(logs, tmp_path):
    out = tmp_path / "out"
    result = calibrate_many([str(p) for p in logs], out=out, jobs=1, created=CREATED)
    assert [r["device"] for r in result.rows] == ["unit0", "unit1", "unit2"]
    for path, row in zip(logs, result.rows, strict=True):
        alone = calibrate_log(str(path.resolve()))
        written = fieldcal.Calibration.from_json((out / row["device"] / "cal.json").read_text())
        assert written == alone  # equality leaves out `created` only
        assert written.created == CREATED
        assert row["dip_deg"] == alone.dip_deg and row["dip_std_deg"] == alone.dip_std_deg
        assert row["accel.gain[1,2]"] == alone.accel.gain[1, 2]
        assert row["mag.bias[0]_std"] == alone.covariance.std("mag.bias[0]")
        assert row["mag_pose_noise"] == alone.mag.pose_noise_std
        assert row["verdict"] == alone.verdict.level and row["error"] == ""
        # and it is right: the simulated dip within 5 of its standard errors
        seed = int(path.stem[-1])
        truth = fieldcal.simulate("paper", seed=seed, n_poses=12, samples=(SAMPLES, SAMPLES))
        true_dip = truth.truth.dip_deg
        assert abs(row["dip_deg"] - true_dip) < 5 * row["dip_std_deg"]
    assert set(REQUIRED) <= set(COLUMNS)


def test_summary_files_hold_the_rows(logs, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow (the parquet extra) not installed")
    out = tmp_path / "out"
    result = calibrate_many(logs, out=out, jobs=1)
    table = pq.read_table(out / "summary.parquet")
    assert table.column_names == list(COLUMNS)
    assert table.column("dip_deg").to_pylist() == [r["dip_deg"] for r in result.rows]
    assert table.column("error").to_pylist() == ["", "", ""]
    with (out / "summary.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [float(r["accel.bias[1]"]) for r in rows] == [r["accel.bias[1]"] for r in result.rows]
    summary = result.summary  # a DataFrame, or a pyarrow Table without pandas
    assert list(getattr(summary, "column_names", None) or summary.columns) == list(COLUMNS)
    assert not list(out.rglob("*.part"))  # nothing half-written left behind


def test_every_executor_writes_the_same_files(logs, tmp_path):
    distributed = pytest.importorskip(
        "distributed", reason="dask.distributed (the dask extra) not installed"
    )
    runs = {}
    runs["sequential"] = calibrate_many(logs, out=tmp_path / "sequential", jobs=1, created=CREATED)
    runs["processes"] = calibrate_many(logs, out=tmp_path / "processes", jobs=2, created=CREATED)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        runs["dask"] = calibrate_many(
            logs, out=tmp_path / "dask", scheduler=cluster.scheduler_address, created=CREATED
        )
    for name in ("processes", "dask"):
        assert_same_rows(runs["sequential"].rows, runs[name].rows)
        for device in ("unit0", "unit1", "unit2"):
            assert_same_file(
                tmp_path / "sequential" / device / "cal.json", tmp_path / name / device / "cal.json"
            )
        assert runs[name].calibrations.keys() == runs["sequential"].calibrations.keys()


def test_a_bad_log_is_a_failed_row_and_the_batch_goes_on(logs, tmp_path):
    corrupt = tmp_path / "logs" / "corrupt.csv"
    corrupt.write_bytes(b"ax,ay\n\x00\x01garbage\n")
    hopeless = _log(tmp_path / "logs" / "hopeless.csv", seed=9, poses=3)
    result = calibrate_many([corrupt, hopeless, *logs], out=tmp_path / "out", jobs=1)
    rows = {r["device"]: r for r in result.rows}
    for name in ("corrupt", "hopeless"):
        assert rows[name]["verdict"] == "fail"
        assert rows[name]["error"] and "\n" not in rows[name]["error"]
        assert math.isnan(rows[name]["dip_deg"])
        assert not (tmp_path / "out" / name / "cal.json").exists()
    assert "3 pose(s) found" in rows["hopeless"]["error"]
    assert [r["verdict"] for r in result.rows[2:]] == ["pass"] * 3
    assert {r["device"] for r in result.failed} == {"corrupt", "hopeless"}


def test_a_dying_worker_is_retried_once(tmp_path, monkeypatch):
    folder = tmp_path / "logs"
    folder.mkdir()
    paths = [_log(folder / f"u{i}.csv", seed=i) for i in range(4)]
    # u1 kills its worker on the first attempt only, u2 every time
    monkeypatch.setenv(CRASH_ENV, "u1.csv:once,u2.csv")
    result = calibrate_many(paths, out=tmp_path / "out", jobs=2)
    verdicts = {r["device"]: (r["verdict"], r["error"]) for r in result.rows}
    assert verdicts["u0"] == ("pass", "") and verdicts["u3"] == ("pass", "")
    assert verdicts["u1"] == ("pass", "")  # the retry succeeded
    assert verdicts["u2"][0] == "fail" and "died twice" in verdicts["u2"][1]
    assert (folder / "u1.csv.crashed").exists()


def test_a_dying_dask_worker_is_retried(tmp_path, monkeypatch):
    """On a cluster the scheduler reschedules the log of a worker that died (the nanny starts
    a new worker); with ``allowed-failures`` 1, once: a log that kills its worker every time
    then gets a failed row and the batch goes on."""
    distributed = pytest.importorskip(
        "distributed", reason="dask.distributed (the dask extra) not installed"
    )
    dask = pytest.importorskip("dask", reason="dask (the dask extra) not installed")
    folder = tmp_path / "logs"
    folder.mkdir()
    paths = [_log(folder / f"d{i}.csv", seed=i) for i in range(3)]
    monkeypatch.setenv(CRASH_ENV, "d1.csv:once,d2.csv")  # before the workers start
    with (
        # one log per worker at a time: a death then counts against the log that caused it only
        dask.config.set(
            {
                "distributed.scheduler.allowed-failures": 1,
                "distributed.scheduler.worker-saturation": 1.0,
            }
        ),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
    ):
        result = calibrate_many(paths, out=tmp_path / "out", scheduler=cluster.scheduler_address)
    verdicts = {r["device"]: (r["verdict"], r["error"]) for r in result.rows}
    assert verdicts["d0"] == ("pass", "") and verdicts["d1"] == ("pass", "")
    assert verdicts["d2"][0] == "fail" and "its workers died" in verdicts["d2"][1]
    assert (tmp_path / "out" / "d1" / "cal.json").exists()


def test_resume_keeps_done_logs_and_redoes_the_rest(logs, tmp_path):
    out = tmp_path / "out"
    first = calibrate_many(logs, out=out, jobs=1)
    # a batch killed after unit1's cal.json but before its row: unit1 is not done
    (out / "unit1" / "row.json").unlink()
    with pytest.raises(InputError, match="--resume"):
        calibrate_many(logs, out=out, jobs=1)
    again = calibrate_many(logs, out=out, jobs=1, resume=True)
    assert again.resumed == 2
    # the kept rows are the earlier ones, wall time and all; unit1 was redone
    assert again.rows[0] == first.rows[0] and again.rows[2] == first.rows[2]
    assert again.rows[1]["seconds"] != first.rows[1]["seconds"]
    assert_same_rows(first.rows, again.rows)
    assert set(again.calibrations) == {r["log"] for r in first.rows}


def test_an_interrupted_batch_loses_nothing(logs, tmp_path):
    out = tmp_path / "out"
    seen = []

    def stop_after_one(row):
        seen.append(row["device"])
        if len(seen) == 1:
            raise KeyboardInterrupt

    # group=1: one log at a time (logs calibrated together finish together)
    with pytest.raises(KeyboardInterrupt):
        calibrate_many(logs, out=out, jobs=1, on_result=stop_after_one, group=1)
    with (out / "summary.csv").open() as f:
        assert [r["device"] for r in csv.DictReader(f)] == ["unit0"]
    assert not (out / "unit1").exists() and not list(out.rglob("*.part"))
    done = calibrate_many(logs, out=out, jobs=1, resume=True)
    assert done.resumed == 1 and [r["verdict"] for r in done.rows] == ["pass"] * 3


def test_manifest_devices_and_per_log_options(logs, tmp_path):
    manifest = tmp_path / "logs" / "manifest.csv"
    manifest.write_text(
        f"log,device,method,no-robust\nunit0.csv,BOARD-7,ellipsoid,yes\n{logs[1]},BOARD-8,,\n"
    )
    result = calibrate_many(manifest, out=tmp_path / "out", jobs=1, created=CREATED)
    assert [r["device"] for r in result.rows] == ["BOARD-7", "BOARD-8"]
    assert [r["method"] for r in result.rows] == ["ellipsoid", "mle"]
    written = fieldcal.Calibration.from_json((tmp_path / "out/BOARD-7/cal.json").read_text())
    assert written == calibrate_log(logs[0], method="ellipsoid", robust=False, cut_unsteady=False)
    assert written.options["robust"] is False


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("log,device,rate\nunit0.csv,A,fast\n", "row 2, column rate: 'fast'"),
        ("log,colour\nunit0.csv,red\n", "unknown column 'colour'"),
        ("log,device\n,A\n", "row 2, column log: empty"),
        ("log,device\nunit0.csv,A B/C\n", "row 2, column device"),
        ("log,device\nunit0.csv,A\nunit1.csv,A,x\n", "row 3: 3 fields for 2 columns"),
        ("log,device\nunit0.csv,A\nunit1.csv,A\n", "both be filed as device 'A'"),
        ("log,method\nunit0.csv,best\n", "column method: 'best'"),
    ],
)
def test_a_malformed_manifest_is_one_line_before_any_work(logs, tmp_path, text, message):
    manifest = tmp_path / "logs" / "m.csv"
    manifest.write_text(text)
    with pytest.raises(InputError, match=message.replace("(", r"\(")) as caught:
        calibrate_many(manifest, out=tmp_path / "out", jobs=1)
    assert "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()


def test_two_logs_of_one_device(logs, tmp_path):
    other = tmp_path / "other"
    other.mkdir()
    twin = _log(other / "unit0.csv", seed=5)
    with pytest.raises(InputError, match=f"{logs[0]} and {twin}.*manifest"):
        calibrate_many([logs[0], twin], out=tmp_path / "out", jobs=1)


def test_the_device_the_log_names(tmp_path):
    folder = tmp_path / "logs"
    folder.mkdir()
    a = _log(folder / "a.csv", seed=1, meta="# device: IMU 0042\n")
    b = _log(folder / "b.csv", seed=2, meta="# device: IMU 0042\n")
    result = calibrate_many([a, b], out=tmp_path / "out", jobs=1)
    first, second = result.rows
    assert first["device"] == "IMU_0042" and first["error"] == ""
    written = fieldcal.Calibration.from_json((tmp_path / "out/IMU_0042/cal.json").read_text())
    assert written.options["log"] == str(a)
    # the second log of that device does not replace the first one's files
    assert second["verdict"] == "fail" and str(a) in second["error"]


def test_cli_batch(logs, tmp_path):
    out = tmp_path / "out"
    bad = tmp_path / "logs" / "bad.csv"
    bad.write_text("nothing,here\n")
    runner = CliRunner()
    good = runner.invoke(
        cli, ["batch", str(tmp_path / "logs" / "unit*.csv"), "--out", str(out), "--export",
              "c-header", "-j", "1"]
    )  # fmt: skip
    assert good.exit_code == 0, good.output
    assert "3 pass" in good.output
    exported = runner.invoke(
        cli, ["export", str(out / "unit0" / "cal.json"), "--format", "c-header"]
    )
    assert (out / "unit0" / "cal.h").read_text() == exported.output
    again = runner.invoke(cli, ["batch", str(logs[0]), "--out", str(out)])
    assert again.exit_code == 2 and "--resume" in again.output
    failing = runner.invoke(cli, ["batch", str(bad), *map(str, logs), "--out", str(out), "--force"])
    assert failing.exit_code == 3
    assert f"bad ({bad})" in failing.output
    usage = runner.invoke(cli, ["batch", str(tmp_path / "missing.csv"), "--out", str(out)])
    assert usage.exit_code == 2 and "no such log" in usage.output
    with (out / "summary.csv").open() as f:
        header = next(csv.reader(f))
    assert set(REQUIRED) <= set(header)
    row = json.loads((out / "unit0" / "row.json").read_text())
    assert row["device"] == "unit0" and row["error"] == ""


def test_a_url_is_read_by_the_worker(logs, tmp_path):
    pytest.importorskip("fsspec", reason="fsspec (with the dask extra) not installed")
    url = f"file://{logs[0]}"
    pattern = f"file://{logs[0].parent}/unit[01].csv"
    result = calibrate_many([url, pattern], out=tmp_path / "out", jobs=1)
    assert [r["log"] for r in result.rows] == [url, f"file://{logs[1]}"]
    assert [r["verdict"] for r in result.rows] == ["pass", "pass"]
    from_url = result.calibrations[url]
    assert from_url.options["log"] == url
    assert from_url.dip_deg == calibrate_log(logs[0]).dip_deg


def test_calibrate_options_flow_to_every_log(logs, tmp_path):
    """Options of ``calibrate`` reach each log's calibration through the command line: here
    the World Magnetic Model reference, whose dip lands in the summary beside the fitted one."""
    from fieldcal.reference import expected_field

    out = tmp_path / "out"
    result = CliRunner().invoke(
        cli, ["batch", *map(str, logs[:2]), "--out", str(out), "-j", "1", "--location",
              "-33.9,151.2", "--date", "2026-06-01"]
    )  # fmt: skip
    assert result.exit_code in (0, 3), result.output
    want = expected_field((-33.9, 151.2), "2026-06-01").dip_deg
    with (out / "summary.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [float(r["reference_dip_deg"]) for r in rows] == pytest.approx([want, want])
    doc = json.loads((out / rows[0]["device"] / "cal.json").read_text())
    assert doc["reference"]["dip_deg"] == pytest.approx(want)
    bad = CliRunner().invoke(cli, ["batch", str(logs[0]), "--out", str(tmp_path / "x"),
                                   "--location", "95,0"])  # fmt: skip
    assert bad.exit_code == 2 and "latitude 95" in bad.output
    assert not (tmp_path / "x").exists()  # refused before any work


def test_reason_codes_column_holds_the_verdicts_codes(logs, tmp_path):
    result = calibrate_many(logs, out=tmp_path / "out", jobs=1)
    for row in result.rows:
        cal = result.calibrations[row["log"]]
        assert row["reason_codes"] == ",".join(cal.verdict.codes)
        assert row["reasons"] == " | ".join(r.text for r in cal.verdict.reasons)
    with (tmp_path / "out" / "summary.csv").open() as f:
        assert "reason_codes" in next(csv.reader(f))


def test_a_failed_export_is_its_own_column_and_keeps_the_numbers(logs, tmp_path, monkeypatch):
    real = job.export_formats.export_bytes

    def refuse(cal, fmt):
        if fmt == "px4":
            raise InputError("px4 needs the field in gauss: give --field-strength")
        return real(cal, fmt)

    monkeypatch.setattr(job.export_formats, "export_bytes", refuse)
    result = calibrate_many(logs[:2], out=tmp_path / "out", jobs=1, exports=("px4", "c-header"))
    for row in result.rows:
        assert row["error"] == "" and row["verdict"] in ("pass", "warn")
        assert row["export_error"] == "px4: px4 needs the field in gauss: give --field-strength"
        assert not math.isnan(row["dip_deg"]) and not math.isnan(row["accel.gain[0,0]"])
        folder = tmp_path / "out" / row["device"]
        assert (folder / "cal.json").is_file() and (folder / "cal.h").is_file()
    assert len(result.failed) == 2  # an export asked for and not written counts


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("bogus", "must be an address like tcp://HOST:8786"),
        ("foo://x:1", "unknown scheme 'foo'"),
        ("inproc://nowhere", "no Dask scheduler in this process"),
        ("tcp://127.0.0.1:{free}", "could not connect to the Dask scheduler"),
    ],
)
def test_a_bad_scheduler_is_one_line_and_no_client_is_left(logs, tmp_path, address, message):
    """Refused before a Dask client exists: a client that failed to connect waited twice its
    timeout (40 s) when collected and printed a ``Client.__del__`` traceback after the error."""
    pytest.importorskip("distributed", reason="dask.distributed (the dask extra) not installed")
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        free = probe.getsockname()[1]
    address = address.format(free=free)
    with pytest.raises(InputError, match=message):
        calibrate_many(logs[:1], out=tmp_path / "lib", scheduler=address)
    result = subprocess.run(
        [sys.executable, "-m", "fieldcal", "batch", str(logs[0]), "--out", str(tmp_path / "o"),
         "--scheduler", address],
        capture_output=True, text=True, timeout=60,  # a guard: the old path took 86 s
    )  # fmt: skip
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith("Error: ") and message in lines[0]
    assert "Traceback" not in result.stderr and "__del__" not in result.stderr
