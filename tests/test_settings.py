"""The option table: each option declared once, and the command line, the batch manifest, the
library's keywords and the settings objects the stages receive derived from it."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

import fieldcal
from fieldcal.batch.manifest import OPTION_COLUMNS
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.pipeline import LogSettings
from fieldcal.reference import DIP_ALLOWANCE_DEG
from fieldcal.settings import (
    DEFAULT_METHOD,
    OPTIONS,
    READ_OPTIONS,
    STAGES,
    TARGET_OPTIONS,
    DetectSettings,
    FitSettings,
    TrustSettings,
    changed,
    parse,
)
from fieldcal.trust.targets import DEFAULT_TARGETS, Targets

#: The command-line options, by their manifest column.
FLAGGED = {o.column: o for o in OPTIONS.values() if o.on_command_line}


def test_each_option_once_with_its_stage_flag_and_help():
    assert len(FLAGGED) == sum(o.on_command_line for o in OPTIONS.values())
    for name, option in OPTIONS.items():
        assert option.name == name and option.stage in STAGES
        assert option.help.strip()
        assert option.flag.startswith("--") or option.flag == ""
        assert (option.column == "") == (not option.on_command_line)
    assert READ_OPTIONS == tuple(n for n, o in OPTIONS.items() if o.stage == "read")
    # the library's own options: no flag, no column
    assert {n for n, o in OPTIONS.items() if not o.on_command_line} == {
        "cut_unsteady",
        "body_frame",
        "false_alarm",
    }


def test_the_front_ends_are_derived_from_the_table():
    columns = {c: o.name for c, o in FLAGGED.items()}
    columns.update({o.old_column: o.name for o in FLAGGED.values() if o.old_flag})  # old names
    assert {c: k for c, (k, _) in OPTION_COLUMNS.items()} == columns
    for command in ("calibrate", "batch"):
        params = {p.name for p in cli.commands[command].params}
        assert set(FLAGGED) <= params, set(FLAGGED) - params
    capture = {p.name for p in cli.commands["capture"].params}
    assert {c for c, o in FLAGGED.items() if o.stage in ("fit", "trust")} <= capture
    method = next(p for p in cli.commands["calibrate"].params if p.name == "method")
    assert method.default == DEFAULT_METHOD
    assert inspect.signature(fieldcal.calibrate).parameters["method"].default == DEFAULT_METHOD


@pytest.mark.parametrize("command", ["calibrate", "batch", "capture", "plan"])
def test_target_options_show_the_targets_defaults(command):
    """One set of defaults everywhere: fieldcal.Targets'; unset, the library takes them."""
    params = {p.name: p for p in cli.commands[command].params}
    for name in TARGET_OPTIONS:
        option = OPTIONS[name]
        param = params[option.column]
        assert not isinstance(param.default, float)  # unset: None reaches the library
        assert param.help.endswith(f"[default: {getattr(DEFAULT_TARGETS, option.target):g}]")
    assert {OPTIONS[n].target for n in TARGET_OPTIONS} == {"tilt_deg", "heading_deg", "norm_pct"}


def test_library_keywords_take_the_tables_defaults():
    """No second list of defaults: fieldcal.calibrate's and calibrate_log's keywords that are
    options default to the table's values (the dip allowance's is the reference's)."""
    for function in (fieldcal.calibrate, fieldcal.calibrate_log):
        keywords = inspect.signature(function).parameters
        shared = [n for n in keywords if n in OPTIONS]
        assert len(shared) >= (12 if function is fieldcal.calibrate else 6)
        for name in shared:
            assert keywords[name].default == OPTIONS[name].default, name
    assert TrustSettings().dip_allowance_deg == DIP_ALLOWANCE_DEG
    assert FitSettings().method == DEFAULT_METHOD


