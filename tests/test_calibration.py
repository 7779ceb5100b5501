"""The sensor model, its gauge, and the Calibration result (JSON, units, inverse model)."""

import dataclasses
import json
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import fieldcal
from fieldcal.calibration import Calibration, Diagnostics, ParameterCovariance, SensorCalibration
from fieldcal.geometry.frames import misalignment_angle_deg
from fieldcal.geometry.gauge import canonical_gauge
from fieldcal.geometry.rotations import exp_so3, random_rotations
from fieldcal.output import exports

seeds = st.integers(0, 2**32 - 1)


def _random_parameters(seed):
    rng = np.random.default_rng(seed)
    R = random_rotations(9, rng)
    Ka = np.eye(3) + rng.uniform(-0.3, 0.3, (3, 3))
    Km = np.eye(3) + rng.uniform(-0.3, 0.3, (3, 3))
    g = rng.standard_normal(3)
    h = rng.standard_normal(3)
    return rng, R, Ka, Km, g, h


def _full_calibration(seed=0) -> Calibration:
    session = fieldcal.simulate("paper", seed=seed)
    truth = session.truth
    names = ("accel.bias[0]", "mag.gain[1,2]", "dip_deg")
    return Calibration(
        accel=SensorCalibration(
            truth.accel.gain,
            truth.accel.bias,
            truth.accel.noise_cov,
            noise_cov_std=np.full((3, 3), 1e-6),
            pose_noise_std=1e-3,
            pose_noise_std_se=2e-4,
        ),
        mag=truth.mag,
        gravity=truth.gravity,
        magnetic=truth.magnetic,
        rotations=truth.rotations,
        method="mle",
        iterations=5,
        converged=True,
        options={"gamma": 1e-4, "nested": {"a": [1, 2]}},
        covariance=ParameterCovariance(
            names, [[1e-6, 1e-7, 2e-7], [1e-7, 4e-6, 3e-7], [2e-7, 3e-7, 1e-4]]
        ),
        diagnostics=Diagnostics(23.5, 23, 0.43, np.arange(15.0), "converged"),
        poses=tuple(
            {"index": i, "samples": 500, "start": 10 * i, "stop": 10 * i + 9} for i in range(15)
        ),
    )


