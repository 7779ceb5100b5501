"""The ``c-library`` export: a C99 library for the device that applies, keeps, checks and
updates the calibration (``fieldcal_cal.h`` and ``fieldcal_cal.c``; docs/microcontroller.md).

The C sources are package data (``c_sources/``); this module fills in the calibration: the
factory ``fieldcal_cal_t`` (corrections, the expected field, the monitor's variances and
threshold, the hard iron's prior covariance) and the header's ``#define`` lines.

The monitor's numbers, from the calibration (``F`` the field's norm and ``g`` gravity's, in
calibrated units; ``C_s = M_s Σ_s M_sᵀ`` a sensor's per-sample noise covariance corrected,
``M_s = inv(gain_s)``; ``q_s`` its pose-level noise, ``cal.<s>.pose_noise_std``):

- ``norm_var_sample = tr(C_m)/3`` and ``norm_var_fixed = q_m² tr(M_m M_mᵀ)/3 + (e F)²`` with
  ``e = cal.accuracy.mag_norm_rel`` (the predicted error of ``|m|`` from the calibration's
  own uncertainty);
- ``dip_var_sample = tr(C_m)/(3F²) + tr(C_a)/(3g²)``, ``dip_var_fixed = q_m² tr(M_m M_mᵀ)/(3F²)
  + q_a² tr(M_a M_aᵀ)/(3g²) + σ_dip² + (t/g)²/3`` with ``t`` the accelerometer gate
  (``accel_norm_tol = max(4 sqrt(tr(C_a)/3), 0.01 g)``: a sample is used when ``||a| − g| <= t``,
  and an acceleration up to ``t`` tilts the measured down direction by up to ``t/g``);
- a block of ``B`` samples gives ``d² = z_norm² + z_dip²`` with each ``z`` the block mean's
  error over its standard deviation ``sqrt(var_fixed + var_sample/B)``. The alarm compares the
  mean ``d²`` of the last ``W`` blocks with ``monitor_threshold``, the ``1 − α`` quantile of that
  mean for a device at rest, the worst case: the fixed parts (pose-level error, the
  calibration's own; for the dip without the acceleration allowance, none at rest) shared by
  the whole window, the samples' noise independent from block to block
  (:func:`rest_threshold`; ``−2 ln α`` when everything is shared). In motion the blocks see
  different orientations and false alarms are rarer still, so ``α`` bounds the false alarms
  per block (docs/microcontroller.md: the figures of ``benchmarks/monitor_alarm.py``).

Temperature terms (``docs/methods/temperature.md``), when the calibration has them: each
sensor's ``<sensor>_temp[12]`` holds ``T_ref, T_min, T_max`` and ``c1, c2, c3`` (3 each, raw units
per K^k), the flag ``FIELDCAL_HAS_TEMPERATURE`` is set and ``fieldcal_<sensor>_at(cal, raw, t,
out)`` applies the bias at the die temperature ``t`` (clipped to the span, as fieldcal and PX4
do). The blob then has :data:`N_FLOATS_TEMPERATURE` floats and version
:data:`VERSION_TEMPERATURE`; a calibration without terms gives the files and the blob it gave
before, byte for byte (version 1, :data:`N_FLOATS`).

The hard iron's prior is ``M_m Cov(b_m) M_mᵀ`` (the body-frame covariance of the magnetometer
bias, ``cal.mag.covariance``), with a random walk ``hard_iron_q`` per update
(:data:`HARD_IRON_WALK`).
"""

from __future__ import annotations

import math
import struct
import zlib
from importlib import resources

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from .c_header import c_float
from .common import TEMPERATURE_FORMULA, corrections, cubic, provenance, temperature_terms

__all__ = [
    "ALPHA",
    "BLOB_SIZE",
    "CONTENT",
    "FILES",
    "FORMULA",
    "HARD_IRON_WALK",
    "N_FLOATS",
    "N_FLOATS_TEMPERATURE",
    "VERSION_TEMPERATURE",
    "blob",
    "factory",
    "files",
    "sensor_id_of",
    "write",
]

Array = NDArray[np.float64]

