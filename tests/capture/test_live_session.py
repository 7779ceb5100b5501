"""``fieldcal capture``: live still detection equal to the offline one, replays, the serial
path on a pseudo-terminal, a simulated user following the printed suggestions, disconnects,
garbage, and ``fieldcal plan``."""

from __future__ import annotations

import io
import json
import re
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest
from _device import PtyDevice, needs_serial
from _words import parse_words
from click.testing import CliRunner
from rich.console import Console
from scipy.spatial.transform import Rotation

import fieldcal
from fieldcal.capture.feeds import open_source
from fieldcal.capture.live_session import CaptureOptions, CaptureSession, run_capture
from fieldcal.capture.view import MAP_COLUMNS, LiveView, coverage_map
from fieldcal.cli import cli
from fieldcal.logs.live import LiveDetector
from fieldcal.logs.log import load_log
from fieldcal.logs.pose_finding import poses_from_log
from fieldcal.logs.stream import LineParser
from fieldcal.simulation.continuous import simulate_continuous


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A simulated continuous log (15 poses, 100 Hz, with a time column) as a CSV file."""
    sim = simulate_continuous("paper", seed=5)
    path = tmp_path_factory.mktemp("log") / "session.csv"
    sim.write_csv(str(path))
    return path, sim


def _ranges(poses):
    return [(int(e["start"]), int(e["stop"])) for e in poses.entries]


def test_live_detection_settles_the_offline_poses(recorded):
    """Fed in pieces, the live detector settles the offline detector's poses one after the
    other, in order, each within the trim of the offline rows (the threshold comes from the
    noise floor of the samples so far, so an edge may move by a sample while the log grows;
    the trim is what the detector itself treats as uncertain at each end), and its final run
    on every sample is the offline answer exactly."""
    path, _ = recorded
    offline = poses_from_log(load_log(path))
    expected = _ranges(offline)
    trim = offline.detection.trim
    lines = path.read_text().splitlines()
    parser = LineParser()
    # no wall-clock throttle (load=0): which pieces run must not depend on the machine's speed
    detector = LiveDetector(load=0.0)
    settled_counts = []
    step = 137  # lines per piece: no relation to the window or the poses
    for k in range(0, len(lines), step):
        for j, line in enumerate(lines[k : k + step]):
            parser.feed(line, (k + j) * 0.01)
        log = load_log(parser.table())
        if not detector.due(log.n, log.rate):
            continue
        state = detector.update(log)
        if state.poses is None:
            continue
        settled = _ranges(state.poses)[: state.settled]
        assert len(settled) <= len(expected)
        for (a, b), (c, d) in zip(settled, expected, strict=False):
            assert abs(a - c) <= trim and abs(b - d) <= trim
        settled_counts.append(len(settled))
    assert settled_counts == sorted(settled_counts)  # settled poses are never taken back
    # at the end every pose but the last is settled (the device still rests there), and the
    # last, held for seconds, is captured
    last = detector.update(load_log(parser.table()))
    assert (last.settled, last.captured) == (len(expected) - 1, len(expected))
    final = detector.update(load_log(parser.table()), final=True)
    assert final.poses is not None
    assert _ranges(final.poses) == expected


def _plain_run(args, input=None):
    result = CliRunner().invoke(cli, args, input=input)
    return result, result.output.splitlines()


def test_replay_through_from_equals_calibrate(recorded, tmp_path):
    """``capture --from FILE`` writes the calibration ``calibrate`` writes for that file, its
    raw log calibrates to the same numbers again, and every pose is announced."""
    path, sim = recorded
    out = tmp_path / "cap"
    result, lines = _plain_run(["capture", "--from", str(path), "--plain", "--out", str(out)])
    assert result.exit_code == 0, result.output
    direct = tmp_path / "direct.json"
    assert CliRunner().invoke(cli, ["calibrate", str(path), "-o", str(direct), "-q"]).exit_code == 0
    captured = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    offline = fieldcal.Calibration.from_json(direct.read_text())
    for sensor in ("accel", "mag"):
        np.testing.assert_array_equal(captured.sensor(sensor).gain, offline.sensor(sensor).gain)
    again = fieldcal.calibrate_log(out / "log.csv")
    np.testing.assert_allclose(again.mag.gain, offline.mag.gain, rtol=1e-9)
    announced = [line for line in lines if line.startswith("pose ") and "captured" in line]
    assert len(announced) == len(sim.segments)
    assert any(line.startswith("next pose: ") for line in lines)
    assert any(line.startswith("calibration: ") for line in lines)
    document = json.loads((out / "cal.json").read_text())
    assert document["capture"]["rows"] == len(path.read_text().splitlines()) - 1


def test_standard_input_and_garbage(recorded, tmp_path):
    """``--from -`` reads a pipe; partial lines, debug prints and binary noise are counted and
    kept in log.csv as comments, never fatal."""
    path, _ = recorded
    text = path.read_text()
    header, *rows = text.splitlines()
    noisy = ["3,0.1,", "MPU9250 ready", header, *rows[:2000], "\x00\x01garbage ]]", *rows[2000:]]
    out = tmp_path / "cap"
    result, _ = _plain_run(
        ["capture", "--from", "-", "--plain", "--out", str(out)], input="\n".join(noisy) + "\n"
    )
    assert result.exit_code == 0, result.output
    document = json.loads((out / "cal.json").read_text())
    assert document["capture"]["rows"] == len(rows)
    assert sum(document["capture"]["skipped"].values()) == 3
    comments = [line for line in (out / "log.csv").read_text().splitlines() if line.startswith("#")]
    assert len(comments) == 3


def test_only_garbage_is_an_error_that_keeps_the_log(tmp_path):
    out = tmp_path / "cap"
    result = CliRunner().invoke(
        cli, ["capture", "--from", "-", "--plain", "--out", str(out)], input="hello\nworld\n"
    )
    assert result.exit_code == 2
    error = result.stderr.strip().splitlines()
    assert len(error) == 1 and error[0].startswith("Error: no data lines"), result.stderr
    assert "--columns" in error[0]  # lines before any header: the way out is named
    assert (out / "log.csv").read_text().count("# skipped") == 2
    assert not (out / "cal.json").exists()


def test_options_are_checked_before_reading(tmp_path):
    runner = CliRunner()
    for args, message in (
        (["capture"], "--port"),
        (["capture", "--port", "/dev/x", "--from", "-"], "--port"),
        (["capture", "--from", "-", "--follow"], "--follow"),
    ):
        result = runner.invoke(cli, [*args, "--out", str(tmp_path / "x")])
        assert result.exit_code == 2 and message in result.output, result.output
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "cal.json").write_text("{}")
    result = runner.invoke(cli, ["capture", "--from", "-", "--out", str(tmp_path / "taken")])
    assert result.exit_code == 2 and "--force" in result.output
    # a bad --location is refused before the folder is made or anything read
    result = runner.invoke(
        cli, ["capture", "--from", "-", "--location", "95,0", "--out", str(tmp_path / "new")]
    )
    assert result.exit_code == 2 and "latitude 95" in result.output
    assert not (tmp_path / "new").exists()


def test_capture_with_a_location_writes_the_reference(recorded, tmp_path):
    path, _ = recorded
    out = tmp_path / "cap"
    args = ["capture", "--from", str(path), "--plain", "--out", str(out)]
    result, _ = _plain_run([*args, "--location", "52.0,4.37", "--date", "2026-06-01"])
    assert result.exit_code == 0, result.output
    document = json.loads((out / "cal.json").read_text())
    assert document["reference"]["model"] == "WMM2025"
    assert document["options"]["mag_handedness"] in ("reference", "stated")


def test_plan_command(recorded, tmp_path):
    path, _ = recorded
    cal_path = tmp_path / "cal.json"
    CliRunner().invoke(cli, ["calibrate", str(path), "-o", str(cal_path), "-q"])
    result = CliRunner().invoke(cli, ["plan", str(cal_path), "-n", "3"])
    assert result.exit_code == 0, result.output
    steps = [line for line in result.output.splitlines() if re.match(r"^\d\. ", line)]
    assert len(steps) == 3
    planned = fieldcal.plan_poses(fieldcal.Calibration.from_json(cal_path.read_text()), 3)
    assert [s[3:] for s in steps] == [p.words for p in planned]
    data = json.loads(CliRunner().invoke(cli, ["plan", str(cal_path), "-n", "2", "--json"]).output)
    assert len(data) == 2 and data[0]["words"] == planned[0].words


def _capture(args):
    """``fieldcal capture`` as a user runs it, in its own process; its output lines are
    collected as they come."""
    process = subprocess.Popen(
        [sys.executable, "-m", "fieldcal", "capture", "--plain", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        bufsize=1,
    )
    lines: list[str] = []
    said = threading.Condition()

    def collect():
        assert process.stdout is not None
        for line in process.stdout:
            with said:
                lines.append(line.rstrip("\n"))
                said.notify_all()

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()
    process.reader = reader  # joined by _finish: the lines are read by this thread alone
    return process, lines, said


def _wait_for(lines, said, predicate, timeout=30.0):
    with said:
        assert said.wait_for(lambda: predicate(lines), timeout), lines[-5:]


def _finish(process, timeout=60):
    process.wait(timeout=timeout)
    process.reader.join(timeout=10)
    assert process.stderr is not None
    return process.returncode, process.stderr.read()


def _announced(lines):
    """The pose numbers announced, in order: counted 1, 2, 3, ... (each said once)."""
    numbers = [int(m[1]) for x in lines if (m := re.match(r"pose (\d+) captured", x))]
    assert numbers == list(range(1, len(numbers) + 1)), numbers
    return numbers


def _paper_rotations(seed):
    return fieldcal.simulate("paper", seed=seed).drawn["rotations"]


@needs_serial
def test_a_device_on_a_serial_port(tmp_path):
    """A board on a (pseudo-)serial port streams a continuous session as fast as it can, with
    garbage, then is unplugged: every pose is announced, the result is the truth within its
    error bars, and it equals ``calibrate`` on the raw log written."""
    out = tmp_path / "cap"
    with PtyDevice(_paper_rotations(11), seed=11, garbage=True, end="disconnect") as device:
        process, lines, said = _capture(["--port", device.port, "--out", str(out)])
        _wait_for(lines, said, lambda seen: any(x.startswith("reading ") for x in seen))
        device.start()
        code, stderr = _finish(process)
    assert code in (0, 3), stderr
    assert len(_announced(lines)) == len(device.pose_rows) == 15, "\n".join(lines)
    done = [x for x in lines if x.startswith("done: ")]
    assert len(done) == 1 and done[0].startswith("done: disconnected"), done
    cal = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    truth = device.truth
    for sensor in ("accel", "mag"):
        est, std = cal.sensor(sensor), cal.sensor(sensor)
        z_gain = (est.gain - truth.sensor(sensor).gain) / std.gain_std
        z_bias = (est.bias - truth.sensor(sensor).bias) / std.bias_std
        assert np.max(np.abs(z_gain)) < 5 and np.max(np.abs(z_bias)) < 5
    again = fieldcal.calibrate_log(out / "log.csv", split_on_reset=True)
    np.testing.assert_allclose(again.mag.gain, cal.mag.gain, rtol=1e-9)
    document = json.loads((out / "cal.json").read_text())
    assert sum(document["capture"]["skipped"].values()) >= 4  # the garbage, counted


@needs_serial
def test_an_unplugged_board_keeps_every_line(tmp_path):
    """Unplugged after five poses: the capture ends, says why in one line, and log.csv holds
    every line the board wrote, in order."""
    out = tmp_path / "cap"
    with PtyDevice(_paper_rotations(12), seed=12, disconnect_after=2200) as device:
        process, lines, said = _capture(["--port", device.port, "--out", str(out)])
        _wait_for(lines, said, lambda seen: any(x.startswith("reading ") for x in seen))
        device.start()
        code, stderr = _finish(process)
    # five poses and the motion between: calibrate's mode on log.csv (poses='auto' takes the
    # motion when the rests are too few), or its one-line refusal naming what was kept
    if code == 2:
        assert stderr.startswith("Error: ") and stderr.count("\n") == 1, stderr
        assert "log.csv" in stderr
    else:
        assert code in (0, 3) and any("log.csv" in x for x in lines), (code, stderr)
    assert any(x.startswith("done: disconnected") for x in lines)
    recorded = [x for x in (out / "log.csv").read_text().splitlines() if not x.startswith("#")]
    written = device.lines()
    assert len(recorded) == len(written) == 2200
    # each line as written, its arrival time appended
    assert all(r.rsplit(",", 1)[0] == w for r, w in zip(recorded, written, strict=True))


@needs_serial
def test_a_user_who_follows_the_suggestions(tmp_path):
    """A simulated user reads each printed suggestion, turns the board that way (words parsed
    back into a rotation by the test's own parser, held within a few degrees) and the capture
    stops by itself once the verdict is pass and the targets are met."""
    out = tmp_path / "cap"
    rng = np.random.default_rng(7)
    followed: list[str] = []

    def next_pose(i):
        # a person takes the next pose once told the last one was captured, following the
        # suggestion printed after that (the same step prints both)
        if i >= 30 or process.poll() is not None:
            return None

        def told(seen):
            at = [k for k, x in enumerate(seen) if re.match(r"pose \d+ captured", x)]
            if len(at) < i:
                return False
            after = at[i - 1] if i else -1
            return any(x.startswith("next pose: ") for x in seen[after + 1 :])

        try:
            _wait_for(lines, said, told, 20)
        except AssertionError:
            return None
        with said:
            words = [x[len("next pose: ") :] for x in lines if x.startswith("next pose: ")][-1]
        followed.append(words)
        _, rotation = parse_words(words)
        if rotation is None:
            raise AssertionError(f"a joint capture must say the heading: {words!r}")
        wobble = Rotation.from_rotvec(rng.normal(scale=np.radians(2.0), size=3)).as_matrix()
        return wobble @ rotation

    with PtyDevice(next_pose, seed=13, hold=3.0, end="disconnect") as device:
        process, lines, said = _capture(
            [
                "--port",
                device.port,
                "--out",
                str(out),
                "--until",
                "pass",
                "--target-heading",
                "1",
                "--target-tilt",
                "0.5",
            ]
        )
        _wait_for(lines, said, lambda seen: any(x.startswith("reading ") for x in seen))
        device.start()
        code, stderr = _finish(process, timeout=120)
    assert code == 0, stderr + "\n".join(lines)
    assert "done: the verdict is pass and the targets are met" in lines
    _announced(lines)
    cal = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    assert cal.verdict.level == "pass"
    assert cal.accuracy.heading_deg <= 1.0 and cal.accuracy.tilt_deg <= 0.5
    # the suggestions differ from one another: the planner moves the user around
    assert len(set(followed)) >= 0.8 * len(followed), "\n".join(followed)
    assert 8 <= len(followed) <= 25


def test_the_live_view_shows_the_session_literally(recorded, tmp_path):
    """The live view, drawn after a replay: the poses, the coverage with one mark per pose
    direction, the verdict and the next pose; text from the stream or the library is shown
    as written, never read as markup."""
    path, sim = recorded
    console = Console(file=io.StringIO(), width=120, record=True)
    view = LiveView(console, "session.csv")
    session = CaptureSession(CaptureOptions(), tmp_path / "cap", view.event)
    run_capture(open_source(path=str(path)), session)
    session.message = "[red]not markup[/red]"
    console.print(view.render(session))
    text = console.export_text()
    assert f"poses ({len(sim.segments)})" in text
    assert "[red]not markup[/red]" in text
    assert "calibration: PASS" in text and "next pose" in text
    # the verdict's level and codes, as the CLI's first line gives them (Verdict.summary)
    verdict = session.run.calibration.verdict
    assert f"calibration: {verdict.summary} from" in " ".join(text.split())
    rows = [line for line in text.splitlines() if "●" in line or "+Z" in line]
    marks = sum(line.count("●") + line.count("✗") for line in rows)
    # poses closer than one cell share it: at most one mark per pose, most of them apart
    assert 0.6 * len(sim.segments) <= marks <= len(sim.segments)


def test_coverage_map_puts_down_directions_where_they_belong():
    up, down, east = np.array([0.0, 0, -1]), np.array([0.0, 0, 1]), np.array([0.0, 1, 0])
    rows = coverage_map([(down, False), (up, True)], now=east, target=None)
    assert rows[0].startswith(" +Z down") and "●" in rows[0]
    assert rows[-1].startswith("   +Z up") and "✗" in rows[-1]
    middle = rows[len(rows) // 2]
    assert middle.index("+", 9) == 9 + MAP_COLUMNS // 4  # azimuth 90° (+Y), a quarter across


def test_bare_numbers_with_columns(recorded, tmp_path):
    """Bare-number lines named by --columns give the calibration of the same log with its
    header."""
    path, _ = recorded
    _, *rows = path.read_text().splitlines()
    out = tmp_path / "cap"
    result, _ = _plain_run(
        [
            "capture",
            "--from",
            "-",
            "--plain",
            "--out",
            str(out),
            "--columns",
            "t,ax,ay,az,gx,gy,gz,mx,my,mz",
        ],
        input="\n".join(rows) + "\n",
    )
    assert result.exit_code == 0, result.output
    bare = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    direct = fieldcal.calibrate_log(path)
    np.testing.assert_allclose(bare.mag.gain, direct.mag.gain, rtol=1e-12)


def test_following_a_growing_file_until_pass(recorded, tmp_path):
    """--follow reads a file as a logger appends to it, and --until pass ends the capture by
    itself before the file is complete, with a calibration meeting the targets."""
    path, _ = recorded
    lines = path.read_text().splitlines(keepends=True)
    growing = tmp_path / "growing.csv"
    growing.write_text(lines[0])
    stop = threading.Event()

    def logger():
        with growing.open("a") as f:
            for k in range(1, len(lines), 200):
                if stop.wait(0.08):  # about 4 s for the whole log: time for the live fits
                    return
                f.write("".join(lines[k : k + 200]))
                f.flush()

    writer = threading.Thread(target=logger, daemon=True)
    out = tmp_path / "cap"
    process, seen, said = _capture(
        [
            "--from",
            str(growing),
            "--follow",
            "--until",
            "pass",
            "--out",
            str(out),
            "--target-heading",
            "2",
            "--target-tilt",
            "1",
        ]
    )
    _wait_for(seen, said, lambda s: any(x.startswith("reading ") for x in s))
    writer.start()
    code, stderr = _finish(process)
    stop.set()
    assert code == 0, stderr
    assert "done: the verdict is pass and the targets are met" in seen
    cal = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    assert cal.accuracy.heading_deg <= 2 and cal.accuracy.tilt_deg <= 1
    assert json.loads((out / "cal.json").read_text())["capture"]["rows"] < len(lines) - 1


@needs_serial
def test_ctrl_c_writes_what_was_received(tmp_path):
    """Ctrl-C in the middle of a paced stream: the capture stops at once, says so, and keeps
    every line received with the calibration of the poses so far."""
    out = tmp_path / "cap"
    with PtyDevice(_paper_rotations(14), seed=14, speed=20.0) as device:
        process, lines, said = _capture(["--port", device.port, "--out", str(out)])
        _wait_for(lines, said, lambda seen: any(x.startswith("reading ") for x in seen))
        device.start()
        _wait_for(lines, said, lambda seen: sum("captured" in x for x in seen) >= 9, 60)
        process.send_signal(signal.SIGINT)
        code, stderr = _finish(process)
        written = device.rows
    assert code in (0, 3), stderr
    assert "done: stopped by the user (Ctrl-C)" in lines
    assert len(_announced(lines)) >= 9
    recorded = [x for x in (out / "log.csv").read_text().splitlines() if not x.startswith("#")]
    assert 0 < len(recorded) - 1 <= written  # every row received (the header aside)
    cal = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    assert len(cal.poses) >= 9, "\n".join(lines)


def test_a_replay_without_time_at_a_stated_rate_equals_calibrate(recorded, tmp_path):
    """A log with no time column replayed at full speed with --rate: the arrival times (as
    fast as the disk) are recorded but not used, so the result is calibrate's at that rate."""
    path, _ = recorded
    header, *rows = path.read_text().splitlines()
    names = header.split(",")
    keep = [k for k, n in enumerate(names) if n != "t"]
    timeless = tmp_path / "timeless.csv"
    lines = [",".join(names[k] for k in keep)]
    lines += [",".join(r.split(",")[k] for k in keep) for r in rows]
    timeless.write_text("\n".join(lines) + "\n")
    out = tmp_path / "cap"
    result, said = _plain_run(
        ["capture", "--from", str(timeless), "--plain", "--out", str(out), "--rate", "100"]
    )
    assert result.exit_code == 0, result.output
    assert [line for line in said if line.startswith("warning")] == []
    captured = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    direct = fieldcal.calibrate_log(timeless, rate=100.0)
    np.testing.assert_array_equal(captured.mag.gain, direct.mag.gain)


def test_a_board_that_printed_its_header_before_the_port_opened(recorded, tmp_path):
    """Bare lines of 10 numbers, from mid-motion: read as t, accelerometer, gyroscope,
    magnetometer (said in a note), calibrated, and the recorded log.csv reads back to the same
    calibration; 9 numbers in another order are refused, saying why."""
    path, _ = recorded
    header, *rows = path.read_text().splitlines()
    assert header == "t,ax,ay,az,gx,gy,gz,mx,my,mz"
    out = tmp_path / "cap"
    result, lines = _plain_run(
        ["capture", "--from", "-", "--plain", "--out", str(out)], input="\n".join(rows[300:])
    )
    assert result.exit_code in (0, 3), result.output
    assert any("10 numbers per line read as t,ax,ay,az,gx,gy,gz,mx,my,mz" in x for x in lines)
    captured = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    again = fieldcal.calibrate_log(out / "log.csv")
    np.testing.assert_allclose(again.mag.gain, captured.mag.gain, rtol=1e-9)
    swapped = [",".join(r.split(",")[i] for i in (1, 2, 3, 7, 8, 9, 4, 5, 6)) for r in rows[300:]]
    result = CliRunner().invoke(
        cli, ["capture", "--from", "-", "--plain", "--out", str(tmp_path / "bad")],
        input="\n".join(swapped),
    )  # fmt: skip
    assert result.exit_code == 2
    error = result.stderr.strip().splitlines()
    assert len(error) == 1 and "the last three read near zero at rest" in error[0]
    assert "--columns" in error[0]
