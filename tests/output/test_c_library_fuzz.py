"""The generated C library against one bad sample, one bad call, one bad blob (issue 35).

The reproducers of the outside fuzzing (C1: an infinite or huge magnetometer sample poisoned
the hard-iron estimate; C2: a save that could not be loaded; C3: re-sealed absurd blobs
loaded) run through ctypes; then a property-based test drives the library, built with
AddressSanitizer and UndefinedBehaviorSanitizer, with random and adversarial operation
scripts (tests/_clib_fuzz.py) and asserts: the state stays finite, a save always loads back as
it was, a refused load leaves the calibration untouched.
"""

from __future__ import annotations

import ctypes
import math
import struct
import zlib

import numpy as np
import pytest
from _clib import HardIron, Library, compiler, v3
from _clib_fuzz import (
    FOLD,
    HEADING,
    HI_APPLY,
    INIT,
    MONITOR,
    SAVE,
    TILT,
    UPDATE,
    Driver,
    apply,
    check,
    flags,
    load,
    poke,
    sanitizers_missing,
    three,
    update,
    widen,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fieldcal
from fieldcal.output.exports import c_library

OK, ERR_VALUE = 0, -6
BAD = [math.nan, math.inf, -math.inf, 1e20, 1e30, 3.4e38, -3.4e38, 1e-40, 1e-45, 0.0]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A calibration, its library (ctypes), clean body-frame samples of many poses."""
    session = fieldcal.simulate("paper", seed=35, n_poses=24, dip_deg=(58.0, 62.0))
    cal = fieldcal.calibrate(session.accel, session.mag)
    lib = Library(cal, tmp_path_factory.mktemp("clib35"))
    # one sample in four of each pose (the poses are lists of rests)
    a = lib.apply("accel", np.concatenate([p[::4] for p in session.accel]))
    m = lib.apply("mag", np.concatenate([p[::4] for p in session.mag]))
    return cal, lib, a, m


def _estimator(lib, cal=None):
    h = HardIron()
    assert lib.lib.fieldcal_hardiron_init(ctypes.byref(h), ctypes.byref(cal or lib.factory)) == 0
    return h


def _update(lib, h, a, m, cal=None):
    return lib.lib.fieldcal_hardiron_update(
        ctypes.byref(h), ctypes.byref(cal or lib.factory), v3(a), v3(m)
    )


def _reseal(blob: bytes) -> bytes:
    return blob[:-4] + struct.pack("<I", zlib.crc32(blob[:-4]))


def _with_floats(blob: bytes, values: dict[int, float]) -> bytes:
    out = bytearray(blob)
    for i, value in values.items():
        out[16 + 4 * i : 20 + 4 * i] = struct.pack("<f", value)
    return _reseal(bytes(out))


# ------------------------------------------------------------------------- C1, C2, C3
@pytest.mark.parametrize("glitch", [math.inf, -math.inf, 1e20, 1e30, -1e30, math.nan])
def test_c1_one_glitched_magnetometer_sample_is_not_an_update(world, glitch):
    _, lib, a, m = world
    h = _estimator(lib)
    for i in range(0, len(a), 40):  # learn a little first
        _update(lib, h, a[i], m[i])
    before = bytes(h)
    bad = m[7].copy()
    bad[1] = glitch
    assert _update(lib, h, a[7], bad) == 0
    assert bytes(h)[:-8] == before[:-8] and h.rejected >= 1  # only the counter moved
    out = v3(m[100])
    assert lib.lib.fieldcal_hardiron_apply(ctypes.byref(h), out) == OK
    assert np.isfinite(list(out)).all()


def test_c1_a_sample_far_from_the_field_norm_is_not_an_update(world):
    _cal, lib, a, m = world
    h = _estimator(lib)
    for scale in (0.3, 1.8, 5.0, 1e6):  # |m| = 0.3 F ... a million F
        assert _update(lib, h, a[3], m[3] * scale) == 0
    assert h.updates == 0 and h.rejected == 4
    assert _update(lib, h, a[3], m[3]) == 1  # the clean one is used


@pytest.mark.parametrize("std", [1e20, math.inf, math.nan, -1.0])
def test_c2_widen_refuses_and_a_save_always_loads(world, std):
    _cal, lib, a, m = world
    h = _estimator(lib)
    P = list(h.P)
    assert lib.lib.fieldcal_hardiron_widen(ctypes.byref(h), ctypes.c_float(std)) == ERR_VALUE
    assert list(h.P) == P
    # the documented main loop after glitches: fold, save, load at the next boot
    target = lib.cal()
    for i in range(len(a)):
        bad = m[i] * (1e30 if i % 7 == 0 else 1.0)
        _update(lib, h, a[i], bad, target)
    assert lib.lib.fieldcal_hardiron_fold(ctypes.byref(h), ctypes.byref(target)) == OK
    blob = lib.save(target)
    status, loaded = lib.load(blob, target.sensor_id)
    assert status == OK and bytes(loaded) == bytes(target)


def test_c2_save_refuses_what_load_would_refuse(world):
    _, lib, *_ = world
    broken = lib.cal()
    broken.f[18] = math.inf  # mag_matrix[0]
    buf = ctypes.create_string_buffer(b"\x55" * 512, 512)
    assert lib.lib.fieldcal_save(ctypes.byref(broken), buf, 512) == ERR_VALUE
    assert buf.raw == b"\x55" * 512  # nothing written
    assert lib.lib.fieldcal_check(ctypes.byref(broken)) == ERR_VALUE
    assert lib.lib.fieldcal_check(ctypes.byref(lib.factory)) == OK


# indices of fc_fields' order: accel_matrix 0-8, accel_bias 9-11, mag_matrix 12-20, ...,
# dip 39, norm_var_sample 40, dip_var_sample 42, hard_iron_cov 46-54
_ZERO_MATRIX = {i: 0.0 for i in range(12, 21)}
_TINY_GAIN = {i: (1e-40 if i in (12, 16, 20) else 0.0) for i in range(12, 21)}
_HUGE_MATRIX = {i: (3e38 if i in (12, 16, 20) else 0.0) for i in range(12, 21)}


@pytest.mark.parametrize(
    ("floats", "flag_bits"),
    [
        (_ZERO_MATRIX, None),
        (_TINY_GAIN, None),
        (_HUGE_MATRIX, None),
        ({40: -1e-6}, None),  # a negative variance
        ({42: 0.0}, None),
        ({46: -1.0}, None),  # the hard iron's covariance not positive-definite
        ({47: 1e3, 49: 1e3}, None),
        ({39: 95.0}, None),  # a dip beyond 90 degrees
        ({}, 0x1F | 0x100),  # an unknown flag bit
        ({}, 0x0),  # no sensor at all
        ({}, 0x10 | 0x4),  # a monitor without the accelerometer and magnetometer
    ],
    ids=[
        "zero-matrix",
        "gain-1e-40",
        "matrix-3e38",
        "negative-variance",
        "zero-variance",
        "negative-covariance",
        "covariance-not-pd",
        "dip-95",
        "unknown-flag",
        "no-sensor",
        "monitor-alone",
    ],
)
def test_c3_resealed_absurd_blobs_are_refused_and_the_target_kept(world, floats, flag_bits):
    _cal, lib, *_ = world
    blob = bytearray(lib.save(lib.factory))
    if flag_bits is not None:
        blob[12:16] = struct.pack("<I", flag_bits)
    damaged = _with_floats(bytes(blob), floats)
    target = lib.cal()
    target.f[5] = 123.0
    before = bytes(target)
    status, after = lib.load(damaged, lib.factory.sensor_id, into=target)
    assert status == ERR_VALUE
    assert bytes(after) == before


def test_the_python_blob_of_several_calibrations_loads_on_the_device(world, tmp_path):
    for seed in (1, 2):
        session = fieldcal.simulate("paper", seed=seed, n_poses=12)
        cal = fieldcal.calibrate(session.accel, session.mag)
        lib = Library(cal, tmp_path / str(seed))
        assert lib.lib.fieldcal_check(ctypes.byref(lib.factory)) == OK
        status, _ = lib.load(c_library.blob(cal), c_library.sensor_id_of(cal))
        assert status == OK


def test_non_finite_inputs_give_nan_and_an_error_code(world):
    _, lib, a, _m = world
    out = v3([1.0, 2.0, 3.0])
    assert lib.lib.fieldcal_mag(ctypes.byref(lib.factory), v3([math.inf, 0, 0]), out) == ERR_VALUE
    assert np.isnan(list(out)).all()
    lib.lib.fieldcal_heading.restype = ctypes.c_float
    assert math.isnan(lib.lib.fieldcal_heading(ctypes.byref(lib.factory), v3(a[0]), v3([0, 0, 0])))
    assert math.isnan(lib.lib.fieldcal_tilt(v3([math.nan, 0, 1]), None, None))
    # a field along gravity has no north
    assert math.isnan(lib.lib.fieldcal_heading(ctypes.byref(lib.factory), v3(a[0]), v3(-a[0])))


# ----------------------------------------------------------------- the property test
@pytest.fixture(scope="module")
def driver(world, tmp_path_factory):
    cal = world[0]
    folder = tmp_path_factory.mktemp("clib35san")
    reason = sanitizers_missing(compiler(), folder)
    if reason is not None:
        pytest.skip(reason)
    return Driver(cal, folder)


_ADVERSE = st.one_of(st.floats(width=32), st.sampled_from(BAD))


def _vector(draw, base: np.ndarray) -> np.ndarray:
    kind = draw(st.integers(0, 5))
    v = base.astype(float).copy()
    if kind == 1:
        v[draw(st.integers(0, 2))] = draw(_ADVERSE)
    elif kind == 2:
        v = v * draw(st.sampled_from([1e-30, 1e-3, 0.4, 0.97, 1.03, 1.6, 20.0, 1e30]))
    elif kind == 3:
        v = np.array([draw(_ADVERSE) for _ in range(3)])
    elif kind == 4:
        v = v + draw(st.floats(-0.08, 0.08))  # a hard iron moved
    return v


@st.composite
def _operation(draw, a, m, blob, sid):
    kind = draw(st.integers(0, 13))
    i = draw(st.integers(0, len(a) - 1))
    if kind <= 3:
        return update(UPDATE, _vector(draw, a[i]), _vector(draw, m[i]))
    if kind <= 5:  # a burst: a monitor block needs 16 samples
        j = draw(st.integers(0, len(a) - 20))
        n = draw(st.integers(1, 20))
        return b"".join(update(MONITOR, a[j + k], _vector(draw, m[j + k])) for k in range(n))
    if kind == 6:
        return widen(draw(st.one_of(_ADVERSE, st.floats(0.0, 0.1))))
    if kind == 7:
        return bytes([draw(st.sampled_from([FOLD, SAVE, INIT, SAVE]))])
    if kind == 8:
        return load(draw(_blobs(blob)), sid if draw(st.integers(0, 9)) else sid ^ 1)
    if kind == 9:
        return apply(draw(st.integers(0, 2)), _vector(draw, a[i]))
    if kind == 10:
        return update(HEADING, _vector(draw, a[i]), _vector(draw, m[i]))
    if kind == 11:
        return three(draw(st.sampled_from([TILT, HI_APPLY])), _vector(draw, m[i]))
    if kind == 12:
        return poke(draw(st.integers(0, 255)), draw(_ADVERSE))
    return flags(draw(st.integers(0, 2**32 - 1)))


@st.composite
def _blobs(draw, blob: bytes):
    kind = draw(st.integers(0, 5))
    out = bytearray(blob)
    if kind == 0:  # bit flips, sealed again or not
        for bit in draw(st.lists(st.integers(0, 8 * len(blob) - 1), min_size=1, max_size=4)):
            out[bit // 8] ^= 1 << (bit % 8)
        return _reseal(bytes(out)) if draw(st.booleans()) else bytes(out)
    if kind in (1, 2):  # absurd floats, re-sealed with a valid CRC
        n = (len(blob) - 20) // 4
        values = draw(st.dictionaries(st.integers(0, n - 1), _ADVERSE, min_size=1, max_size=4))
        return _with_floats(blob, values)
    if kind == 3:  # flags
        out[12:16] = struct.pack("<I", draw(st.integers(0, 2**32 - 1)))
        return _reseal(bytes(out))
    if kind == 4:
        return bytes(blob[: draw(st.integers(0, len(blob)))])
    return blob  # the factory's, intact


@settings(
    max_examples=120,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(data=st.data())
def test_property_no_input_poisons_the_device(world, driver, data):
    _cal, lib, a, m = world
    blob = lib.save(lib.factory)
    sid = lib.factory.sensor_id
    ops = data.draw(st.lists(_operation(a, m, blob, sid), min_size=1, max_size=60))
    (init_rc, check_rc), steps = driver.run(b"".join(ops))
    assert init_rc == OK and check_rc == OK  # the factory calibration is a valid one
    check(steps)