FORMULA = "body = M * (raw - b), M = inv(gain), b = bias (fieldcal_apply)"
CONTENT = (
    "a folder (`-o DIR`): `fieldcal_cal.h`, `fieldcal_cal.c`, C99 with no dynamic memory: apply "
    "(accel, mag, gyro, tilt, heading), keep (versioned blob with CRC-32), check (the field's "
    "norm and dip against the calibration's), update (the hard iron, recursively); with "
    "temperature terms `fieldcal_<sensor>_at(cal, raw, t, out)` (blob version 2)"
)

#: The files written, in order.
FILES = ("fieldcal_cal.h", "fieldcal_cal.c")
#: The monitor's false-alarm rate per block (at most; see the module docstring).
ALPHA = 1e-3
#: Samples per block and blocks per decision (``FIELDCAL_MONITOR_BLOCK``, ``_WINDOW``).
BLOCK = 16
WINDOW = 8
#: The hard iron's random walk per update, relative to the field (``hard_iron_q = (w F)²``):
#: about 1 % of the field after 100 updates (a few minutes of motion), so a slow drift is
#: followed; a sudden change needs ``fieldcal_hardiron_widen``.
HARD_IRON_WALK = 1e-3
#: Floats in the blob, in ``fc_fields`` order; the blob's size in bytes.
N_FLOATS = 56
BLOB_SIZE = 16 + 4 * N_FLOATS + 4
_MAGIC = 0x4C434446
_VERSION = 1
#: The blob's version and float count with temperature terms (three ``<sensor>_temp[12]``).
VERSION_TEMPERATURE = 2
N_FLOATS_TEMPERATURE = N_FLOATS + 36
_FLAGS = {"accel": 1, "mag": 2, "gyro": 4, "declination": 8, "monitor": 16, "temperature": 32}
#: The bounds ``fieldcal_check`` applies (``FIELDCAL_*`` in the header; docs/microcontroller.md).
MATRIX_RANGE = (1e-12, 1e12)
CONDITION_MAX = 1e4
BIAS_MAX = 1e6
NORM_RANGE = (1e-9, 1e9)
VAR_MIN = 1e-14
#: The floor the export gives the monitor's per-sample variances and the hard iron's (times
#: ``F²`` for the norm and the hard iron, rad² for the dip): float32 resolves no finer, and a
#: zero variance is one ``fieldcal_check`` refuses.
VAR_FLOOR = 1e-12
#: The float fields of ``fieldcal_cal_t`` in blob order, with their lengths.
_LAYOUT = (
    ("accel_matrix", 9),
    ("accel_bias", 3),
    ("mag_matrix", 9),
    ("mag_bias", 3),
    ("gyro_matrix", 9),
    ("gyro_bias", 3),
    ("declination_deg", 1),
    ("gravity_norm", 1),
    ("field_norm", 1),
    ("dip_deg", 1),
    ("norm_var_sample", 1),
    ("norm_var_fixed", 1),
    ("dip_var_sample", 1),
    ("dip_var_fixed", 1),
    ("accel_norm_tol", 1),
    ("monitor_threshold", 1),
    ("hard_iron_cov", 9),
    ("hard_iron_q", 1),
)
#: The fields a calibration with temperature terms adds at the end (T_ref, T_min, T_max, c1..c3).
_TEMPERATURE_LAYOUT = (("accel_temp", 12), ("mag_temp", 12), ("gyro_temp", 12))


def _layout(cal: Calibration) -> tuple[tuple[str, int], ...]:
    """The float fields of this calibration's ``fieldcal_cal_t``, in blob order."""
    return _LAYOUT + (_TEMPERATURE_LAYOUT if temperature_terms(cal) else ())


def _known_flags(thermal: bool) -> int:
    """``FIELDCAL_KNOWN_FLAGS``: every flag this library's calibration may carry."""
    return sum(v for k, v in _FLAGS.items() if thermal or k != "temperature")


