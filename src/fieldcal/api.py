"""``fieldcal.calibrate``: validate the input, summarise the poses, run the method through the
shared trust path, then express the result in the user's units and handedness.

:func:`calibrate` takes the options as keywords (their defaults are the fields' of
:class:`~fieldcal.settings.FitSettings` and :class:`~fieldcal.settings.TrustSettings`);
:func:`calibrate_with` takes them as those settings objects (the log pipeline's way in). Either
way they are checked once, here, with one line per problem.

This module names no method: :mod:`fieldcal.methods` validates and dispatches.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib
import numbers
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .calibration import Calibration
from .errors import InputError
from .limits import RANGE_TEXT, in_range
from .methods import Method
from .methods import get as get_method
from .reference import FieldReference, expected_field
from .settings import (
    OPTIONS,
    TARGET_OPTIONS,
    DateSpec,
    FitSettings,
    LocationSpec,
    NoiseSpec,
    PoseNoiseSpec,
    TrustSettings,
    renamed,
    settings_of,
    wmm_unit,
)
from .stats.noise_models import noise_covariance, per_sensor, pose_noise_value
from .stats.pose_stats import PoseStats, Samples, brief, summarize_scaled
from .stats.pose_temperature import pose_temperatures
from .stats.scaling import normalise
from .trust.handedness import decide as decide_handedness
from .trust.targets import DEFAULT_TARGETS, Targets
from .trust.verdict import with_late_checks

if TYPE_CHECKING:
    from threadpoolctl import ThreadpoolController

    from .likelihood.temperature import with_temperature_terms
    from .trust.fitting import fit_trusted
else:

    def with_temperature_terms(*args, **kwargs):
        """The temperature terms' span rule and order test (:func:`fieldcal.likelihood.
        temperature.with_temperature_terms`), imported on the first call (SciPy)."""
        module = importlib.import_module(".likelihood.temperature", __package__)
        return module.with_temperature_terms(*args, **kwargs)

    def fit_trusted(*args, **kwargs):
        """The shared trust path (:func:`fieldcal.trust.fitting.fit_trusted`), imported on the
        first call: it needs SciPy, which ``import fieldcal`` does not load. The type checker
        sees the real function, so every call is checked."""
        return importlib.import_module(".trust.fitting", __package__).fit_trusted(*args, **kwargs)


__all__ = [
    "NoiseSpec",
    "PoseNoiseSpec",
    "calibrate",
    "calibrate_with",
    "check_targets",
    "field_settings",
    "targets_for",
]

#: The defaults of the keywords, from the option table (:mod:`fieldcal.settings`).
_FIT, _TRUST = FitSettings(), TrustSettings()


@functools.cache
def _blas() -> ThreadpoolController:
    """One cached controller: limiting threads through it costs microseconds, not the
    milliseconds of re-scanning the loaded BLAS libraries on every call."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def _one_thread() -> Iterator[None]:
    """Every thread pool the controller found (BLAS, OpenMP) at one thread while the fit runs,
    as ``_blas().limit(limits=1)`` would do, setting only the pools not at one already and
    restoring them after (about 5 µs against that call's 15 µs of bookkeeping)."""
    pools = [(lib, n) for lib in _blas().lib_controllers if (n := lib.num_threads) != 1]
    for lib, _ in pools:
        lib.set_num_threads(1)
    try:
        yield
    finally:
        for lib, n in pools:
            lib.set_num_threads(n)


# ----------------------------------------------------------------------------- checks
@dataclass(frozen=True)
class _Checked:
    """The user's settings, checked once, and what follows from them.

    ``fit`` and ``trust`` hold the values as given with ``robust`` a ``bool`` and
    ``false_alarm`` a ``float``; ``trim`` is ``fit.cut_unsteady`` decided (``None``: as
    ``robust``; the calibration's ``options["trim"]``);
    ``magnitudes`` the field magnitudes given (``None``: not given), ``fixed`` each sensor's
    pose-level variance given (``None``: estimated), ``user_noise`` each sensor's per-sample
    covariance given (raw units)."""

    spec: Method
    fit: FitSettings
    trust: TrustSettings
    trim: bool
    reference: FieldReference | None
    magnitudes: dict[str, float | None]
    fixed: dict[str, float | None]
    user_noise: dict[str, np.ndarray]
    targets: Targets | None
    options: Mapping[str, object]
    on_progress: Callable[[str], None] | None

    def provenance(self) -> dict[str, object]:
        """How the fit was made, for ``cal.options``."""
        return {
            "body_frame": self.fit.body_frame,
            "robust": self.fit.robust,
            "false_alarm": self.trust.false_alarm,
            "trim": self.trim,
        }


def _reference(location: object, date: object, allowance: object) -> FieldReference | None:
    if location is None:
        if date is not None:
            raise InputError("a date was given without a location; give --location LAT,LON too")
        return None
    if (
        isinstance(allowance, bool)
        or not isinstance(allowance, (int, float, np.floating, np.integer))
        or not 0 <= float(allowance) < 90
    ):
        raise InputError(f"dip_allowance_deg must be degrees from 0 to 90, got {brief(allowance)}")
    return expected_field(location, date)  # type: ignore[arg-type]  # validated there


def _field_strength(value: object, reference: FieldReference | None) -> float | None:
    """A number, or ``"wmm"``/``"wmm:uT"``/``"wmm:nT"``: the model's intensity at the site."""
    if not isinstance(value, str):
        return _magnitude(value, "field_strength")
    unit = wmm_unit(value)
    if unit is None:
        raise InputError(
            f"field_strength {value[:40]!r} is neither a number nor wmm, wmm:uT, wmm:nT, "
            "wmm:gauss or wmm:mgauss"
        )
    if reference is None:
        raise InputError(
            "field strength 'wmm' takes the World Magnetic Model's intensity where the log was "
            "recorded: give --location LAT,LON too"
        )
    return reference.intensity_in(unit)


def field_settings(
    fit: FitSettings, trust: TrustSettings
) -> tuple[FieldReference | None, dict[str, float | None]]:
    """The World Magnetic Model's field where the log was recorded (``trust.location``,
    ``trust.date``; ``None`` without a location) and the field magnitudes given
    (``{"accel": fit.gravity, "mag": fit.field_strength}``, ``"wmm"`` resolved; ``None``: not
    given), each checked as :func:`calibrate_with` checks it, for a path that does not go
    through it (the continuous-motion estimator, :func:`fieldcal.pipeline.run_log`).

    Raises
    ------
    InputError
        A date without a location, an allowance out of range, a magnitude that is not a
        plausible number, or ``"wmm"`` without a location.
    """
    reference = _reference(trust.location, trust.date, trust.dip_allowance_deg)
    magnitudes = {
        "accel": _magnitude(fit.gravity, "gravity"),
        "mag": _field_strength(fit.field_strength, reference),
    }
    return reference, magnitudes


def check_targets(targets: object) -> Targets | None:
    """``targets=`` checked: a :class:`~fieldcal.trust.targets.Targets` or ``None``.

    Raises
    ------
    ValueError
        In one line, naming what was given.
    """
    if targets is not None and not isinstance(targets, Targets):
        raise ValueError(f"targets must be a fieldcal.Targets, got {brief(targets)}")
    return targets


def targets_for(targets: object, trust: TrustSettings) -> Targets | None:
    """The verdict's targets: ``targets`` (``None``: :class:`~fieldcal.trust.targets.Targets`'
    defaults) with the target options set in ``trust`` (``--target-tilt`` ...) in place of its
    values.

    Parameters
    ----------
    targets : Targets or None
        The library's ``targets=``.
    trust : TrustSettings
        ``target_tilt``, ``target_heading``, ``target_norm``: each ``None`` or the value to use.

    Returns
    -------
    Targets or None
        ``None`` when neither gives any (the defaults).

    Raises
    ------
    ValueError
        ``targets`` is not a :class:`~fieldcal.trust.targets.Targets`, or a target is not a
        positive number (one line each).
    """
    targets = check_targets(targets)
    changes = {
        OPTIONS[name].target: value
        for name in TARGET_OPTIONS
        if (value := getattr(trust, name)) is not None
    }
    if not changes:
        return targets
    try:
        return dataclasses.replace(targets or DEFAULT_TARGETS, **changes)
    except InputError as exc:  # the message names the option given, not the attribute
        text = str(exc)
        for name in TARGET_OPTIONS:
            text = text.replace(f"Targets.{OPTIONS[name].target} ", f"{name} ")
        raise InputError(text) from None


def _check_flags(fit: FitSettings, on_progress: object) -> None:
    """Check the switches of :func:`calibrate` and ``on_progress``, in one line each."""
    if fit.body_frame not in ("accel", "mag"):
        raise ValueError(f"body_frame must be 'accel' or 'mag', got {brief(fit.body_frame)}")
    for flag, value in (("mag_mirrored", fit.mag_mirrored), ("robust", fit.robust)):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{flag} must be True or False, got {brief(value)}")
    if on_progress is not None and not callable(on_progress):
        raise ValueError(
            f"on_progress must be a function taking one line of text, got {brief(on_progress)}"
        )


def _given(cut_unsteady: bool | None) -> dict[str, object]:
    """``cut_unsteady`` as a keyword when given (for :func:`fieldcal.settings.renamed`)."""
    return {} if cut_unsteady is None else {"cut_unsteady": cut_unsteady}


def _check_trim(trim: object, robust: bool) -> bool:
    """``trim`` as a bool (default: the same as ``robust``)."""
    if trim is None:
        return robust
    if not isinstance(trim, (bool, np.bool_)):
        raise ValueError(f"cut_unsteady must be True or False, got {brief(trim)}")
    return bool(trim)


def _magnitude(value: object, name: str) -> float | None:
    """A reference field's magnitude: a real number in :data:`fieldcal.limits.RANGE_TEXT` (the
    gains are raw units per unit of it, and their covariance must stay in floating-point
    range)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a positive number, got {brief(value)}")
    if not in_range(float(value)):
        raise ValueError(f"{name} must be a positive number {RANGE_TEXT}, got {brief(value)}")
    return float(value)


def _probability(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number in (0, 1), got {brief(value)}")
    if not 0 < float(value) < 1:
        raise ValueError(f"{name} must be in (0, 1), got {brief(value)}")
    return float(value)


def _user_noise(noise: object) -> dict[str, np.ndarray]:
    """The user's per-sample noise covariance per sensor (raw units), checked."""
    given = per_sensor(noise, "noise") if noise is not None else {}
    return {name: noise_covariance(v, name) for name, v in given.items() if v is not None}


def _check(
    fit: FitSettings,
    trust: TrustSettings,
    targets: object,
    on_progress: Callable[[str], None] | None,
    options: Mapping[str, object],
) -> _Checked:
    """Every setting of a calibration checked once, in one line each, before any work."""
    spec = get_method(fit.method)
    _check_flags(fit, on_progress)
    goal = targets_for(targets, trust)
    robust = bool(fit.robust)
    if robust is not fit.robust:  # np.bool_: as bool (no copy in the common case)
        fit = dataclasses.replace(fit, robust=robust)
    trim = _check_trim(fit.cut_unsteady, fit.robust)
    alpha = _probability(trust.false_alarm, "false_alarm")
    if type(trust.false_alarm) is not float:
        trust = dataclasses.replace(trust, false_alarm=alpha)
    g = _magnitude(fit.gravity, "gravity")
    reference = _reference(trust.location, trust.date, trust.dip_allowance_deg)
    h = _field_strength(fit.field_strength, reference)
    if options:  # none given: none unknown (the check reads the method's signature, ~50 µs)
        spec.check_options(options)
    pose_noise = per_sensor(fit.pose_noise, "pose_noise")
    return _Checked(
        spec=spec,
        fit=fit,
        trust=trust,
        trim=trim,
        reference=reference,
        magnitudes={"accel": g, "mag": h},
        fixed={s: pose_noise_value(v, s) for s, v in pose_noise.items()},
        user_noise=_user_noise(fit.noise),
        targets=goal,
        options=options,
        on_progress=on_progress,
    )


# ----------------------------------------------------------------------------- the call
def calibrate(
    accel: Samples | None,
    mag: Samples | None = None,
    method: str = _FIT.method,
    *,
    gravity: float | None = _FIT.gravity,
    field_strength: float | str | None = _FIT.field_strength,
    noise: NoiseSpec | None = _FIT.noise,
    pose_noise: PoseNoiseSpec = _FIT.pose_noise,
    robust: bool = _FIT.robust,
    false_alarm: float = _TRUST.false_alarm,
    cut_unsteady: bool | None = _FIT.cut_unsteady,
    body_frame: str = _FIT.body_frame,
    mag_mirrored: bool = _FIT.mag_mirrored,
    location: LocationSpec | None = _TRUST.location,
    date: DateSpec | None = _TRUST.date,
    dip_allowance_deg: float = _TRUST.dip_allowance_deg,
    targets: Targets | None = None,
    on_progress: Callable[[str], None] | None = None,
    time_ordered: bool = False,
    temperature: Sequence[ArrayLike] | None = None,
    **options: object,
) -> Calibration:
    """Calibrate an accelerometer and a magnetometer together from static poses.

    Parameters
    ----------
    accel, mag
        Each N arrays (n_i, 3): the raw samples of pose i (same poses for both; ``None``: one
        sensor alone). ``"ellipsoid"`` also takes single (n, 3) arrays of samples.
    method : str
        In :data:`fieldcal.METHODS`: ``"mle"`` (default), ``"greedy"``, ``"ellipsoid"``.
    gravity, field_strength : float, optional
        Magnitudes of the reference fields (default 1); ``field_strength="wmm"`` (``"wmm:nT"``)
        takes the World Magnetic Model's total intensity at ``location`` in µT (nT).
    noise : float, array, or dict, optional
        One raw sample's noise instead of the within-pose scatter (Eq. 7): std, 3x3 covariance.
    pose_noise : "auto", "none", float, or dict
        The pose-level noise ``q`` (raw units, per axis) of each pose mean beyond ``noise /
        sqrt(samples)``: estimated (``"auto"``), zero (``"none"``, the seed paper's) or given.
    robust : bool
        Test every pose, drop disturbed ones (``cal.rejected``) and refit (default True).
    false_alarm : float
        Family-wise false-alarm rate of the pose tests per calibration (default 0.01).
    cut_unsteady : bool, optional
        Cut samples that are not still inside each pose before Eq. 5/7 (default: ``robust``;
        ``trim=``, its old name, is taken until the next release).
    body_frame : {"accel", "mag"}
        Which sensor's gain is made symmetric, fixing the common body frame (Sec. 4.3).
    mag_mirrored : bool
        Whether the magnetometer's axes are mirrored relative to the accelerometer's (a
        left-handed triad, e.g. the LSM9DS1's): a prior static poses cannot test; with a
        ``location`` the model's dip decides (``cal.options["mag_handedness"]`` says which).
    location : str or sequence of float, optional
        ``"LAT,LON[,ALT_M]"`` or ``(lat, lon[, alt_m])``: the World Magnetic Model's field
        there (:func:`fieldcal.expected_field`) becomes ``cal.field_reference``.
    date : str or datetime.date, optional
        When (``"YYYY-MM-DD"``, default today) for the model.
    dip_allowance_deg : float
        The local anomaly allowed before the verdict warns that the dip differs from the
        model's (default 2°).
    targets : Targets, optional
        The accuracy the verdict asks for (:class:`fieldcal.Targets`): beyond a target warns,
        beyond 5 times fails.
    on_progress : callable, optional
        Hears one line at each step of the robust fit.
    time_ordered : bool
        The poses are consecutive pieces of one motion: error bars widened for the correlation
        between neighbours (:mod:`fieldcal.trust.correlation`).
    temperature : sequence of arrays, optional
        Each pose's temperatures (°C): biases in T (``docs/methods/temperature.md``).
    **options
        The method's own options (its ``fit``'s keywords, e.g. ``gamma`` for ``"greedy"``).

    Returns
    -------
    Calibration
        With ``verdict``, ``rejected``, ``accuracy`` and each sensor's ``pose_noise_std``.

    Notes
    -----
    Defaults: :class:`fieldcal.settings.FitSettings`, :class:`~fieldcal.settings.TrustSettings`
    (the option table); :func:`calibrate_with` is the same call with those objects.
    """
    given = dict(locals())  # the keywords by name: the settings' fields are among them
    if "trim" in options:  # the old name, for one release
        given.update(renamed({"trim": options.pop("trim"), **_given(cut_unsteady)}))
    fit, trust = settings_of(FitSettings, given), settings_of(TrustSettings, given)
    return calibrate_with(
        accel,
        mag,
        fit,
        trust,
        targets=targets,
        method_options=options,
        on_progress=on_progress,
        time_ordered=time_ordered,
        temperature=temperature,
    )


def calibrate_with(
    accel: Samples | None,
    mag: Samples | None,
    fit: FitSettings = _FIT,
    trust: TrustSettings = _TRUST,
    *,
    targets: Targets | None = None,
    method_options: Mapping[str, object] | None = None,
    on_progress: Callable[[str], None] | None = None,
    time_ordered: bool = False,
    temperature: Sequence[ArrayLike] | None = None,
) -> Calibration:
    """:func:`calibrate` with its options as settings objects.

    Parameters
    ----------
    accel, mag, targets, on_progress, time_ordered, temperature
        As :func:`calibrate` takes them.
    fit : FitSettings
        ``method``, the reference magnitudes, the noise model, ``robust``, ``trim``,
        ``body_frame``, ``mag_mirrored`` (the log pipeline's ``mag_axes``, ``accel_sign`` and
        ``gyro`` are not read here).
    trust : TrustSettings
        ``location``, ``date``, ``dip_allowance_deg``, ``false_alarm`` and the target options
        (``target_tilt`` ...: they replace the values of ``targets``, :func:`targets_for`).
    method_options : mapping, optional
        The method's own options (checked by its registry entry).

    Returns
    -------
    Calibration
    """
    checked = _check(fit, trust, targets, on_progress, method_options or {})
    try:
        # The problems are small (3x3 blocks, a 22x22 system): threaded BLAS only adds
        # contention, and two processes calibrating at once made a 5 ms fit take 0.7 s.
        # Floating-point trouble is not printed: the result is checked below and refused in
        # one line when anything a correction uses is not finite.
        with _one_thread(), np.errstate(all="ignore"):
            cal, scales = _fit(checked, accel, mag, time_ordered, temperature)
            cal = with_late_checks(_in_user_terms(cal, checked, scales))
    except np.linalg.LinAlgError:  # no numpy message reaches the user: it names no fix
        raise ValueError(
            "the poses cannot determine the calibration (a singular or indefinite system); "
            "record poses with each axis pointing up and down, and check the readings change "
            "from pose to pose"
        ) from None
    try:
        cal.check_values()
    except ValueError as exc:
        raise ValueError(
            f"the {fit.method} fit gave no usable calibration "
            f"({str(exc).removeprefix('invalid ')}); check the readings (units, columns) and "
            "record poses with each axis up and down"
        ) from None
    return cal


# ----------------------------------------------------------------------------- the fit
def _with_user_noise(
    stats: PoseStats, given: Mapping[str, np.ndarray], scales: Mapping[str, float]
) -> tuple[PoseStats, dict[str, str]]:
    """Replace Eq. 7's covariance by the user's where given (in the readings' scaled units);
    report each sensor's source."""
    sources: dict[str, str] = {}
    for name in stats.sensors:
        value = given.get(name)
        if value is not None:
            stats = stats.replace(
                **{name: dataclasses.replace(stats.sensor(name), cov=value / scales[name] ** 2)}
            )
            sources[name] = "user"
        else:
            sources[name] = "scatter" if stats.sensor(name).cov is not None else "residuals"
    return stats, sources


def _scaled_variance(variance: float | None, scale: float) -> float | None:
    return None if variance is None else variance / scale**2


def _continuous(accel: object, mag: object) -> bool:
    return any(isinstance(x, np.ndarray) and x.ndim == 2 for x in (accel, mag) if x is not None)


def _fit_samples(
    checked: _Checked, accel: Samples | None, mag: Samples | None, temperature: object
) -> tuple[Calibration, dict[str, float]]:
    """A method that takes continuous samples (the ellipsoid), on them: no pose statistics,
    no trust path (its verdict comes from its own fit)."""
    spec = checked.spec
    accel, accel_scale = normalise(accel, "accel")
    mag, mag_scale = normalise(mag, "mag")
    if not spec.continuous:
        raise ValueError(
            f"method {spec.name!r} needs per-pose input: pass a list with one (n_i, 3) "
            "array per static pose (or use method='ellipsoid' for continuous samples)"
        )
    if temperature is not None:
        raise ValueError("temperature= needs per-pose input: one array per static pose")
    if checked.user_noise:
        raise ValueError(
            "noise= needs per-pose input; with continuous samples the ellipsoid method "
            "estimates the noise from its fit residuals (pass per-pose arrays instead)"
        )
    cal = spec.load()(
        None, raw_accel=accel, raw_mag=mag, body_frame=checked.fit.body_frame, **checked.options
    )
    return cal, {"accel": accel_scale, "mag": mag_scale}


def _check_count(spec: Method, stats: PoseStats) -> None:
    need = spec.min_poses_for(len(stats.sensors))
    if stats.n_poses < need:
        raise ValueError(
            f"{stats.n_poses} poses given; the {spec.name} method needs at least {need}"
            + (
                " (6N readings must outnumber the 3N rotation angles plus 22 sensor parameters)"
                if len(stats.sensors) == 2
                else " for one sensor (3N readings must outnumber 2N tilt angles plus "
                "9 sensor parameters)"
            )
        )


def _fit(
    checked: _Checked,
    accel: Samples | None,
    mag: Samples | None,
    time_ordered: bool,
    temperature: Sequence[ArrayLike] | None,
) -> tuple[Calibration, dict[str, float]]:
    """The method through the shared trust path, on readings divided by an exact power of two
    per sensor (the fit sees numbers of order one in any unit); returns the result and those
    divisors, by which :meth:`Calibration.with_raw_scale` scales it back."""
    if _continuous(accel, mag):
        return _fit_samples(checked, accel, mag, temperature)
    spec, fit = checked.spec, checked.fit
    # one pass over the samples: checks, the divisors and Eq. 5/7 (the statistics are scaled,
    # not the samples; a method that reads the samples gets scaled copies)
    stats, scales, arrays = summarize_scaled(accel, mag, trim=checked.trim)
    raw: dict[str, list[np.ndarray] | None] = {"accel": None, "mag": None}
    if spec.raw_samples:
        for s, poses in arrays.items():
            raw[s] = poses if poses is None or scales[s] == 1.0 else [p / scales[s] for p in poses]
    _check_count(spec, stats)
    stats, sources = _with_user_noise(stats, checked.user_noise, scales)
    thermal: dict[str, object] = {}
    if temperature is not None:
        method_fit = spec.load()

        def order_zero(base: PoseStats) -> Calibration:
            return method_fit(base, body_frame=fit.body_frame, **checked.options)

        means = pose_temperatures(temperature, stats.n_poses)
        stats, thermal = with_temperature_terms(
            stats, means, fit.body_frame, order_zero if spec.temperature else None
        )
    # the field magnitudes the user gave, for the verdict's gain rules: (factor, given)
    given = {
        s: (scales[s] / m, m) for s, m in checked.magnitudes.items() if m and s in stats.sensors
    }
    cal = fit_trusted(
        spec,
        stats,
        raw_accel=raw["accel"],
        raw_mag=raw["mag"],
        fit=fit,
        trust=checked.trust,
        options=checked.options,
        sources=sources,
        pose_noise={s: _scaled_variance(checked.fixed[s], scales[s]) for s in stats.sensors},
        reference=checked.reference,
        on_progress=checked.on_progress,
        targets=checked.targets,
        magnitudes=given,
        time_ordered=time_ordered,
    )
    if thermal:
        cal = dataclasses.replace(cal, options={**cal.options, **thermal})
    return cal, scales


def _in_user_terms(cal: Calibration, checked: _Checked, scales: dict[str, float]) -> Calibration:
    """The fitted ``cal`` in the user's units, handedness and frame, with how it was made."""
    fit, reference = checked.fit, checked.reference
    # the handedness is decided once (trust.handedness.decide), in the trust path
    if "mag_handedness" not in cal.options:  # the continuous path has none
        hand = decide_handedness(
            cal, bool(fit.mag_mirrored), reference, checked.trust.dip_allowance_deg
        )
        mirrored = cal.with_mag_handedness(hand.mirrored)
        cal = dataclasses.replace(mirrored, options={**mirrored.options, **hand.options})
    provenance = checked.provenance()
    provenance.update({k: cal.options[k] for k in ("mag_mirrored", "mag_handedness")})
    # back to the user's units with the provenance (one new Calibration, not two)
    cal = cal.with_raw_scale(scales, options=provenance)
    if reference is not None and cal.field_reference is None:  # the ellipsoid path
        cal = dataclasses.replace(cal, field_reference=reference)
    g, h = checked.magnitudes["accel"], checked.magnitudes["mag"]
    if g is not None or h is not None:
        cal = cal.with_field_magnitudes(g, h)
    return cal
