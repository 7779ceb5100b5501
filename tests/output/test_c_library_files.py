"""The C library's two files are one (issue 35): written all or nothing, never mixed by two
exports at once, and a mixed pair does not build (``FIELDCAL_PAIR_ID``, ``#error``)."""

from __future__ import annotations

import errno
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from _cli import run, user_error
from _clib import CFLAGS, compiler

import fieldcal
from fieldcal import _files
from fieldcal.output.exports import export_files

PAIR = re.compile(rb"FIELDCAL_PAIR_ID (0x[0-9a-f]{8})u")


@pytest.fixture(scope="module")
def cals(tmp_path_factory):
    """Two calibrations (two cal.json files) whose libraries differ."""
    folder = tmp_path_factory.mktemp("pair")
    out = []
    for seed in (1, 2):
        session = fieldcal.simulate("paper", seed=seed, n_poses=12)
        cal = fieldcal.calibrate(session.accel, session.mag)
        path = folder / f"cal{seed}.json"
        path.write_text(cal.to_json(), encoding="utf-8")
        out.append((cal, path))
    return out


def _pair_ids(folder: Path) -> tuple[str, str]:
    h = PAIR.search((folder / "fieldcal_cal.h").read_bytes())
    c = re.search(
        rb"FIELDCAL_PAIR_ID != (0x[0-9a-f]{8})u", (folder / "fieldcal_cal.c").read_bytes()
    )
    assert h and c
    return h.group(1).decode(), c.group(1).decode()


def _compile(folder: Path, out: Path) -> subprocess.CompletedProcess[str]:
    cmd = [compiler(), *CFLAGS, "-c", str(folder / "fieldcal_cal.c"), "-o", str(out)]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def test_a_mixed_pair_does_not_build(cals, tmp_path):
    (cal_a, _), (cal_b, _) = cals
    a, b = export_files(cal_a, "c-library"), export_files(cal_b, "c-library")
    assert PAIR.search(a["fieldcal_cal.h"]).group(1) != PAIR.search(b["fieldcal_cal.h"]).group(1)
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    (mixed / "fieldcal_cal.c").write_bytes(a["fieldcal_cal.c"])
    (mixed / "fieldcal_cal.h").write_bytes(b["fieldcal_cal.h"])  # new header, old source
    out = _compile(mixed, tmp_path / "m.o")
    assert out.returncode != 0
    assert "#error" in out.stderr and "export both again" in out.stderr
    (mixed / "fieldcal_cal.h").write_bytes(a["fieldcal_cal.h"])
    assert _compile(mixed, tmp_path / "m.o").returncode == 0


def test_a_full_disk_leaves_the_old_pair_whole(cals, tmp_path, monkeypatch):
    (_, old_json), (_, new_json) = cals
    lib = tmp_path / "lib"
    run("export", old_json, "--format", "c-library", "-o", lib)
    before = {p.name: p.read_bytes() for p in lib.iterdir()}
    real, calls = _files._write, []

    def full_disk(temp: Path, data: bytes) -> None:
        calls.append(temp)
        if len(calls) >= 2:  # the first file fits, the second does not
            raise OSError(errno.ENOSPC, "No space left on device", str(temp))
        real(temp, data)

    monkeypatch.setattr(_files, "_write", full_disk)
    line = user_error(
        "export", new_json, "--format", "c-library", "-o", lib, "--force", match="No space left"
    )
    assert "no file was replaced" in line and "fieldcal_cal.c" in line
    assert len(calls) == 2
    assert {p.name: p.read_bytes() for p in lib.iterdir()} == before  # nothing new, nothing left
    monkeypatch.undo()
    run("export", new_json, "--format", "c-library", "-o", lib, "--force")
    h, c = _pair_ids(lib)
    assert h == c and (lib / "fieldcal_cal.h").read_bytes() != before["fieldcal_cal.h"]


def test_concurrent_exports_in_threads_never_mix_the_pair(cals, tmp_path):
    (cal_a, _), (cal_b, _) = cals
    texts = [export_files(cal_a, "c-library"), export_files(cal_b, "c-library")]
    lib = tmp_path / "lib"
    lib.mkdir()
    for _round in range(20):
        barrier = threading.Barrier(4)

        def export(files: dict[str, bytes], barrier: threading.Barrier = barrier) -> None:
            barrier.wait()
            _files.write_together({lib / name: data for name, data in files.items()})

        threads = [threading.Thread(target=export, args=(texts[i % 2],)) for i in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        got = {p.name: p.read_bytes() for p in lib.iterdir()}
        assert got in texts  # one export's pair, whole, and no temporary file left


def test_concurrent_exports_in_processes_never_mix_the_pair(cals, tmp_path):
    (_, a_json), (_, b_json) = cals
    lib = tmp_path / "lib"
    for _round in range(2):
        procs = [
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "fieldcal",
                    "export",
                    str(j),
                    "--format",
                    "c-library",
                    "-o",
                    str(lib),
                    "--force",
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
            )
            for j in (a_json, b_json, a_json)
        ]
        for p in procs:
            _, err = p.communicate(timeout=120)
            assert p.returncode == 0, err
        h, c = _pair_ids(lib)
        assert h == c
        assert sorted(p.name for p in lib.iterdir()) == ["fieldcal_cal.c", "fieldcal_cal.h"]