def _hard_iron_prior(cov: Array, F: float) -> Array:
    """The prior as ``fieldcal_check`` accepts it: symmetric (bit for bit), each variance within
    ``[VAR_FLOOR F², F²]`` (a hard iron uncertain by more than the field says nothing more),
    positive-definite with a margin (else its correlations are dropped, as the device does)."""
    var = np.diag(cov)
    std = np.sqrt(np.clip(var, VAR_FLOOR * F**2, F**2))
    corr = np.eye(3)
    if np.all(var > 0):
        corr = 0.5 * (cov + cov.T) / np.sqrt(np.outer(var, var))
        np.fill_diagonal(corr, 1.0)
        if np.abs(corr - np.eye(3)).max() >= 1.0 - 1e-6 or np.linalg.det(corr) < 1e-5:
            corr = np.eye(3)
    upper = np.triu(corr * np.outer(std, std))
    return np.asarray(upper + np.triu(upper, 1).T, dtype=float)


def _plausible(flags: int, fields: dict[str, Array]) -> None:
    """Refuse what ``fieldcal_check`` would refuse on the device (the same rules, in float64 on
    the float32 values): an export the device cannot load is an error here, not a silent
    fallback to nothing there."""
    for name in ("accel", "mag", "gyro"):
        if not flags & _FLAGS[name]:
            continue
        M = fields[f"{name}_matrix"].astype(np.float32).astype(float).reshape(3, 3)
        largest = float(np.abs(M).max())
        if not MATRIX_RANGE[0] <= largest <= MATRIX_RANGE[1]:
            raise InputError(
                f"cannot export c-library: the {name} correction's largest entry {largest:.3g} "
                f"is outside {MATRIX_RANGE[0]:g}..{MATRIX_RANGE[1]:g} (the gain is not a sensor's)"
            )
        if np.linalg.cond(M, "fro") > 0.9 * CONDITION_MAX:
            raise InputError(
                f"cannot export c-library: the {name} gain is (nearly) singular: condition "
                f"number {np.linalg.cond(M):.3g}, the device accepts at most {CONDITION_MAX:g}"
            )
        biases = [fields[f"{name}_bias"]]
        if f"{name}_temp" in fields:  # the bias at both ends of the temperature span
            temp = fields[f"{name}_temp"]
            for end in (temp[1], temp[2]):
                u = end - temp[0]
                biases.append(biases[0] + temp[3:6] * u + temp[6:9] * u**2 + temp[9:12] * u**3)
        if max(float(np.abs(M @ b).max()) for b in biases) > BIAS_MAX:
            raise InputError(
                f"cannot export c-library: the {name} bias is more than {BIAS_MAX:g} calibrated "
                "units: not a sensor's"
            )


def _isotropic(M: Array, cov: Array) -> float:
    """``tr(M cov Mᵀ)/3``: the variance of one corrected component, averaged over axes."""
    return float(np.trace(M @ cov @ M.T) / 3.0)