def test_log_settings_split_the_keywords_by_stage():
    targets = Targets(heading_deg=3.0)
    settings = LogSettings.of(
        {"accel_cols": "a,b,c", "still_trim": 0.2, "gravity": 9.8, "location": "47,8"},
        dip_allowance_deg=4.0,
        target_tilt=0.5,
        targets=targets,
        max_iter=7,
    )
    assert settings.read.accel_cols == "a,b,c" and settings.read.keywords() == {
        "accel_cols": "a,b,c"
    }
    assert settings.detect == DetectSettings(still_trim=0.2)
    assert settings.detect.detector_keywords()["trim"] == 0.2
    assert changed(settings.fit) == {"gravity": 9.8}
    assert changed(settings.trust) == {
        "location": "47,8",
        "dip_allowance_deg": 4.0,
        "target_tilt": 0.5,
    }
    assert settings.targets is targets
    assert dict(settings.method_options) == {"max_iter": 7}  # checked by the method's registry
    with pytest.raises(ValueError, match=r"targets must be a fieldcal\.Targets"):
        LogSettings.of(targets={"tilt_deg": 1.0})
    # frozen: a stage cannot change what the next one receives
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.fit.gravity = 1.0  # type: ignore[misc]


def test_target_options_reach_the_verdict():
    """--target-tilt (target_tilt=) replaces the tilt target of targets= (or of the defaults):
    half the predicted tilt error warns (code accuracy); the other targets stay."""
    session = fieldcal.simulate("paper", seed=4)
    columns = {"pose": np.repeat(np.arange(len(session.accel)), [len(a) for a in session.accel])}
    for i, axis in enumerate("xyz"):
        columns[f"a{axis}"] = np.concatenate(session.accel)[:, i]
        columns[f"m{axis}"] = np.concatenate(session.mag)[:, i]
    plain = fieldcal.calibrate_log(columns)
    codes = {r.code for r in plain.verdict.reasons}
    assert not codes & {"accuracy", "unusable"}, plain.verdict.reasons
    half = plain.accuracy.tilt_deg / 2
    tight = fieldcal.calibrate_log(columns, target_tilt=half)
    assert "accuracy" in {r.code for r in tight.verdict.reasons}
    assert "unusable" not in {r.code for r in tight.verdict.reasons}  # within 5x the target
    assert tight.verdict.level == "warn"
    same = fieldcal.calibrate_log(columns, targets=Targets(tilt_deg=half))
    assert same.verdict == tight.verdict
    # the option replaces the object's tilt and keeps its heading
    loose = Targets(tilt_deg=1e-9, heading_deg=plain.accuracy.heading_deg / 2)
    both = fieldcal.calibrate_log(columns, targets=loose, target_tilt=1e3)
    texts = " ".join(r.text for r in both.verdict.reasons if r.code == "accuracy")
    assert "heading" in texts and "tilt" not in texts
    with pytest.raises(InputError, match="target_norm must be a positive number") as caught:
        fieldcal.calibrate_log(columns, target_norm=float("nan"))
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("name", "text", "value"),
    [
        ("rate", "100", 100.0),
        ("still_trim", "0", 0.0),
        ("robust", "yes", False),  # --no-robust yes: robust off
        ("gyro", "off", False),
        ("noise", "accel=0.01,mag=0.2", {"accel": 0.01, "mag": 0.2}),
        ("pose_noise", "mag=auto", {"mag": "auto"}),
        ("field_strength", "wmm:nT", "wmm:nT"),
        ("dip_allowance_deg", "5", 5.0),
        ("target_tilt", "0.5", 0.5),
    ],
)
def test_parse_gives_the_value(name, text, value):
    assert parse(OPTIONS[name], text) == value


@pytest.mark.parametrize(
    ("name", "text", "reason"),
    [
        ("rate", "0", "out of range; give a number above 0"),
        ("rate", "fast", "'fast' is not a number"),
        ("gravity", "inf", "not a finite number"),
        ("dip_allowance_deg", "90", "at most 89"),
        ("decimal", ";", "give one of ., ,"),
        ("noise", "gyro=1", "'gyro' is not a sensor"),
        ("field_strength", "earth", "neither a number nor wmm"),
        ("drop_nan", "maybe", "give true or false"),
        ("target_norm", "-2", "out of range; give a number above 0"),
    ],
)
def test_parse_refuses_in_one_line(name, text, reason):
    with pytest.raises(ValueError, match=reason) as caught:
        parse(OPTIONS[name], text)
    assert "\n" not in str(caught.value)