@given(seeds)
def test_canonical_gauge_keeps_every_prediction(seed):
    _, R, Ka, Km, g, h = _random_parameters(seed)
    R2, Ka2, Km2, g2, h2 = canonical_gauge(R, Ka, Km, g, h)
    before_a = np.einsum("ij,njk,k->ni", Ka, R, g)
    before_m = np.einsum("ij,njk,k->ni", Km, R, h)
    np.testing.assert_allclose(np.einsum("ij,njk,k->ni", Ka2, R2, g2), before_a, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,njk,k->ni", Km2, R2, h2), before_m, atol=1e-12)
    np.testing.assert_allclose(Ka2, Ka2.T, atol=1e-14)
    assert np.all(np.linalg.eigvalsh(Ka2) > 0)
    np.testing.assert_allclose(g2, [0, 0, -1])
    assert h2[1] == pytest.approx(0, abs=1e-14) and h2[0] > 0
    assert np.linalg.norm(h2) == pytest.approx(1)
    np.testing.assert_allclose(np.linalg.det(R2), 1.0, atol=1e-12)


@given(seeds)
def test_canonical_gauge_mag_frame_makes_the_magnetometer_symmetric(seed):
    _, R, Ka, Km, g, h = _random_parameters(seed)
    _, Ka2, Km2, _, _ = canonical_gauge(R, Ka, Km, g, h, body_frame="mag")
    np.testing.assert_allclose(Km2, Km2.T, atol=1e-14)
    assert np.all(np.linalg.eigvalsh(Km2) > 0)
    assert not np.allclose(Ka2, Ka2.T, atol=1e-6)


@given(seeds, st.floats(-1e3, 1e3))
def test_correct_inverts_the_forward_model(seed, scale):
    rng = np.random.default_rng(seed)
    gain = np.eye(3) + rng.uniform(-0.5, 0.5, (3, 3))
    sensor = SensorCalibration(gain, rng.uniform(-5, 5, 3), np.eye(3))
    body = scale * rng.standard_normal((4, 2, 3))
    np.testing.assert_allclose(
        sensor.correct(sensor.distort(body)), body, atol=1e-9 * (1 + abs(scale))
    )


def test_correct_rejects_wrong_shapes():
    sensor = SensorCalibration(np.eye(3), np.zeros(3), np.eye(3))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        sensor.correct(np.zeros((5, 2)))


def test_predicted_means_follow_eq4():
    truth = fieldcal.simulate("paper", seed=4).truth
    a, m = truth.predicted_means()
    i = 3
    np.testing.assert_allclose(
        a[i], truth.accel.gain @ truth.rotations[i] @ truth.gravity + truth.accel.bias
    )
    np.testing.assert_allclose(
        m[i], truth.mag.gain @ truth.rotations[i] @ truth.magnetic + truth.mag.bias
    )
    # the calibrated vectors of both sensors live in one body frame: R_i g and R_i h
    np.testing.assert_allclose(truth.correct_accel(a), truth.rotations @ truth.gravity, atol=1e-12)
    np.testing.assert_allclose(truth.correct_mag(m), truth.rotations @ truth.magnetic, atol=1e-12)


def test_json_round_trip_is_lossless():
    cal = _full_calibration()
    text = cal.to_json()
    back = Calibration.from_json(text)
    assert back == cal
    assert back.to_json() == text
    doc = json.loads(text)
    assert doc["schema"] == "fieldcal.calibration" and doc["schema_version"] == 4
    assert doc["fieldcal_version"] == fieldcal.__version__
    assert doc["method"] == "mle" and doc["options"]["gamma"] == 1e-4
    assert doc["created"].startswith("20")
    assert set(doc["units"]) >= {"accel_raw", "mag_raw", "accel_calibrated", "mag_calibrated"}
    assert doc["dip_deg"] == pytest.approx(cal.dip_deg)
    assert doc["poses"][3] == {"index": 3, "samples": 500, "start": 30, "stop": 39}


def test_json_round_trip_keeps_nan_and_missing_sensor():
    cal = _full_calibration()
    import dataclasses

    cal = dataclasses.replace(cal, mag=None, magnetic=None, diagnostics=None)
    back = Calibration.from_json(cal.to_json())
    assert back == cal and back.mag is None and np.isnan(back.cost) and back.dip_deg is None


def test_json_rejects_foreign_and_future_documents():
    with pytest.raises(ValueError, match="not a fieldcal calibration"):
        Calibration.from_json('{"schema": "something-else"}')
    doc = json.loads(_full_calibration().to_json())
    doc["schema_version"] = 99
    with pytest.raises(ValueError, match="upgrade fieldcal"):
        Calibration.from_json(json.dumps(doc))
    with pytest.raises(ValueError, match="not a fieldcal calibration JSON"):
        Calibration.from_json("{not json")


def test_field_magnitudes_change_units_not_predictions():
    cal = _full_calibration()
    phys = cal.with_field_magnitudes(gravity=9.80665, field_strength=48.0)
    for before, after in zip(cal.predicted_means(), phys.predicted_means(), strict=True):
        np.testing.assert_allclose(after, before, atol=1e-12)
    np.testing.assert_allclose(phys.accel.gain, cal.accel.gain / 9.80665)
    np.testing.assert_allclose(phys.accel.gain_std, cal.accel.gain_std / 9.80665)
    assert phys.gravity_norm == pytest.approx(9.80665)
    assert phys.field_strength == pytest.approx(48.0)
    assert phys.dip_deg == pytest.approx(cal.dip_deg)
    raw = cal.predicted_means()[0]
    np.testing.assert_allclose(phys.correct_accel(raw), 9.80665 * cal.correct_accel(raw))
    assert phys.covariance.std("mag.gain[1,2]") == pytest.approx(2e-3 / 48.0)
    assert phys.covariance.std("dip_deg") == pytest.approx(1e-2)
    assert phys.units["accel_calibrated"] == "|g| = 9.80665"


def test_dip_sign_convention():
    """NED: the field pointing below the horizon (h_z > 0) has a positive dip."""
    down = fieldcal.simulate("paper", seed=1, dip_deg=(60, 60)).truth
    up = fieldcal.simulate("paper", seed=1, dip_deg=(-30, -30)).truth
    assert down.dip_deg == pytest.approx(60) and down.magnetic[2] > 0
    assert up.dip_deg == pytest.approx(-30)


def test_misalignment_angle_known_answers():
    P = np.diag([1.1, 0.9, 1.05])
    tilt = exp_so3(np.radians(3.0) * np.array([0.6, 0.0, 0.8]))
    assert misalignment_angle_deg(P, 0.8 * tilt) == pytest.approx(3.0)
    swapped = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])  # "+y+x-z" wiring
    assert misalignment_angle_deg(P, swapped @ tilt) == pytest.approx(3.0)
    mirrored = np.diag([1.0, 1.0, -1.0])  # a left-handed magnetometer
    assert misalignment_angle_deg(P, mirrored @ tilt) == pytest.approx(3.0)
    assert misalignment_angle_deg(P, P) == pytest.approx(0.0, abs=1e-6)