def _monitor(cal: Calibration, inv: dict[str, Array]) -> dict[str, float | Array] | None:
    """The monitor's and the update's numbers, or ``None`` without both sensors' fields."""
    if cal.accel is None or cal.mag is None or cal.gravity is None or cal.magnetic is None:
        return None
    F = float(np.linalg.norm(cal.magnetic))
    g = float(np.linalg.norm(cal.gravity))
    Ma, Mm = inv["accel"], inv["mag"]
    var_a = _isotropic(Ma, np.asarray(cal.accel.noise_cov, dtype=float))
    var_m = _isotropic(Mm, np.asarray(cal.mag.noise_cov, dtype=float))
    pose_a = cal.accel.pose_noise_std**2 * _isotropic(Ma, np.eye(3))
    pose_m = cal.mag.pose_noise_std**2 * _isotropic(Mm, np.eye(3))
    rel = (cal.accuracy.mag_norm_rel if cal.accuracy is not None else None) or 0.0
    dip_std = math.radians(cal.dip_std_deg or 0.0)
    tol = max(4.0 * math.sqrt(var_a), 0.01 * g)
    cov = cal.mag.covariance
    names = [f"bias[{j}]" for j in range(3)]
    if cov is not None and all(name in cov.names for name in names):
        idx = [cov.index(name) for name in names]
        bias_cov = np.asarray(cov.matrix, dtype=float)[np.ix_(idx, idx)]
    else:  # no error bars for the bias: a wide prior, 5 % of the field per axis
        bias_cov = np.linalg.inv(Mm) @ np.linalg.inv(Mm).T * (0.05 * F) ** 2
    return {
        "gravity_norm": g,
        "field_norm": F,
        "dip_deg": float(cal.dip_deg or 0.0),
        "norm_var_sample": max(var_m, VAR_FLOOR * F**2),
        "norm_var_fixed": pose_m + (rel * F) ** 2,
        "dip_var_sample": max(var_m / F**2 + var_a / g**2, VAR_FLOOR),
        "dip_var_fixed": pose_m / F**2 + pose_a / g**2 + dip_std**2 + (tol / g) ** 2 / 3.0,
        "accel_norm_tol": tol,
        "monitor_threshold": rest_threshold(
            (pose_m + (rel * F) ** 2, var_m),
            (pose_m / F**2 + pose_a / g**2 + dip_std**2, var_m / F**2 + var_a / g**2),
            (pose_m + (rel * F) ** 2, var_m),
            (
                pose_m / F**2 + pose_a / g**2 + dip_std**2 + (tol / g) ** 2 / 3.0,
                var_m / F**2 + var_a / g**2,
            ),
        ),
        "hard_iron_cov": _hard_iron_prior(Mm @ bias_cov @ Mm.T, F),
        "hard_iron_q": (HARD_IRON_WALK * F) ** 2,
    }


def _mass(scale: float, dof: int, edges: Array) -> Array:
    """The probability of each bin between ``edges`` of ``scale`` times a chi-square."""
    from scipy.stats import chi2

    return np.asarray(np.diff(chi2.cdf(edges / scale, dof)), dtype=float)


def rest_threshold(
    norm: tuple[float, float],
    dip: tuple[float, float],
    norm_model: tuple[float, float] | None = None,
    dip_model: tuple[float, float] | None = None,
    alpha: float = ALPHA,
) -> float:
    """The monitor's threshold: the ``1 − alpha`` quantile of its statistic (the mean ``d²`` of
    :data:`WINDOW` blocks of :data:`BLOCK` samples) for a device at rest, its worst case.

    Each channel's block mean errs by a part that a rest shares over the whole window (the
    pose-level error and the calibration's own, variance ``v``) plus the samples' noise
    (``s``, independent from block to block); the statistic divides by the model's variance
    ``v_m + s_m/B`` (for the dip, ``v_m`` also allows for the tilt that accelerations within
    the gate cause: none at rest). So a channel contributes ``c [ρ + (1 − ρ)/W] χ²(1) + c (1 −
    ρ)/W χ²(W − 1)`` with ``ρ = v/(v + s/B)`` and ``c = (v + s/B)/(v_m + s_m/B)``; the
    quantile of the sum of the four terms is found by convolving their distributions.
    In motion, blocks see different orientations (their shared parts decorrelate) and false
    alarms are rarer still. With every part shared (``ρ = 1``, ``c = 1``) this is ``−2 ln
    alpha``, the threshold of a single block.

    Parameters
    ----------
    norm, dip : (float, float)
        ``(v, s)`` of each channel at rest.
    norm_model, dip_model : (float, float), optional
        ``(v_m, s_m)`` the statistic divides by (default: ``norm``, ``dip``).
    alpha : float
        False alarms per block.

    Returns
    -------
    float
    """
    from scipy.signal import fftconvolve
    from scipy.stats import chi2

    terms: list[tuple[float, int]] = []
    for (v, s), (vm, sm) in ((norm, norm_model or norm), (dip, dip_model or dip)):
        total, model = v + s / BLOCK, vm + sm / BLOCK
        if not (total > 0 and model > 0):
            continue
        rho, c = v / total, total / model
        terms += [(c * (rho + (1 - rho) / WINDOW), 1), (c * (1 - rho) / WINDOW, WINDOW - 1)]
    terms = [(a, k) for a, k in terms if a > 1e-12]
    if not terms:
        return -2.0 * math.log(alpha)
    top = sum(a * chi2.ppf(1 - alpha / 10, k) for a, k in terms)  # beyond the quantile
    edges = np.linspace(0.0, top, 40_001)
    mass = np.array([1.0])
    for a, k in terms:
        mass = fftconvolve(mass, _mass(a, k, edges))[: len(edges) - 1]
    survival = 1.0 - np.cumsum(np.clip(mass, 0.0, None))
    # the upper edge of the first bin where the survival drops below alpha (errs on the safe side)
    return float(edges[1:][np.argmax(survival <= alpha)])


