"""Which logs a batch runs (fieldcal.batch.manifest), without running them: a manifest's rows
with paths joined to its folder and options parsed, globs in order and each log once, device
ids as folder names; one-line refusals naming the row."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldcal.batch.manifest import (
    LogSpec,
    device_id,
    expand_logs,
    fallback_device,
    read_manifest,
)
from fieldcal.errors import InputError


def _touch(folder: Path, *names: str) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / n for n in names]
    for p in paths:
        p.write_text("t,ax,ay,az\n0,0,0,1\n")
    return paths


def test_a_manifests_rows(tmp_path):
    manifest = tmp_path / "m" / "logs.csv"
    manifest.parent.mkdir()
    manifest.write_text(
        "\ufeffLog, Device ,Method,--no-robust\n"
        "\n"
        "a.csv,BOARD-1,ellipsoid,yes\n"
        "/abs/b.csv,,,\n"
        "s3://bucket/c.csv,BOARD-3,,\n",
        encoding="utf-8",
    )
    specs = read_manifest(manifest)
    assert [s.log for s in specs] == [
        str(manifest.parent / "a.csv"),
        "/abs/b.csv",
        "s3://bucket/c.csv",
    ]
    assert [s.device for s in specs] == ["BOARD-1", None, "BOARD-3"]
    assert specs[0].options == {"method": "ellipsoid", "robust": False, "cut_unsteady": False}
    assert specs[1].options == {} and specs[0].source == f"{manifest} row 3"  # physical lines


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("log,colour\na.csv,red\n", "unknown column 'colour'"),
        ("log,log\na.csv,b.csv\n", "the column 'log' is given twice"),
        ("log,device\n,A\n", "row 2, column log: empty"),
        ("log,device\na.csv,A B/C\n", "row 2, column device"),
        ("log,device\na.csv,A,x\n", "row 2: 3 fields for 2 columns"),
        ("log,method\na.csv,best\n", "row 2, column method: 'best' is not understood"),
        ("log\n", "a manifest without rows"),
    ],
)
def test_malformed_manifests_are_refused_in_one_line(tmp_path, text, message):
    manifest = tmp_path / "m.csv"
    manifest.write_text(text)
    with pytest.raises(InputError) as info:
        read_manifest(manifest)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_globs_paths_and_manifests_expand_in_order_each_log_once(tmp_path):
    b, a = _touch(tmp_path / "logs", "b.csv", "a.csv")
    manifest = tmp_path / "m.csv"
    manifest.write_text("log,device\nlogs/a.csv,X\n")
    specs = expand_logs([str(tmp_path / "logs" / "*.csv"), b, manifest])
    assert [s.log for s in specs] == [str(a), str(b)]  # sorted glob; repeats dropped
    assert specs[0].device is None  # its first place wins: the glob's
    given = LogSpec("somewhere.csv", "D")
    assert expand_logs([given]) == [given]


def test_expansion_refusals(tmp_path):
    with pytest.raises(InputError, match="matches no file"):
        expand_logs([str(tmp_path / "*.csv")])
    with pytest.raises(InputError, match="no such log"):
        expand_logs([tmp_path / "missing.csv"])
    with pytest.raises(InputError, match="no logs given"):
        expand_logs([])


@pytest.mark.parametrize(
    ("log", "device"),
    [("/data/imu 7/run.01.csv", "run"), ("s3://b/unit-3.parquet", "unit-3"), (".hidden", "hidden"),
     ("/x/__.csv", "log")],
)  # fmt: skip
def test_fallback_device_is_the_file_stem_as_a_folder_name(log, device):
    assert fallback_device(log) == device


def test_device_ids_become_folder_names():
    assert device_id(" Board 7/rev B ") == "Board_7_rev_B"
    assert device_id("...") == "log"
    assert len(device_id("x" * 300)) == 100