def test_calibration_is_immutable():
    cal = _full_calibration()
    with pytest.raises(AttributeError):
        cal.method = "x"
    with pytest.raises(ValueError):
        cal.accel.gain[0, 0] = 2.0


def test_mag_handedness_twin_predicts_the_same_readings():
    cal = _full_calibration()
    assert np.linalg.det(cal.mag.gain) > 0
    twin = cal.with_mag_handedness(mirrored=True)
    assert np.linalg.det(twin.mag.gain) < 0
    for before, after in zip(cal.predicted_means(), twin.predicted_means(), strict=True):
        np.testing.assert_allclose(after, before, atol=1e-12)
    assert twin.dip_deg == pytest.approx(-cal.dip_deg)
    assert twin.misalignment_deg == pytest.approx(cal.misalignment_deg)
    np.testing.assert_allclose(twin.gravity, cal.gravity)
    np.testing.assert_allclose(np.linalg.det(twin.rotations), 1.0)
    # accel.bias[0] vs mag.gain[1,2] changes sign; mag.gain[1,2] vs dip_deg (both flip) does not
    assert twin.covariance.matrix[0, 1] == -cal.covariance.matrix[0, 1]
    assert twin.covariance.matrix[1, 2] == cal.covariance.matrix[1, 2]
    assert twin.options["mag_mirrored"] is True
    back = twin.with_mag_handedness(mirrored=False)
    assert back.options["mag_mirrored"] is False
    assert dataclasses.replace(back, options=cal.options) == cal
    assert cal.with_mag_handedness(mirrored=False) is cal


def test_mag_handedness_twin_in_the_magnetometer_frame_keeps_its_gain_symmetric():
    truth = fieldcal.simulate("paper", seed=5).truth
    R, Ka, Km, g, h = canonical_gauge(
        truth.rotations, truth.accel.gain, truth.mag.gain, truth.gravity, truth.magnetic, "mag"
    )
    cal = Calibration(
        accel=SensorCalibration(Ka, truth.accel.bias, truth.accel.noise_cov),
        mag=SensorCalibration(Km, truth.mag.bias, truth.mag.noise_cov),
        gravity=g,
        magnetic=h,
        rotations=R,
        method="mle",
    )
    twin = cal.with_mag_handedness(mirrored=True)
    np.testing.assert_array_equal(twin.mag.gain, cal.mag.gain)
    assert np.linalg.det(twin.accel.gain) < 0 and twin.dip_deg == pytest.approx(-cal.dip_deg)
    for before, after in zip(cal.predicted_means(), twin.predicted_means(), strict=True):
        np.testing.assert_allclose(after, before, atol=1e-12)