def sensor_id_of(cal: Calibration) -> int:
    """The sensor id the blob carries: CRC-32 of the calibration's device name, 0 without one."""
    device = cal.options.get("device")
    return zlib.crc32(str(device).encode("utf-8")) if device else 0


def factory(cal: Calibration, sensor_id: int | None = None) -> tuple[int, int, dict[str, Array]]:
    """``(sensor_id, flags, fields)``: the calibration as ``fieldcal_cal_t`` holds it.

    Parameters
    ----------
    cal : Calibration
    sensor_id : int or None
        The id a blob must carry to load (0 to 2³²−1); by default :func:`sensor_id_of`.

    Returns
    -------
    tuple
        The id, the ``FIELDCAL_HAS_*`` flags and every float field (float64 arrays, in
        ``_LAYOUT`` order, then the temperature fields when the calibration has terms)
        before rounding to float32.

    Raises
    ------
    InputError
        A sensor id outside 0 to 2³²−1, or a value a C float cannot hold.
    """
    sid = sensor_id_of(cal) if sensor_id is None else sensor_id
    if isinstance(sid, bool) or not isinstance(sid, int) or not 0 <= sid < 2**32:
        raise InputError(f"the sensor id must be an integer from 0 to 2^32-1, got {sid!r}")
    inv = {name: M for name, M, _ in corrections(cal)}
    fields: dict[str, Array] = {name: np.zeros(n) for name, n in _layout(cal)}
    flags = 0
    for name, M, b in corrections(cal):
        fields[f"{name}_matrix"] = M.reshape(9)
        fields[f"{name}_bias"] = b
        flags |= _FLAGS[name]
    for name in ("accel", "mag", "gyro"):
        if name not in inv:
            fields[f"{name}_matrix"] = np.eye(3).reshape(9)
    if cal.field_reference is not None:
        fields["declination_deg"] = np.array([cal.field_reference.declination_deg])
        flags |= _FLAGS["declination"]
    for name, model in temperature_terms(cal):
        head = [model.reference, *(float(t) for t in model.span)]
        fields[f"{name}_temp"] = np.concatenate([head, cubic(model).reshape(9)])
        flags |= _FLAGS["temperature"]
    monitor = _monitor(cal, inv)
    if monitor is not None:
        flags |= _FLAGS["monitor"]
        for key, value in monitor.items():
            fields[key] = np.atleast_1d(np.asarray(value, dtype=float)).reshape(-1)
    big = float(np.finfo(np.float32).max)
    for key, value in fields.items():
        if not (np.isfinite(value).all() and np.all(np.abs(value) <= big)):
            raise InputError(f"cannot export c-library: {key} does not fit a C float")
    _plausible(flags, fields)
    return sid, flags, fields


def blob(cal: Calibration, sensor_id: int | None = None) -> bytes:
    """The blob ``fieldcal_save`` writes for this calibration (the same bytes).

    Little-endian: magic ``"FDCL"``, version (uint16), float count (uint16), sensor id and
    flags (uint32), the floats (IEEE binary32) in ``_LAYOUT`` order (then the temperature
    fields: version 2), CRC-32 of all before it.

    Parameters
    ----------
    cal : Calibration
    sensor_id : int or None
        As :func:`factory`.

    Returns
    -------
    bytes
        :data:`BLOB_SIZE` bytes (with temperature terms, 144 more).
    """
    sid, flags, fields = factory(cal, sensor_id)
    layout = _layout(cal)
    floats = np.concatenate([fields[name] for name, _ in layout]).astype("<f4")
    version = VERSION_TEMPERATURE if len(layout) > len(_LAYOUT) else _VERSION
    head = struct.pack("<IHHII", _MAGIC, version, len(floats), sid, flags)
    body = head + floats.tobytes()
    return body + struct.pack("<I", zlib.crc32(body))


