"""Noise characterisation of a log: Allan deviation of each sensor over its still parts, the
white-noise density, bias instability and rate random walk fitted to it, and the ``imu.yaml``
Kalibr and OpenVINS read.

:func:`characterise_noise` reads a log as ``fieldcal calibrate`` does, finds where the device
rests (or takes the whole log as one long still recording), computes the overlapping Allan
deviation of every axis over those stretches (:mod:`fieldcal.stats.allan`) and fits the noise
model to it. :meth:`NoiseReport.kalibr_yaml` writes the result in Kalibr's units.

Still stretches
---------------
``still="auto"`` runs fieldcal's still detector (:func:`fieldcal.logs.stillness.detect_still`:
0.5 s windows, rests of at least 1 s) and, when one still interval covers at least
:data:`WHOLE_LOG` of the log, takes the whole log as one still recording (the detector's
trimming and a few noisy windows would otherwise cut a long recording into pieces and lose the
long τ); otherwise the intervals found. ``still="detect"`` always uses the intervals,
``still="all"`` always the whole log. Stretches are also cut where rows were dropped (NaN), at
resets of the clock (``Log.segment``) and at pauses of the logger (a time step longer than
:data:`GAP` sample periods). The stretches are never concatenated: the Allan variance of each τ
adds the stretches long enough for it, weighted by their cluster counts
(:func:`fieldcal.stats.allan.allan_deviation`), so the long τ come from the longest stretches
and a step between two poses' readings is never read as noise.

Units
-----
The accelerometer's and gyroscope's units are needed for the yaml (Kalibr wants m/s² and
rad/s). They come from, in order: the calibration (``cal``: its corrected readings are in
``cal.units``: ``|g| = 1`` is g, ``|g| = 9.80665`` (or any value within 2 % of it) is m/s²;
the gyroscope in rad/s), the options ``accel_unit`` / ``gyro_unit`` (a unit name, or a number:
SI units per raw unit, for raw counts), the column names (``ax_g``, ``gx_dps``, ``acc_x_mps2``,
``gyr_x_rad_s``). When none says, the fit is reported in raw units and
:meth:`NoiseReport.kalibr_yaml` refuses, naming the option.

One number per sensor
---------------------
Kalibr takes one noise density and one random walk per sensor. fieldcal writes the **largest of
the three axes** (the conservative choice for a filter: an axis whose noise is underrated is
trusted too much), and lists every axis in a comment. A random walk the data do not resolve
(fitted value under two standard errors, as in a short recording) is written as its upper
bound ``K + 2σ_K``, and the yaml says so.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._frozen import ArrayDataclass
from ._version import __version__
from .calibration import Calibration
from .errors import InputError
from .imu_yaml import IMU_YAML_FORMATS, ImuNoise, imu_yaml
from .logs.inputs import read_log
from .logs.log import Log
from .logs.stillness import detect_still
from .reading_units import (
    SI_NAMES,
    STANDARD_GRAVITY,
    UNIT_OPTIONS,
    UNITS,
    calibration_unit,
    column_unit,
    option_unit,
)
from .stats.allan import AllanDeviation, allan_deviation
from .stats.allan_model import NoiseModel, fit_noise_model

__all__ = [
    "GAP",
    "IMU_YAML_FORMATS",
    "SENSORS",
    "STANDARD_GRAVITY",
    "STILL_MODES",
    "WHOLE_LOG",
    "ImuNoise",
    "NoiseFit",
    "NoiseReport",
    "characterise_noise",
    "imu_yaml",
]

Array = NDArray[np.float64]

#: The sensors characterised, in report order.
SENSORS = ("accel", "gyro", "mag")
#: How the still stretches are chosen (``still=``).
STILL_MODES = ("auto", "detect", "all")
#: ``still="auto"``: one still interval covering this share of the log makes it one still
#: recording.
WHOLE_LOG = 0.9
#: A time step longer than this many sample periods ends a stretch (a pause of the logger).
GAP = 5.0
#: Still detection: the window and the shortest rest, in seconds (as ``fieldcal calibrate``).
_WINDOW_S, _MIN_STILL_S = 0.5, 1.0

_NAMES = {"accel": "accelerometer", "gyro": "gyroscope", "mag": "magnetometer"}


@dataclass(frozen=True, eq=False)
class NoiseFit(ArrayDataclass):
    """One sensor's Allan deviation and noise model, per axis (x, y, z).

    Values are in ``unit`` (the readings as analysed: raw, or corrected by the calibration);
    ``si_scale`` converts them to m/s² (accelerometer) or rad/s (gyroscope).

    Attributes
    ----------
    sensor : str
        ``"accel"``, ``"gyro"`` or ``"mag"``.
    unit : str
        Unit of the readings analysed (``"g"``, ``"m/s^2"``, ``"deg/s"``, ``"rad/s"``, a
        calibration's unit, or ``"raw"``).
    si_scale : float or None
        SI units (m/s², rad/s) per ``unit``; ``None`` when unknown (or for the magnetometer).
    curve : AllanDeviation
        Taus (s), Allan deviation and its confidence band per axis, with the EDF of the
        fitted model's dominant noise type.
    model : NoiseModel
        N, B, K per axis with standard errors, the τ range fitted.
    """

    sensor: str
    unit: str
    si_scale: float | None
    curve: AllanDeviation
    model: NoiseModel

    @property
    def taus(self) -> Array:
        """Averaging times (s)."""
        return self.curve.taus

    @property
    def adev(self) -> Array:
        """(k, 3) Allan deviation (``unit``)."""
        return self.curve.adev

    @property
    def lower(self) -> Array:
        """(k, 3) lower end of the confidence band."""
        return self.curve.lower

    @property
    def upper(self) -> Array:
        """(k, 3) upper end of the confidence band."""
        return self.curve.upper

    @property
    def noise_density(self) -> Array:
        """N per axis: ``unit``/√Hz (the −½ line at τ = 1 s)."""
        return self.model.noise_density

    @property
    def noise_density_std(self) -> Array:
        return self.model.noise_density_std

    @property
    def random_walk(self) -> Array:
        """K per axis: ``unit``/s/√Hz (the +½ line at τ = 3 s)."""
        return self.model.random_walk

    @property
    def random_walk_std(self) -> Array:
        return self.model.random_walk_std

    @property
    def bias_instability(self) -> Array:
        """B per axis: ``unit`` (the flat floor over 0.664)."""
        return self.model.bias_instability

    @property
    def bias_instability_std(self) -> Array:
        return self.model.bias_instability_std

    @property
    def tau_range(self) -> tuple[float, float]:
        """Shortest and longest τ fitted (s)."""
        return self.model.tau_range

    @property
    def random_walk_resolved(self) -> NDArray[np.bool_]:
        """Per axis: whether the random walk exceeds two standard errors."""
        return np.asarray(self.random_walk > 2.0 * self.random_walk_std)

    def to_dict(self) -> dict[str, Any]:
        """The fit and the curve as plain numbers and lists, for JSON."""
        return {
            "unit": self.unit,
            "si_unit": SI_NAMES.get(self.sensor) if self.si_scale is not None else None,
            "si_scale": self.si_scale,
            **self.model.to_dict(),
            "random_walk_resolved": self.random_walk_resolved.tolist(),
            "curve": {
                "taus": self.taus.tolist(),
                "adev": self.adev.tolist(),
                "lower": self.lower.tolist(),
                "upper": self.upper.tolist(),
                "edf": self.curve.edf.tolist(),
                "confidence": self.curve.confidence,
            },
        }


@dataclass(frozen=True, eq=False)
class NoiseReport(ArrayDataclass):
    """The noise of each sensor of a log, from its still stretches.

    Attributes
    ----------
    source : str
        The log (its path, or ``<table>`` for one given in memory).
    rate : float
        Samples per second used for τ.
    still : str
        ``"all"`` (the whole log as one still recording) or ``"detect"`` (still intervals).
    stretches : tuple of (int, int)
        The stretches analysed, as data rows ``[start, stop)`` of the file (0-based).
    fits : dict of str to NoiseFit
        One entry per sensor characterised (``"accel"``, ``"gyro"``, ``"mag"``).
    notes : tuple of str
        How the stretches and units were chosen, and what to look out for.
    version : str
        fieldcal's version.
    """

    source: str
    rate: float
    still: str
    stretches: tuple[tuple[int, int], ...]
    fits: dict[str, NoiseFit]
    notes: tuple[str, ...] = ()
    version: str = __version__

    @property
    def samples(self) -> int:
        """Samples in the stretches analysed."""
        return int(sum(b - a for a, b in self.stretches))

    @property
    def seconds(self) -> float:
        """Duration of the stretches analysed (s)."""
        return self.samples / self.rate

    @property
    def longest(self) -> float:
        """Duration of the longest stretch (s)."""
        return max((b - a for a, b in self.stretches), default=0) / self.rate

    def to_dict(self) -> dict[str, Any]:
        """The report as plain numbers, lists and strings, for JSON."""
        return {
            "source": self.source,
            "fieldcal_version": self.version,
            "rate": self.rate,
            "still": self.still,
            "stretches": [list(s) for s in self.stretches],
            "samples": self.samples,
            "seconds": self.seconds,
            "longest_s": self.longest,
            "model": "sigma^2(tau) = N^2/tau + B^2 (2 ln 2/pi) + K^2 tau/3",
            "sensors": {name: fit.to_dict() for name, fit in self.fits.items()},
            "notes": list(self.notes),
        }

    def kalibr_yaml(self) -> str:
        """The ``imu.yaml`` of Kalibr: noise densities and random walks in SI.

        Keys: ``accelerometer_noise_density`` [m/s²/√Hz], ``accelerometer_random_walk``
        [m/s³/√Hz], ``gyroscope_noise_density`` [rad/s/√Hz], ``gyroscope_random_walk``
        [rad/s²/√Hz], ``rostopic``, ``update_rate`` [Hz]. Each value is the largest of the
        three axes (every axis in a comment); an unresolved random walk is written as its
        upper bound ``K + 2σ``. The measured values are written as they are: Kalibr's
        documentation advises larger ones for calibration, which the comments say and
        fieldcal does not apply. Written by :func:`imu_yaml`, as ``fieldcal export``'s.

        Returns
        -------
        str

        Raises
        ------
        InputError
            The log has no accelerometer or gyroscope, or their units are unknown.
        """
        return imu_yaml(self.imu_noise(), "kalibr", header=self._yaml_header())

    def openvins_yaml(self) -> str:
        """OpenVINS' ``kalibr_imu_chain.yaml``: ``%YAML:1.0`` and the ``imu0`` block.

        The same figures as :meth:`kalibr_yaml`, written by :func:`imu_yaml`.

        Returns
        -------
        str

        Raises
        ------
        InputError
            As :meth:`kalibr_yaml`.
        """
        return imu_yaml(self.imu_noise(), "openvins", header=self._yaml_header())

    def _yaml_header(self) -> list[str]:
        how = "the whole log as one still recording" if self.still == "all" else "still intervals"
        return [
            f"written by fieldcal {self.version} (fieldcal noise) from {self.source}",
            f"{self.samples} still samples in {len(self.stretches)} stretch(es): "
            f"{self.seconds:.1f} s, the longest {self.longest:.1f} s, at {self.rate:.6g} Hz "
            f"({how})",
            "Allan deviation fit per axis: sigma^2(tau) = N^2/tau + B^2 (2 ln2/pi) + K^2 tau/3;",
            "each value is the LARGEST of the three axes (x, y, z in its comment).",
            "These are the figures of a still sensor at one temperature. Kalibr's wiki (IMU",
            "Noise Model) advises larger values for calibration, to cover unmodelled effects;",
            "OpenVINS' example configurations inflate them (e.g. x5 the densities, x10 the",
            "random walks). fieldcal does NOT inflate them: scale them up if you follow that.",
        ]

    def imu_noise(self) -> ImuNoise:
        """The four figures of an ``imu.yaml`` in SI units, with a comment for each.

        Returns
        -------
        ImuNoise

        Raises
        ------
        InputError
            The log has no accelerometer or gyroscope, or their units are unknown.
        """
        values: dict[str, float] = {}
        notes: dict[str, str] = {}
        for sensor, word in (("accel", "accelerometer"), ("gyro", "gyroscope")):
            fit = self.fits.get(sensor)
            if fit is None:
                raise InputError(
                    f"{self.source}: no {_NAMES[sensor]} was characterised; an imu.yaml "
                    f"needs both the accelerometer and the gyroscope (pass --{sensor}-cols)"
                )
            if fit.si_scale is None:
                raise InputError(
                    f"{self.source}: the {_NAMES[sensor]}'s unit is unknown; pass "
                    f"{UNIT_OPTIONS[sensor]} (one of {', '.join(UNITS[sensor])}, or SI units per "
                    "raw unit) or a calibration"
                )
            si = SI_NAMES[sensor]
            density = fit.noise_density * fit.si_scale
            walk = fit.random_walk * fit.si_scale
            walk_std = fit.random_walk_std * fit.si_scale
            resolved = fit.random_walk_resolved
            written = np.where(resolved, walk, walk + 2.0 * walk_std)
            axis_n = int(np.argmax(density))
            axis_k = int(np.argmax(written))
            conversion = "" if fit.si_scale == 1.0 else f", from {fit.unit} x {fit.si_scale:.8g}"
            values[f"{word}_noise_density"] = float(density[axis_n])
            notes[f"{word}_noise_density"] = (
                f"[{si}/sqrt(Hz)] white noise, axis {'xyz'[axis_n]}; x,y,z: {_triple(density)}"
                f"{conversion}; tau {_range(fit)}"
            )
            if resolved[axis_k]:
                how = f"bias random walk, axis {'xyz'[axis_k]}"
            else:
                how = (
                    f"UPPER BOUND K + 2 sigma (axis {'xyz'[axis_k]}): the still data do not "
                    "resolve the random walk; record longer"
                )
            walk_unit = "m/s^3" if sensor == "accel" else "rad/s^2"
            values[f"{word}_random_walk"] = float(written[axis_k])
            notes[f"{word}_random_walk"] = (
                f"[{walk_unit}/sqrt(Hz)] {how}; K x,y,z: {_triple(walk)} +- {_triple(walk_std)}"
            )
        notes["update_rate"] = "[Hz] the log's sample rate (discretises the densities)"
        return ImuNoise(
            rate=float(self.rate),
            accel_density=values["accelerometer_noise_density"],
            accel_walk=values["accelerometer_random_walk"],
            gyro_density=values["gyroscope_noise_density"],
            gyro_walk=values["gyroscope_random_walk"],
            notes=notes,
        )


def _triple(values: Array) -> str:
    return ", ".join(f"{v:.3e}" for v in values)


def _range(fit: NoiseFit) -> str:
    a, b = fit.tau_range
    return f"{a:.3g}-{b:.3g} s"


def _check_varies(values: Array, ranges: Sequence[tuple[int, int]], sensor: str, path: str) -> None:
    """Refuse an axis whose still readings never change: no sensor has zero noise (an ADC
    flips at least its last count), so it is a placeholder column or a stuck sensor, and the
    Allan fit of a zero curve has nothing to fit."""
    for j in range(values.shape[1]):
        if all(np.ptp(values[a:b, j]) == 0 for a, b in ranges if b > a):
            raise InputError(
                f"{path}: the {_NAMES[sensor]}'s {'xyz'[j]} axis reads the same value in every "
                "still row: no noise to measure (a stuck sensor or a placeholder column); check "
                "the columns"
            )


# --------------------------------------------------------------------------- stretches
def _contiguous(log: Log, rate: float) -> NDArray[np.int64]:
    """Starts of the log's contiguous pieces (kept rows, plus ``log.n`` at the end): rows
    dropped in between, a reset of the clock, or a pause of more than :data:`GAP` periods end
    a piece."""
    n = log.n
    cut = np.zeros(max(n - 1, 0), dtype=bool)
    if n > 1:
        cut |= np.diff(log.index) != 1
        if log.segment is not None:
            cut |= np.diff(log.segment) != 0
        if log.time is not None:
            cut |= np.diff(log.time) > GAP / rate
    return np.concatenate([[0], np.flatnonzero(cut) + 1, [n]]).astype(np.int64)


def _split(pieces: Sequence[tuple[int, int]], edges: NDArray[np.int64]) -> list[tuple[int, int]]:
    """``pieces`` cut at ``edges`` (sorted row positions)."""
    out: list[tuple[int, int]] = []
    for a, b in pieces:
        inside = edges[(edges > a) & (edges < b)]
        bounds = [a, *(int(e) for e in inside), b]
        out.extend((lo, hi) for lo, hi in itertools.pairwise(bounds) if hi > lo)
    return out


def _stretches(log: Log, rate: float, still: str) -> tuple[list[tuple[int, int]], str, list[str]]:
    """The still stretches (kept-row ranges), the mode used, notes."""
    edges = _contiguous(log, rate)
    whole = [(int(a), int(b)) for a, b in itertools.pairwise(edges) if b > a]
    notes: list[str] = []
    if still == "all":
        notes.append("the whole log taken as one still recording (still='all')")
        return whole, "all", notes
    ref = log.accel if log.accel is not None else log.gyro if log.gyro is not None else log.mag
    if ref is None:  # pragma: no cover - load_log needs one of the sensors
        raise InputError(f"{log.path}: no sensor columns; name them ax,ay,az,gx,gy,gz")
    gyro = log.gyro if log.accel is not None else None
    window = max(3, round(_WINDOW_S * rate))
    detection = detect_still(
        ref,
        gyro,
        window=window,
        min_samples=max(3, round(_MIN_STILL_S * rate)),
        segment=log.segment,
    )
    pieces = [p for s in detection.segments for p in (s.pieces or ((s.start, s.stop),))]
    covered = sum(b - a for a, b in pieces)
    longest = max((s.stop - s.start for s in detection.segments), default=0)
    if still == "auto" and log.n and longest >= WHOLE_LOG * log.n:
        notes.append(
            f"one still interval covers {longest / log.n:.0%} of the log: the whole log taken "
            "as one still recording (still='detect' to use the intervals only)"
        )
        return whole, "all", notes
    notes.append(
        f"{len(detection.segments)} still interval(s) detected, covering "
        f"{covered / max(log.n, 1):.0%} of the log"
        + (" (still='all' to take the whole log)" if still == "auto" else "")
    )
    return _split(pieces, edges[1:-1]), "detect", notes


# --------------------------------------------------------------------------- the entry
def _one_thread() -> contextlib.AbstractContextManager[object]:
    """BLAS limited to one thread: the dot products and 50x50 eigen-decompositions here are
    far slower with threads contending on a shared machine (as ``fieldcal.calibrate``)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency, but not needed for correctness
        return contextlib.nullcontext()
    return threadpool_limits(limits=1)


def _calibration(cal: object) -> Calibration | None:
    if cal is None or isinstance(cal, Calibration):
        return cal
    if isinstance(cal, str | os.PathLike):
        try:
            text = Path(cal).read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{cal}: cannot read the calibration ({exc.strerror})") from None
        return Calibration.from_json(text)
    raise InputError(
        f"cal must be a Calibration or the path of its JSON file, got {type(cal).__name__}"
    )


def _rate(log: Log, rate: float | None) -> float:
    measured = log.rate
    if rate is None:
        if measured is None:
            raise InputError(
                f"{log.path}: no time column to give the sample rate; pass rate= (--rate) in Hz"
            )
        return float(measured)
    ok = not isinstance(rate, (bool, np.bool_)) and isinstance(rate, (int, float, np.number))
    hz = float(rate) if ok else math.nan
    if not (math.isfinite(hz) and hz > 0):
        raise InputError(f"rate must be a positive number of samples per second, got {rate!r}")
    if measured is not None and abs(hz / measured - 1.0) > 0.05:
        warnings.warn(
            f"{log.path}: the rate given ({hz:g} Hz) and the time column's ({measured:.4g} Hz) "
            "differ by more than 5 %; τ uses the rate given",
            UserWarning,
            stacklevel=3,
        )
    return hz


def _sensors(log: Log, sensors: Sequence[str] | None) -> list[str]:
    present = [s for s in SENSORS if getattr(log, s) is not None]
    if sensors is None:
        if not present:  # pragma: no cover - load_log needs one of the sensors
            raise InputError(f"{log.path}: no accelerometer, gyroscope or magnetometer columns")
        return present
    if isinstance(sensors, str):
        sensors = [sensors]
    out = []
    for s in sensors:
        if s not in SENSORS:
            raise InputError(f"sensors must be among {', '.join(SENSORS)}; got {s!r}"[:200])
        if getattr(log, s) is None:
            raise InputError(
                f"{log.path}: no {_NAMES[s]} columns found; pass --{s}-cols or leave {s} out"
            )
        out.append(s)
    return list(dict.fromkeys(out))


def _readings(
    log: Log, sensor: str, cal: Calibration | None, option: object
) -> tuple[Array, str, float | None, str | None]:
    """The readings analysed, their unit, SI factor and a note."""
    raw = np.asarray(getattr(log, sensor), dtype=float)
    given = option_unit(option, sensor) if sensor in UNITS else None
    if cal is not None and getattr(cal, sensor) is not None:
        unit, si = calibration_unit(cal, sensor)
        if given is not None and (given[0] != unit or given[0] == "raw"):
            raise InputError(
                f"{UNIT_OPTIONS[sensor].split()[0]}={option!r}, but the calibration gives the "
                f"{_NAMES[sensor]} in {unit}; leave {UNIT_OPTIONS[sensor].split()[0]} out"
            )
        corrected = cal.sensor(sensor).correct(raw)
        return corrected, unit, si, f"{_NAMES[sensor]} corrected by the calibration ({unit})"
    if given is not None:
        return raw, given[0], given[1], None
    if sensor in UNITS:
        unit_name = column_unit(log.used.get(sensor, []), sensor)
        if unit_name is not None:
            note = f"{_NAMES[sensor]} in {unit_name}, from its column names"
            return raw, unit_name, UNITS[sensor][unit_name], note
    return raw, "raw", None, None


def _fit_sensor(
    sensor: str,
    stretches: list[Array],
    hz: float,
    unit: str,
    si: float | None,
    notes: list[str],
    per_decade: float,
    confidence: float,
    tau_min: float | None,
    tau_max: float | None,
) -> NoiseFit:
    """One sensor's Allan deviation over the still ``stretches`` and its noise model, with the
    notes the fit calls for (a low-pass filter before sampling, a random walk not resolved)
    appended to ``notes``."""
    curve = allan_deviation(stretches, hz, per_decade=per_decade, confidence=confidence)
    model = fit_noise_model(curve, tau_min=tau_min, tau_max=tau_max)
    if model.low_pass:
        notes.append(
            f"{_NAMES[sensor]}: the shortest τ lie below the white-noise line (a low-pass "
            f"filter before sampling); fitted from τ = {model.tau_range[0]:.3g} s"
        )
    fit = NoiseFit(
        sensor=sensor,
        unit=unit,
        si_scale=si,
        curve=curve.with_edf(model.edf),
        model=model,
    )
    unresolved = ~fit.random_walk_resolved
    if sensor in UNITS and np.any(unresolved):
        notes.append(
            f"{_NAMES[sensor]}: the random walk is not resolved on axis "
            f"{','.join('xyz'[j] for j in np.flatnonzero(unresolved))} (fit up to "
            f"τ = {model.tau_range[1]:.3g} s); the yaml gets its upper bound"
        )
    return fit


@contextlib.contextmanager
def _quiet_numpy() -> Iterator[None]:
    with np.errstate(under="ignore"):
        yield


def characterise_noise(
    source: Log | str | os.PathLike[str] | object,
    *,
    cal: Calibration | str | os.PathLike[str] | None = None,
    sensors: Sequence[str] | None = None,
    still: str = "auto",
    rate: float | None = None,
    accel_unit: str | float | None = None,
    gyro_unit: str | float | None = None,
    per_decade: float = 10,
    confidence: float = 0.683,
    tau_min: float | None = None,
    tau_max: float | None = None,
    **reading: Any,
) -> NoiseReport:
    """Allan deviation and noise model of each sensor of a log, over its still stretches.

    Parameters
    ----------
    source : path, DataFrame, pyarrow Table, mapping or Log
        The log, read by :func:`fieldcal.logs.inputs.read_log` (columns recognised by name).
    cal : Calibration or path, optional
        A calibration (or its JSON file): the sensors it calibrates are analysed as it corrects
        them, in its units (``cal.units``), the gyroscope in rad/s.
    sensors : sequence of str, optional
        Among ``"accel"``, ``"gyro"``, ``"mag"``; default every one the log has.
    still : {"auto", "detect", "all"}
        Still intervals detected, the whole log as one still recording, or ``"auto"``: the
        whole log when one still interval covers at least :data:`WHOLE_LOG` of it.
    rate : float, optional
        Samples per second; default the time column's (:func:`fieldcal.logs.sample_rate`).
    accel_unit, gyro_unit : str or float, optional
        The raw columns' units (``"g"``, ``"mg"``, ``"m/s^2"``; ``"deg/s"``, ``"rad/s"``), or SI
        units per raw unit for raw counts; by default from the column names.
    per_decade : float
        Averaging times per decade of τ.
    confidence : float
        Probability of the Allan deviation's confidence band (68.3 %: one sigma).
    tau_min, tau_max : float, optional
        The τ range of the fit (s); by default chosen from the data
        (:func:`fieldcal.stats.allan.fit_noise_model`).
    **reading
        Column and reader options of :func:`~fieldcal.logs.inputs.read_log`
        (``accel_cols``, ``gyro_cols``, ``mag_cols``, ``time_col``, ``drop_nan``,
        ``split_on_reset``, ``decimal`` ...).

    Returns
    -------
    NoiseReport

    Raises
    ------
    InputError
        Unreadable log or options, no sample rate, no still stretch long enough for τ = 1 s
        (2 s of still data), a unit option that contradicts the calibration.
    """
    if still not in STILL_MODES:
        raise InputError(f"still must be one of {', '.join(STILL_MODES)}; got {still!r}"[:200])
    calibration = _calibration(cal)
    reading.setdefault("need", ("accel", "mag", "gyro"))
    log = read_log(source, **reading)
    hz = _rate(log, rate)
    chosen = _sensors(log, sensors)
    with _one_thread(), _quiet_numpy():
        ranges, mode, notes = _stretches(log, hz, still)
        one_second = round(hz)
        longest = max((b - a for a, b in ranges), default=0)
        if longest < 2 * one_second:
            raise InputError(
                f"{log.path}: no still part long enough for τ = 1 s (the longest still stretch "
                f"is {longest / hz:.2f} s; τ needs 2τ of still data): record at least 2 s still, "
                "better minutes (hours for the random walk)"
            )
        fits: dict[str, NoiseFit] = {}
        for sensor in chosen:
            option = {"accel": accel_unit, "gyro": gyro_unit}.get(sensor)
            values, unit, si, note = _readings(log, sensor, calibration, option)
            if note:
                notes.append(note)
            _check_varies(values, ranges, sensor, log.path)
            curves = [values[a:b] for a, b in ranges]
            fits[sensor] = _fit_sensor(
                sensor, curves, hz, unit, si, notes, per_decade, confidence, tau_min, tau_max
            )
    stretches = tuple((int(log.index[a]), int(log.index[b - 1]) + 1) for a, b in ranges)
    return NoiseReport(
        source=log.path,
        rate=hz,
        still=mode,
        stretches=stretches,
        fits=fits,
        notes=tuple(notes),
    )