# ----------------------------------------------------------------------------- malformed files
def _doc():
    return json.loads(_full_calibration().to_json())


def _refused(text, match):
    with pytest.raises(ValueError, match=match) as info:
        Calibration.from_json(text)
    message = str(info.value)
    assert "\n" not in message and len(message) < 300, message
    assert type(info.value) is ValueError  # not a TypeError, KeyError, RecursionError...
    return message


def _mutated(change):
    doc = _doc()
    change(doc)
    return json.dumps(doc, allow_nan=True)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda d: d.update(converged="false"), "converged must be true or false, not 'false'"),
        (lambda d: d.update(converged=1), "converged must be true or false"),
        (lambda d: d["accel"]["gain"][1].__setitem__(2, "inf"), "accel.gain has NaN or inf"),
        (lambda d: d["mag"]["bias"].__setitem__(0, float("nan")), "mag.bias has NaN or inf"),
        (lambda d: d["accel"].update(gain=[[1, 0, 0], [0, 1, 0]]), "must have shape 3x3"),
        (lambda d: d["accel"].update(gain=[[1, 2, 3]] * 3), "accel.gain is singular"),
        (lambda d: d["mag"].update(gain=np.zeros((3, 3)).tolist()), "mag.gain is singular"),
        (lambda d: d["mag"].update(bias=["1", "2", "3"]), "must be a number, not the text '1'"),
        (lambda d: d["accel"].pop("gain"), "document.accel has no 'gain'"),
        (lambda d: d.update(accel=[d["accel"]]), "document.accel must be an object, not list"),
        (lambda d: d.update(rotations="R"), "rotations must be a list of numbers, not str"),
        (lambda d: d["rotations"][0].append([1, 2, 3]), "rotations has rows of different"),
        (lambda d: d["accel"].update(noise_cov=(-np.eye(3)).tolist()), "negative variance"),
        (lambda d: d["accel"].update(pose_noise_std="inf"), "pose_noise_std must be a finite"),
        (lambda d: d["covariance"]["matrix"][0].__setitem__(0, "-inf"), "covariance has NaN"),
        (lambda d: d.update(options={"a": [[[[[[[[[[1]]]]]]]]]]}), None),
        (lambda d: d.update(schema_version="2"), "schema_version '2' is not a version"),
        (lambda d: d.update(schema_version=True), "schema_version"),
        (lambda d: d.pop("schema"), "not a fieldcal calibration"),
        (lambda d: d.update(accel=None, mag=None), "neither an accelerometer nor a magnet"),
        (lambda d: d.update(verdict={"level": "great"}), "verdict level must be pass, warn"),
    ],
)
def test_malformed_documents_are_one_line_value_errors(change, match):
    text = _mutated(change)
    if match is None:  # a legal document
        assert Calibration.from_json(text).options["a"]
        return
    _refused(text, match)


def test_documents_that_are_not_json_objects():
    _refused("[" * 100_000 + "]" * 100_000, "nested too deeply")
    doc = _doc()
    doc["options"] = {"x": "__DEEP__"}
    _refused(json.dumps(doc).replace('"__DEEP__"', "[" * 500 + "]" * 500), "nested too deeply")
    _refused(json.dumps(doc).replace('"__DEEP__"', "1" * 5000), "not a fieldcal calibration JSON")
    text = json.dumps(_doc()).replace('"gain": [[', '"gain": [[' + "1" * 400 + ".0, ", 1)
    _refused(text, "has rows of different lengths")
    big = json.dumps(_doc()).replace('"bias": [', '"bias": [' + "1" * 400 + ", ", 1)
    _refused(big, "too large a number|rows of different lengths|must have shape")
    for text in ("", "[]", "null", '"cal"', "{"):
        _refused(text, "not a fieldcal calibration")
    with pytest.raises(ValueError, match="takes the text of a calibration file, not dict"):
        Calibration.from_json(_doc())
    _refused(b"\xff\xfe{}", "not a fieldcal calibration JSON")