def _initializer(sid: int, flags: int, fields: dict[str, Array]) -> str:
    lines = ["const fieldcal_cal_t FIELDCAL_FACTORY = {", f"    {sid}u, /* sensor_id */"]
    lines.append(f"    0x{flags:x}u, /* flags */")
    layout = _LAYOUT + (_TEMPERATURE_LAYOUT if "accel_temp" in fields else ())
    for name, n in layout:
        values = ", ".join(c_float(float(v) + 0.0) for v in fields[name])
        lines.append(f"    {{{values}}}, /* {name} */" if n > 1 else f"    {values}, /* {name} */")
    lines.append("};")
    return "\n".join(lines)


def _source(name: str) -> str:
    return (resources.files(__package__) / "c_sources" / name).read_text(encoding="utf-8")


def _fill(text: str, values: dict[str, str]) -> str:
    """Each ``@KEY@`` replaced by its value; a line holding only an empty one is removed."""
    for key, value in values.items():
        mark = f"@{key}@"
        text = text.replace(mark + "\n", value + "\n" if value else "").replace(mark, value)
    return text


#: The C of the temperature terms (only in a library whose calibration has them).
_TEMPERATURE_FLAG = "#define FIELDCAL_HAS_TEMPERATURE 0x20u"
_TEMPERATURE_FIELDS = """\
    /* temperature terms, per sensor: T_ref, T_min, T_max (deg C), c1[3], c2[3], c3[3] (raw
     * units per K^k): bias(t) = bias + c1 d + c2 d^2 + c3 d^3, d = clamp(t, T_min, T_max) - T_ref;
     * all zero for a sensor without terms (its bias does not change with t) */
    float accel_temp[12], mag_temp[12], gyro_temp[12];"""
_TEMPERATURE_API = """\
/* The same with the die temperature t (deg C): the bias at t (FIELDCAL_HAS_TEMPERATURE;
 * a sensor without temperature terms has zero coefficients, so t changes nothing).
 * FIELDCAL_ERR_VALUE (out NaN) for a non-finite t, raw or result. */
int fieldcal_bias_at(const float temp[12], const float b[3], float t, float out[3]);
int fieldcal_accel_at(const fieldcal_cal_t *cal, const float raw[3], float t, float out[3]);
int fieldcal_mag_at(const fieldcal_cal_t *cal, const float raw[3], float t, float out[3]);
int fieldcal_gyro_at(const fieldcal_cal_t *cal, const float raw[3], float t, float out[3]);"""
_TEMPERATURE_CODE = """\

/* TEMPERATURE_FORMULA */
int fieldcal_bias_at(const float temp[12], const float b[3], float t, float out[3])
{
    float u;
    int j;
    if (out == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    if (temp == NULL || b == NULL || !isfinite(t)) {
        fc_nan3(out);
        return FIELDCAL_ERR_VALUE;
    }
    u = (t < temp[1] ? temp[1] : (t > temp[2] ? temp[2] : t)) - temp[0];
    for (j = 0; j < 3; j++) {
        out[j] = b[j] + ((temp[9 + j] * u + temp[6 + j]) * u + temp[3 + j]) * u;
    }
    if (!fc_finite3(out)) {
        fc_nan3(out);
        return FIELDCAL_ERR_VALUE;
    }
    return FIELDCAL_OK;
}

/* A sensor's terms: a span within -273.15..1000 deg C, the bias at both ends within bounds. */
static int fc_temperature_ok(const float temp[12], const float M[9], const float b[3])
{
    float bt[3], mb[3];
    int k, i;
    if (!(temp[0] >= -273.15f && temp[0] <= 1000.0f && temp[1] >= -273.15f &&
          temp[1] <= temp[2] && temp[2] <= 1000.0f)) {
        return 0;
    }
    for (k = 1; k <= 2; k++) {
        if (fieldcal_bias_at(temp, b, temp[k], bt) != FIELDCAL_OK) {
            return 0;
        }
        fc_mul(M, bt, mb);
        for (i = 0; i < 3; i++) {
            if (!(fabsf(mb[i]) <= FIELDCAL_BIAS_MAX)) {
                return 0;
            }
        }
    }
    return 1;
}

static int fc_sensor_at(int has, const float temp[12], const float M[9], const float b[3],
                        const float raw[3], float t, float out[3])
{
    float bt[3];
    int rc;
    if (out == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    if (!has) {
        fc_nan3(out);
        return FIELDCAL_ERR_MISSING;
    }
    rc = fieldcal_bias_at(temp, b, t, bt);
    return rc == FIELDCAL_OK ? fieldcal_apply(M, bt, raw, out) : rc;
}

int fieldcal_accel_at(const fieldcal_cal_t *cal, const float raw[3], float t, float out[3])
{
    if (cal == NULL) {
        return fc_sensor_at(0, NULL, NULL, NULL, raw, t, out);
    }
    return fc_sensor_at((cal->flags & FIELDCAL_HAS_ACCEL) != 0u, cal->accel_temp,
                        cal->accel_matrix, cal->accel_bias, raw, t, out);
}

int fieldcal_mag_at(const fieldcal_cal_t *cal, const float raw[3], float t, float out[3])
{
    if (cal == NULL) {
        return fc_sensor_at(0, NULL, NULL, NULL, raw, t, out);
    }
    return fc_sensor_at((cal->flags & FIELDCAL_HAS_MAG) != 0u, cal->mag_temp, cal->mag_matrix,
                        cal->mag_bias, raw, t, out);
}

int fieldcal_gyro_at(const fieldcal_cal_t *cal, const float raw[3], float t, float out[3])
{
    if (cal == NULL) {
        return fc_sensor_at(0, NULL, NULL, NULL, raw, t, out);
    }
    return fc_sensor_at((cal->flags & FIELDCAL_HAS_GYRO) != 0u, cal->gyro_temp,
                        cal->gyro_matrix, cal->gyro_bias, raw, t, out);
}""".replace("TEMPERATURE_FORMULA", TEMPERATURE_FORMULA)
_TEMPERATURE_CHECK = """\
    if (((flags & FIELDCAL_HAS_ACCEL) &&
         !fc_temperature_ok(cal->accel_temp, cal->accel_matrix, cal->accel_bias)) ||
        ((flags & FIELDCAL_HAS_MAG) &&
         !fc_temperature_ok(cal->mag_temp, cal->mag_matrix, cal->mag_bias)) ||
        ((flags & FIELDCAL_HAS_GYRO) &&
         !fc_temperature_ok(cal->gyro_temp, cal->gyro_matrix, cal->gyro_bias))) {
        return FIELDCAL_ERR_VALUE;
    }"""
_TEMPERATURE_BLOB = """\
    for (i = 0; i < 12; i++) f[n++] = &c->accel_temp[i];
    for (i = 0; i < 12; i++) f[n++] = &c->mag_temp[i];
    for (i = 0; i < 12; i++) f[n++] = &c->gyro_temp[i];"""