def test_nothing_downstream_sees_a_non_finite_or_singular_matrix():
    """What from_json accepts, corrections and every export can use."""
    from fieldcal.output import exports

    rng = np.random.default_rng(11)
    base = _doc()
    paths = [("accel", "gain"), ("mag", "gain"), ("accel", "bias"), ("mag", "noise_cov")]
    for _ in range(40):
        doc = json.loads(json.dumps(base))
        sensor, part = paths[rng.integers(0, len(paths))]
        value = np.array(doc[sensor][part], dtype=float)
        value.flat[rng.integers(0, value.size)] = rng.choice([np.nan, np.inf, 0.0, 1e300])
        doc[sensor][part] = value.tolist()
        try:
            cal = Calibration.from_json(json.dumps(doc, allow_nan=True))
        except ValueError as exc:
            assert "\n" not in str(exc)
            continue
        for s in ("accel", "mag"):
            sensor = cal.sensor(s)
            assert np.all(np.isfinite(sensor.gain)) and np.all(np.isfinite(sensor.bias))
            assert np.all(np.isfinite(cal.correct_accel([0.1, 0.2, 0.9])))
        for fmt in exports.FORMATS:
            try:
                assert exports.export(cal, fmt)
            except ValueError as exc:  # a format may refuse what it cannot hold, in one line
                assert "\n" not in str(exc)


@pytest.mark.parametrize(
    ("sensor", "part", "entry", "value", "message"),
    [
        ("accel", "gain", (0, 0), 1e300, "accel.gain[0,0] is 1e+300, beyond the range"),
        ("mag", "gain", (1, 2), -1e200, "mag.gain[1,2] is -1e+200, beyond the range"),
        ("accel", "gain", None, 1e-300, "accel.gain's smallest scale is 1e-300, below 1e-200"),
        ("mag", "bias", (0,), 1e308, "mag.bias[0] is 1e+308, beyond the range"),
        ("mag", "noise_cov", (2, 0), 1e308, "mag.noise_cov has an entry beyond 1e+300"),
    ],
)
def test_absurd_values_are_refused_on_load_naming_the_key(sensor, part, entry, value, message):
    """apply, export, report, plan and store add read files through from_json."""
    doc = _doc()
    if entry is None:  # a uniformly tiny gain: well conditioned, its inverse beyond the range
        doc[sensor][part] = (value * np.eye(3)).tolist()
    else:
        array = np.array(doc[sensor][part], dtype=float)
        array[entry] = value
        doc[sensor][part] = array.tolist()
    with pytest.raises(ValueError, match=re.escape(message)) as info:
        Calibration.from_json(json.dumps(doc))
    assert "\n" not in str(info.value)
    assert Calibration.from_json(json.dumps(_doc()))  # the document as written loads


@pytest.mark.parametrize("gravity", ["9.8", True, float("nan"), -1.0, 1e308, [9.8]])
def test_field_magnitudes_are_checked(gravity):
    with pytest.raises(ValueError, match="gravity must be a positive number from 1e-150"):
        _full_calibration().with_field_magnitudes(gravity=gravity)


def test_correct_refuses_what_is_not_real_readings():
    cal = _full_calibration()
    for raw in ([[1 + 1j, 0, 0]], [["1", "2", "3"]], [[True, False, True]]):
        with pytest.raises(ValueError, match="raw readings must be real numbers"):
            cal.correct_accel(raw)