def _interference(cal: Calibration) -> tuple[str, str]:
    """The C of the magnetometer's interference term (:mod:`fieldcal.interference`), when the
    calibration has one the log identified: constants beside the calibration (its struct and
    blob are unchanged), and ``fieldcal_mag_driven`` taking ``c (u − u_ref)`` off the raw
    reading before the calibration, ``u`` the input the term was fitted in."""
    model = None if cal.mag is None else cal.mag.interference
    if model is None or not model.identifiable:
        return "", ""
    name, unit = model.inputs[0], model.units[0]
    c = ", ".join(c_float(float(v)) for v in model.coefficients[0])
    api = (
        f"/* The magnetometer with its interference term: u is the {name} ({unit}); the raw\n"
        f" * reading less FIELDCAL_INTERFERENCE_C * (u - FIELDCAL_INTERFERENCE_REF), then\n"
        " * fieldcal_mag. */\n"
        "#define FIELDCAL_HAS_INTERFERENCE 1\n"
        f"#define FIELDCAL_INTERFERENCE_REF {c_float(float(model.reference[0]))}\n"
        "extern const float FIELDCAL_INTERFERENCE_C[3]; /* raw units per unit of u */\n"
        "void fieldcal_mag_driven(const fieldcal_cal_t *cal, const float raw[3], float u, "
        "float out[3]);"
    )
    code = (
        f"\nconst float FIELDCAL_INTERFERENCE_C[3] = {{{c}}};\n\n"
        "void fieldcal_mag_driven(const fieldcal_cal_t *cal, const float raw[3], float u, "
        "float out[3])\n{\n"
        "    const float d = u - FIELDCAL_INTERFERENCE_REF;\n"
        "    float r[3];\n"
        "    int j;\n"
        "    for (j = 0; j < 3; j++) {\n"
        "        r[j] = raw[j] - FIELDCAL_INTERFERENCE_C[j] * d;\n"
        "    }\n"
        "    fieldcal_mag(cal, r, out);\n"
        "}"
    )
    return api, code


def files(cal: Calibration, sensor_id: int | None = None) -> dict[str, str]:
    """``fieldcal_cal.h`` and ``fieldcal_cal.c`` for this calibration.

    Parameters
    ----------
    cal : Calibration
    sensor_id : int or None
        As :func:`factory`.

    Returns
    -------
    dict of str to str
        File name -> text; both compile with ``cc -std=c99 -Wall -Wextra -Werror``.
    """
    sid, flags, fields = factory(cal, sensor_id)
    prov = "\n".join(f" * {line}" for line in ["Written by fieldcal.", *provenance(cal)])
    defines = [
        f"#define FIELDCAL_SENSOR_ID {sid}u",
        f"#define FIELDCAL_MONITOR_ALPHA {c_float(ALPHA)} /* false alarms per block, at most */",
    ]
    thermal = "accel_temp" in fields
    parts = {
        "PROVENANCE": prov,
        "DEFINES": "\n".join(defines),
        "BLOB_VERSION": str(VERSION_TEMPERATURE if thermal else _VERSION),
        "N_FLOATS": str(N_FLOATS_TEMPERATURE if thermal else N_FLOATS),
        "TEMPERATURE_FLAG": _TEMPERATURE_FLAG if thermal else "",
        "TEMPERATURE_FIELDS": _TEMPERATURE_FIELDS if thermal else "",
        "TEMPERATURE_API": _TEMPERATURE_API if thermal else "",
        "TEMPERATURE_CODE": _TEMPERATURE_CODE if thermal else "",
        "TEMPERATURE_BLOB": _TEMPERATURE_BLOB if thermal else "",
        "TEMPERATURE_CHECK": _TEMPERATURE_CHECK if thermal else "",
        "KNOWN_FLAGS": f"0x{_known_flags(thermal):x}u",
        "FACTORY": _initializer(sid, flags, fields),
    }
    parts["INTERFERENCE_API"], parts["INTERFERENCE_CODE"] = _interference(cal)
    header = _fill(_source("fieldcal_cal.h"), parts)
    source = _fill(_source("fieldcal_cal.c"), parts)
    # the pair's mark (FIELDCAL_PAIR_ID): a digest of both texts, so a header from another
    # export (another calibration, another fieldcal) stops the build with #error
    pair = {"PAIR_ID": f"0x{zlib.crc32((header + source).encode('utf-8')):08x}u"}
    return {"fieldcal_cal.h": _fill(header, pair), "fieldcal_cal.c": _fill(source, pair)}


def write(cal: Calibration, sensor_id: int | None = None) -> str:
    """Refuse: the library is two files, written into a folder (``-o DIR``).

    Raises
    ------
    InputError
        Always, after the checks every export makes.
    """
    factory(cal, sensor_id)
    raise InputError(
        "the c-library format is a folder of two files (fieldcal_cal.h, fieldcal_cal.c): "
        "write it with -o DIR"
    )