def _with_gyro(cal: Calibration, seed: int = 3) -> Calibration:
    """``cal`` with a gyroscope: a gain near 100 counts per rad/s, its covariance block added
    beside the other parameters'."""
    rng = np.random.default_rng(seed)
    gain = 100.0 * (np.eye(3) + 0.02 * rng.standard_normal((3, 3)))
    gyro = SensorCalibration(gain=gain, bias=rng.normal(size=3), noise_cov=0.04 * np.eye(3))
    names = [f"gyro.gain[{j},{k}]" for j in range(3) for k in range(3)]
    names += [f"gyro.bias[{j}]" for j in range(3)]
    A = rng.standard_normal((12, 12)) * 1e-3
    base = cal.covariance
    n = len(base.names)
    matrix = np.zeros((n + 12, n + 12))
    matrix[:n, :n] = base.matrix
    matrix[n:, n:] = A @ A.T
    covariance = ParameterCovariance((*base.names, *names), matrix)
    segments = ({"start": 10, "stop": 90, "seconds": 0.8, "angle_deg": 91.0, "residual_deg": 0.2},)
    return dataclasses.replace(cal, gyro=gyro, covariance=covariance, gyro_segments=segments)


def test_the_gyroscope_travels_with_the_calibration():
    """A gyroscope's gain, bias, standard errors and segments survive the JSON; its correction
    inverts its model; the exports carry it; a broken one is refused in one line."""
    cal = _with_gyro(_full_calibration())
    again = Calibration.from_json(cal.to_json())
    assert again == cal
    np.testing.assert_array_equal(again.gyro.gain_std, cal.gyro.gain_std)
    assert again.gyro.bias_std is not None and np.all(again.gyro.bias_std > 0)
    assert again.gyro_segments == cal.gyro_segments
    omega = np.random.default_rng(1).normal(size=(5, 3))
    np.testing.assert_allclose(again.correct_gyro(cal.gyro.distort(omega)), omega, atol=1e-12)
    header = exports.export(cal, "c-header")
    assert "FIELDCAL_GYRO_MATRIX" in header and "gyroscope rad/s" in header
    assert "A_gyro" in exports.export(cal, "matlab")
    assert cal.units["gyro_calibrated"] == "rad/s"
    broken = dataclasses.replace(cal, gyro=dataclasses.replace(cal.gyro, gain=np.zeros((3, 3))))
    with pytest.raises(ValueError, match=r"gyro\.gain is singular"):
        Calibration.from_json(broken.to_json())
    with pytest.raises(ValueError, match="no gyro"):
        _full_calibration().correct_gyro(omega)


def test_compare_flags_what_moved_beyond_the_combined_error():
    """Against itself nothing changed; a magnetometer bias moved by 10 of its standard errors
    is flagged alone (z = 10/√2 with both calibrations' errors combined); different units are
    refused in one line."""
    session = fieldcal.simulate("paper", seed=4)
    cal = fieldcal.calibrate(session.accel, session.mag)
    assert cal.compare(cal).changed == ()
    std = cal.mag.bias_std[1]
    moved = dataclasses.replace(
        cal, mag=dataclasses.replace(cal.mag, bias=cal.mag.bias + np.array([0.0, 10 * std, 0.0]))
    )
    result = cal.compare(moved)
    assert [c.name for c in result.changed] == ["mag.bias[1]"]
    assert result.changed[0].z == pytest.approx(10 / np.sqrt(2), rel=1e-9)
    with pytest.raises(fieldcal.InputError, match="different units"):
        cal.compare(cal.with_field_magnitudes(gravity=9.80665))


def test_notebook_html_shows_the_verdict_numbers_and_poses_escaped():
    session = fieldcal.simulate("paper", seed=4)
    cal = fieldcal.calibrate(session.accel, session.mag)
    odd = dataclasses.replace(cal, verdict=fieldcal.Verdict("warn", ("<b>bold</b> & co",)))
    page = odd._repr_html_()
    assert "verdict: WARN" in page and "&lt;b&gt;bold&lt;/b&gt; &amp; co" in page
    assert "<b>bold" not in page
    assert page.count("<circle") == cal.n_poses
    assert f"{cal.mag.bias[0]:.5g} ± {cal.mag.bias_std[0]:.2g}" in page


# ----------------------------------------------------------------------------- check_values
def _changed(cal: Calibration, sensor: str | None, **values: object) -> Calibration:
    """``cal`` with fields of one sensor (or of the result, ``sensor=None``) replaced."""
    if sensor is None:
        return dataclasses.replace(cal, **values)
    return dataclasses.replace(cal, **{sensor: dataclasses.replace(cal.sensor(sensor), **values)})


def _with_entry(array: np.ndarray, index: tuple[int, ...], value: float) -> np.ndarray:
    out = np.array(array, dtype=float)
    out[index] = value
    return out


_GYRO = SensorCalibration(np.eye(3), np.zeros(3), 1e-6 * np.eye(3), noise_source="user")

#: (sensor, field values, message): each a value check_values refuses.
_REFUSED = [
    ("accel", {"gain": _with_entry(np.eye(3), (1, 2), np.nan)}, "accel.gain has NaN or inf"),
    ("mag", {"bias": np.array([np.inf, 0.0, 0.0])}, "mag.bias has NaN or inf"),
    ("mag", {"noise_cov": _with_entry(np.eye(3), (0, 0), -1e-6)}, "negative variance"),
    ("accel", {"noise_cov": np.full((3, 3), 1e301)}, "noise_cov has an entry beyond"),
    ("accel", {"pose_noise_std": float("nan")}, "pose_noise_std must be a finite"),
    ("mag", {"pose_noise_std": -1e-3}, "pose_noise_std must be a finite"),
    ("accel", {"gain": np.array([[1.0, 2.0, 3.0]] * 3)}, "accel.gain is singular"),
    ("mag", {"gain": _with_entry(np.eye(3), (2, 0), 2e150)}, r"mag.gain\[2,0\] is 2e\+150"),
    ("accel", {"bias": np.array([0.0, -3e150, 0.0])}, r"accel.bias\[1\] is -3e\+150"),
    ("mag", {"gain": 1e-201 * np.eye(3)}, "smallest scale is 1e-201"),
    (None, {"gravity": np.array([0.0, 0.0, np.nan])}, "accel reference field is not finite"),
    (None, {"magnetic": np.zeros(3)}, "mag reference field is not finite"),
    (None, {"magnetic": None}, "mag reference field is not finite"),
    (None, {"rotations": np.full((15, 3, 3), np.nan)}, "rotations has NaN or inf"),
    (
        None,
        {"covariance": ParameterCovariance(("dip_deg",), np.array([[np.inf]]))},
        "covariance has NaN or inf",
    ),
    (None, {"gyro": dataclasses.replace(_GYRO, gain=np.zeros((3, 3)))}, "so rates cannot"),
    (None, {"gyro": dataclasses.replace(_GYRO, noise_cov=np.full((3, 3), np.nan))}, "gyro.noise"),
]


@pytest.mark.parametrize(("sensor", "values", "match"), _REFUSED)
def test_check_values_refuses_each_unusable_value_in_one_line(sensor, values, match):
    """The pass over all the numbers at once lets none of these through: the checks one by
    one then name it."""
    bad = _changed(_full_calibration(), sensor, **values)
    with pytest.raises(ValueError, match=match) as info:
        bad.check_values()
    assert str(info.value).startswith("invalid calibration: ") and "\n" not in str(info.value)


def test_a_usable_calibration_passes_check_values_at_a_glance(monkeypatch):
    """The usual case takes the one pass (the checks one by one are not reached), with or
    without a gyroscope."""
    from fieldcal import calibration

    def one_by_one(*args: object) -> None:
        raise AssertionError("the checks one by one ran")

    monkeypatch.setattr(calibration, "_check_range", one_by_one)
    cal = _full_calibration()
    cal.check_values()
    _changed(cal, None, gyro=_GYRO).check_values()
    with pytest.raises(AssertionError):  # and the spy sees the checks when they run
        _changed(cal, "mag", pose_noise_std=-1.0).check_values()
