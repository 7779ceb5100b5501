"""Calibration from continuous motion: the gyroscope ties the orientations together.

Orchestration only; the pieces live in

- :mod:`.model` — parameters, the field sensors' residuals and analytic Jacobians (Eq. C1–C2);
- :mod:`.preintegration` — the gyroscope's factor between epochs and its Jacobians (C3–C5);
- :mod:`.initial` — the start (ellipsoids, constant-angle alignment, Wahba per epoch);
- :mod:`.solver` — Levenberg–Marquardt on the block-banded normal equations;
- :mod:`.weights` — per-stretch variances (body acceleration), the gyroscope's noise (C6);
- :mod:`.uncertainty` — the covariance with the trajectory marginalised (Schur complement):
  Cramér–Rao (C8) and the sandwich over the scores' long-run covariance (C9), reported;
- :mod:`.observability` — which parameters the motion leaves undetermined, and the turns to add;
- :mod:`.trajectory` — the trajectory's summary, the motion statistics, down-weighted stretches;
- :mod:`.thermal_terms` — the biases' temperature terms: the orders the log identifies.

``docs/methods/continuous.md`` describes the method.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtrc
from threadpoolctl import threadpool_limits

from ...calibration import Calibration, Diagnostics, ParameterCovariance, SensorCalibration
from ...errors import InputError
from ...findings import Findings, MotionFindings, TemperatureSpan
from ...geometry.frames import GRAVITY, HALF_TURN_DOWN, magnetic_reference, twin_flip
from .held_blocks import Held, held_blocks
from .initial import start
from .model import LEVER, Data, State, accel_of, mag_block
from .motion_checks import field_check, gyro_check, gyro_units_ratio, turn_check
from .motion_noise import field_direction_variance, once_per_stretch
from .observability import Identifiability, check_motion, identifiability, motion_advice
from .preintegration import HOLDS, SAMPLINGS, sampling_evidence
from .solver import Prior, Weights, levenberg_marquardt, state_factors
from .thermal_terms import choose_orders, models, temperature_record
from .trajectory import downweighted, summary
from .uncertainty import BATCH, LEVER_NAMES, NAMES, kept_shares, sandwich
from .weights import STRETCH, gyro_rate_variance, stretch_variance

__all__ = ["EPOCH_SECONDS", "MIN_SECONDS", "fit_continuous"]

Array = NDArray[np.float64]

#: Spacing of the rotations kept in the result (``cal.rotations``), seconds.
EPOCH_SECONDS = 0.1
#: Prior standard deviation of each gain entry, relative to the sensor's scale (Eq. C7).
PRIOR_GAIN = 0.25
#: Prior standard deviation of each gyroscope gain entry (rad/s units, Eq. C7): a MEMS
#: gyroscope's scale error is a few percent and its cross-axis terms smaller (datasheets:
#: ±3 %, ±2 %); twice the larger.
PRIOR_GYRO_GAIN = 0.06
#: Prior standard deviation of the gyroscope's bias, rad/s.
PRIOR_GYRO_BIAS = 0.5
#: Prior standard deviation of each component of the lever arm, metres (Eq. C7): a hand-held
#: device turns within about half a metre of the point it turns about (a wrist, an elbow).
PRIOR_LEVER = 0.5
#: The first round's gyroscope noise, as a share of its RMS rate (unless ``gyro_noise`` is
#: given): weak, so that the field sensors lead until the factors' noise is measured.
WEAK_GYRO = 0.02
#: Factor (standard deviation) by which the gyroscope's factors must misfit beyond the raw
#: rates' white noise before the fit's own measure of their noise replaces it (Eq. C6).
GYRO_MISFIT = 20.0
#: Shortest log the method takes, seconds.
MIN_SECONDS = 5.0
#: The groups of parameters whose widening (sandwich ÷ Cramér–Rao) the result records.
_GROUPS = {
    group: [n for n in NAMES if n.startswith(group)] for group in ("accel", "mag", "dip", "gyro")
}


def _array(name: str, value: ArrayLike, n: int | None, width: int) -> Array:
    a = np.asarray(value, dtype=float)
    shape = (n, width) if width > 1 else (n,)
    if a.ndim != len(shape) or (width > 1 and a.shape[1] != 3) or (n is not None and len(a) != n):
        raise InputError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} has NaN or inf values; drop those rows (--drop-nan)")
    return a


def _weights(
    state: State, data: Data, length: int, rate_var: float, kept: Array, allow: bool = False
) -> tuple[Weights, dict[str, Array]]:
    """Inverse variances (Eq. C6): each field sensor's per stretch from its residuals, divided
    by the share of its errors the fit keeps (``kept``, :func:`.uncertainty.kept_shares`);
    the gyroscope's from ``rate_var`` (rad²/s² per axis); with ``allow``, the allowances for
    what the model leaves out (C6a–C6b)."""
    ra = accel_of(state, data).residual
    rm = mag_block(state, data.mag, data.temperature).residual
    va, per_a = stretch_variance(ra / np.sqrt(kept[0]), length, 0.0)
    vm, per_m = stretch_variance(rm / np.sqrt(kept[1]), length, 0.0)
    floor_a = max(1e-4 * float(np.median(per_a)), 1e-300)
    floor_m = max(1e-4 * float(np.median(per_m)), 1e-300)
    va, per_a = np.maximum(va, floor_a), np.maximum(per_a, floor_a)
    vm, per_m = np.maximum(vm, floor_m), np.maximum(per_m, floor_m)
    # what the model leaves out, counted as it is (Eq. C6a–C6b, :mod:`.motion_noise`)
    if allow:
        va = once_per_stretch(va, length)
        vm = vm + field_direction_variance(data.mag, state.mag_bias)
    dt = np.diff(data.time)
    w = Weights(1.0 / va, 1.0 / vm, 1.0 / (rate_var * dt**2))
    return w, {"accel": per_a, "mag": per_m, "gyro": np.array([rate_var])}


def _plain_weights(
    state: State, data: Data, w: Weights, length: int, levels: dict[str, Array]
) -> Weights:
    """:func:`_weights` without the allowances (C6a–C6b), ``w``'s prior kept: the temperature
    terms are chosen on the noise's own weights, as C6a would count a drift not yet modelled
    as body acceleration and hide it."""
    rate_var = float(levels["gyro"][0])
    plain, _ = _weights(state, data, length, rate_var, kept_shares(state, data, w), False)
    plain.prior = w.prior
    return plain


def _gyro_variance(state: State, data: Data, w: Weights, rate_var: float, kept: float) -> float:
    """The gyroscope's rate variance for the next round (Eq. C6): the raw rates' white noise
    (:func:`.weights.gyro_rate_variance`), unless its factors misfit by more than
    :data:`GYRO_MISFIT` times that in standard deviation — their weighted mean square over the
    share the fit keeps (:func:`.uncertainty.kept_shares`), times the variance they were
    weighed with, is then the variance. A log without time stamps, sampled by a loop that
    sleeps (the ICM-20948 sessions: 62 times), turns by more or less than its rate times the
    nominal interval, and only the fit sees it. Below the threshold the white noise stands: the
    moment estimate also takes in the field sensors' correlated errors, which the trajectory
    passes on to the gyroscope's residuals (BROAD: 6 times), and trusting the gyroscope less
    for them made the trajectory and the gains worse against the motion capture."""
    f = state_factors(state, data)
    # per interval, the rate error the factor implies (rad/s)²
    mean_square = float(np.mean(np.sum(f.residual**2, axis=1) / f.dt**2) / 3.0)
    white = gyro_rate_variance(data.gyro, state.gyro_gain)
    misfit = mean_square / kept
    return misfit if misfit > GYRO_MISFIT**2 * white else white


def _prior(state: State) -> Prior:
    """Weak priors (Eq. C7): each field sensor's gain within :data:`PRIOR_GAIN` of the start's
    (relative to its scale) and its bias within one scale of it; the gyroscope's gain within
    :data:`PRIOR_GYRO_GAIN` of the identity (rad/s units) and its bias within
    :data:`PRIOR_GYRO_BIAS` rad/s of zero. They only matter where the motion leaves a parameter
    undetermined (the identifiability check then says so); elsewhere the data outweigh them by
    orders."""
    sa = float(np.linalg.norm(state.accel_gain) / np.sqrt(3.0))
    sm = float(np.linalg.norm(state.mag_gain) / np.sqrt(3.0))
    std = np.concatenate(
        [
            np.full(6, PRIOR_GAIN * sa),
            np.full(3, sa),
            np.full(9, PRIOR_GAIN * sm),
            np.full(3, sm),
            [np.pi],
            np.full(9, PRIOR_GYRO_GAIN),
            np.full(3, PRIOR_GYRO_BIAS),
            np.full(3, PRIOR_LEVER),
        ]
    )
    mean = state.vector()[: LEVER.stop]
    mean[22:31] = np.eye(3).ravel()
    mean[31:34] = 0.0
    mean[LEVER] = 0.0
    return Prior(mean, 1.0 / std**2)


def _canonical(state: State) -> State:
    """fieldcal's gauge: the field points north (``cos δ > 0``) and the magnetometer's triad
    has the accelerometer's handedness. Readings cannot tell the handedness twin apart (a
    negated magnetometer gain, the dip's sign changed and every ``R_j → R_j D``, ``D`` a half
    turn about down, :func:`fieldcal.geometry.frames.twin_flip`) and neither can the
    gyroscope (``R_{j+1} D (R_j D)ᵀ = R_{j+1} R_jᵀ``): as for poses, an unmirrored
    magnetometer is taken."""
    if np.linalg.det(state.mag_gain) < 0:
        state = state.copy()
        state.mag_gain = -state.mag_gain
        state.dip = -state.dip
        state.rotations = state.rotations @ twin_flip("mag")
    if np.cos(state.dip) < 0:
        state = state.copy()
        state.dip = float(np.pi - state.dip)
        state.rotations = state.rotations @ HALF_TURN_DOWN
    state.dip = float(np.arctan2(np.sin(state.dip), np.cos(state.dip)))
    return state


def _findings(
    check: Identifiability,
    disturbed: list[dict[str, Any]],
    trajectory: dict[str, Any],
    lacking: str | None,
    thermal: dict[str, Any] | None,
    measured: dict[str, Any],
) -> Findings:
    """What the verdict's rules judge (:mod:`fieldcal.findings`): what the motion leaves
    undetermined (with the turns to add), what it lacks or what the fit left unsettled, the
    seconds down-weighted for body acceleration, a temperature span too small for terms. The
    estimator builds no reason: ``continuous_*``, the gyroscope's rules and
    ``temperature_span`` in :mod:`fieldcal.trust.verdict` read these; ``measured`` is
    :func:`_measured`'s (:mod:`.motion_checks`: the field, the gyroscope's units, the turns)."""
    field, turns = measured["field_check"], measured["turn_check"]
    motion = MotionFindings(
        undetermined=tuple(check.advice),
        lacking=lacking or "",
        unsettled=tuple(check.unsettled),
        disturbed_seconds=float(sum(d["seconds"] for d in disturbed)),
        duration_seconds=float(trajectory["duration_s"]),
        field_strength_rms=float(field["strength_rms"]),
        dip_spread_deg=float(field["dip_spread_deg"]),
        gyro_units_ratio=measured["gyro_units_ratio"],
        turn_step_rad=float(turns["step_rad_p99"]),
        max_rate=float(turns["max_rate"]),
        clipped_axes=tuple(int(i) for i in turns["clipped_axes"]),
    )
    span = None
    if thermal is not None and "refused" in thermal:
        low, high = (float(x) for x in thermal["span_c"])
        span = TemperatureSpan(low, high, float(thermal["reference_c"]))
    return Findings(motion=motion, temperature_span=span)


def fit_continuous(
    time: ArrayLike,
    accel: ArrayLike,
    mag: ArrayLike,
    gyro: ArrayLike,
    *,
    rows: ArrayLike | None = None,
    max_iter: int = 50,
    rounds: int = 2,
    tol: float = 1e-3,
    gravity: float | None = None,
    hold: str | Sequence[str] | None = None,
    gyro_noise: float | None = None,
    on_progress: Callable[[str], None] | None = None,
    temperature: ArrayLike | None = None,
    gyro_sampling: str = "auto",
    prior: object = None,
    allowances: bool = False,
) -> Calibration:
    """Calibrate accelerometer, magnetometer and gyroscope from a log in continuous motion.

    Maximum likelihood over the three sensors' gains and biases, the dip, the noise levels
    and the orientation at every sample, the calibrated gyroscope driving the orientation
    between samples (``docs/methods/continuous.md``, Eq. C1–C6).

    Parameters
    ----------
    time : (n,) array_like
        Seconds, strictly increasing.
    accel, mag : (n, 3) array_like
        Raw readings (the accelerometer's specific force; any units).
    gyro : (n, 3) array_like
        Raw rates in rad/s (nominally; the gain absorbs a scale error).
    rows : (n,) array_like of int, optional
        Each sample's row in the log (for the down-weighted stretches); default ``0..n−1``.
    max_iter : int
        Levenberg–Marquardt iterations per round.
    rounds : int
        Rounds of noise estimation and refitting (at least 1).
    tol : float
        Decrease of the cost (half a χ²) below which a round stops.
    gravity : float, optional
        ``|g|`` in the accelerometer's units, for the body acceleration in those units.
    hold : str or sequence of str, optional
        Blocks held fixed at ``prior``'s values (:mod:`.held_blocks`): any of ``gyro.gain``,
        ``gyro.bias``, ``accel.bias``, ``mag.bias`` (``"gyro.gain,gyro.bias"``). The former
        spellings ``"midpoint"``/``"previous"`` still name the sampling convention (as
        ``gyro_sampling="instant"``/``"mean"``).
    gyro_noise : float, optional
        The gyroscope's white noise per sample (rad/s, one axis), when known; by default
        measured from the raw rates' second differences (which real rate jitter at the sample
        rate inflates: give it then, e.g. from a datasheet or a still log).
    gyro_sampling : {"auto", "instant", "mean"}
        Whether a gyroscope reading is the rate at its instant (the interval between samples
        takes the mean of its two ends) or the mean rate over the interval that follows it.
        ``"auto"``: detected from how the magnetometer's direction turns
        (:func:`.preintegration.sampling_evidence`), ``"instant"`` when the data cannot tell;
        ``options["gyro_sampling"]`` records the choice and how it was made.
    prior : Calibration or path, optional
        The earlier calibration (a ``cal.json``) the ``hold`` blocks are held at.
    on_progress : callable, optional
        Hears one line per round.
    allowances : bool
        Weigh for what the model leaves out (Eq. C6a–C6b, :mod:`.motion_noise`): a moving
        stretch's body acceleration counted once, the field's direction uniform only to 3°.
        Experimental: on BROAD every third sample the measured/predicted tilt came to 1.3,
        0.55 and 1.6 (01, 04, 06; 4.3–4.9 without); at the full 285.7 Hz trial 01 needs
        ``max_iter=150`` (216 iterations, 9 times the default's CPU).
    temperature : (n,) array_like, optional
        The die temperature at each sample (°C). Each sensor's bias then gets the terms in
        ``T − T_ref`` (``T_ref`` the mean) that the log identifies
        (:mod:`.thermal_terms`); ``cal.<sensor>.temperature`` holds them (order 0: none kept;
        ``refused`` with too small a span, verdict code ``temperature_span``) and
        ``options["temperature"]`` the tests. Without it, nothing changes.

    Returns
    -------
    Calibration
        ``method == "continuous"``; ``gyro`` filled; ``covariance`` the sandwich covariance with
        the trajectory marginalised (:func:`.uncertainty.sandwich`: the Cramér–Rao bound
        widened per parameter for time-correlated residuals; gyroscope included, correlations
        kept); ``rotations`` every :data:`EPOCH_SECONDS` (``options["epoch_step"]`` samples);
        ``options`` records ``mode``,
        ``trajectory``, ``motion``, ``downweighted``, ``noise``, ``error_bars`` (the batch's
        seconds, the widening per sensor) and ``identifiability``;
        ``findings`` (:class:`fieldcal.findings.MotionFindings`: undetermined, unsettled,
        disturbed; no verdict: :func:`fieldcal.trust.continuous_motion.trust_continuous` judges
        it by the registered rules).

    Raises
    ------
    InputError
        Too short a log, time not increasing, or readings that do not outline an ellipsoid.
    """
    # the linear algebra is many small products: threads only add contention
    with threadpool_limits(limits=1), np.errstate(all="ignore"):
        return _fit(
            time,
            accel,
            mag,
            gyro,
            rows,
            max_iter,
            rounds,
            tol,
            gravity,
            hold,
            gyro_noise,
            on_progress,
            temperature,
            gyro_sampling,
            prior,
            allowances,
        )


def _check_options(
    max_iter: int, rounds: int, tol: float, sampling: str, gyro_noise: float | None
) -> None:
    """One-line errors for the fit's options."""
    if sampling not in ("auto", *SAMPLINGS):
        raise InputError(f"gyro_sampling must be auto, instant or mean; got {sampling!r}"[:200])
    for name, value in (("max_iter", max_iter), ("rounds", rounds)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InputError(f"{name} must be a whole number of at least 1, got {value!r}"[:200])
    if isinstance(tol, bool) or not (
        isinstance(tol, (int, float)) and np.isfinite(tol) and tol > 0
    ):
        raise InputError(f"tol must be a positive finite number, got {tol!r}"[:200])
    if gyro_noise is not None and not (np.isfinite(gyro_noise) and gyro_noise > 0):
        raise InputError(f"gyro_noise must be a positive number of rad/s, got {gyro_noise!r}")


def _inputs(time: ArrayLike, accel: ArrayLike, mag: ArrayLike, gyro: ArrayLike) -> Data:
    """The readings checked (shapes, finite values, time strictly increasing, long enough)."""
    t = _array("time", time, None, 1)
    n = len(t)
    a = _array("accel", accel, n, 3)
    m = _array("mag", mag, n, 3)
    g = _array("gyro", gyro, n, 3)
    if n < 3:  # not a question of order: there is no motion in so few rows
        raise InputError(
            f"the log has {n} data row(s); continuous calibration needs at least "
            f"{MIN_SECONDS:g} s of turning through every orientation (or a log of still poses)"
        )
    if np.any(np.diff(t) <= 0):
        raise InputError(
            "the time column must increase strictly from row to row (sort the log, spread "
            "bursts or give --rate)"
        )
    if t[-1] - t[0] < MIN_SECONDS:
        raise InputError(
            f"the log lasts {t[-1] - t[0]:.3g} s; continuous calibration needs at least "
            f"{MIN_SECONDS:g} s of turning through every orientation"
        )
    return Data(t, a, m, g)


def _sampling(state: State, data: Data, given: str) -> dict[str, Any]:
    """The gyroscope's sampling convention: as given, or detected
    (:func:`.preintegration.sampling_evidence` on the start's calibrated magnetometer): the
    share ``λ`` is about 1 for instant readings and 0 for interval means; a convention is taken
    when ``λ`` is consistent with its value (within 3 standard errors plus 0.25) and not with the
    other's. Otherwise ``"instant"``: the data cannot tell (slow changes of rate), or the timing
    fits neither (a magnetometer that lags or leads the gyroscope), which the note says."""
    if given != "auto":
        return {"used": given, "how": "given"}
    field = np.asarray(np.linalg.solve(state.mag_gain, (data.mag - state.mag_bias).T).T, np.float64)
    field /= np.maximum(np.linalg.norm(field, axis=1), 1e-300)[:, None]
    lam, std = sampling_evidence(data.time, data.gyro, field)
    near = {c: bool(np.isfinite(lam) and abs(lam - c) < 3.0 * std + 0.25) for c in (0.0, 1.0)}
    if near[0.0] != near[1.0]:
        used, how = ("mean" if near[0.0] else "instant"), "detected"
    elif near[0.0]:
        used, how = "instant", "default (the data cannot tell)"
    else:
        used, how = "instant", "default (the timing fits neither: the sensors' clocks may differ)"
    return {"used": used, "how": how, "share": float(lam), "share_std": float(std)}


def _gyro_source(gyro_noise: float | None, rate_var: float, white: float) -> str:
    """Where the gyroscope's noise level came from (Eq. C6, :func:`_gyro_variance`)."""
    if gyro_noise is not None:
        return "given (gyro_noise)"
    if abs(rate_var - white) <= 1e-9 * white:
        return "raw rates' second differences"
    return "the factors' misfit (beyond the raw rates' white noise)"


def _measured(
    state: State, data: Data, cov: ParameterCovariance, rates: Array, length: int
) -> dict[str, Any]:
    """The options the verdict's continuous rules read (:mod:`.motion_checks`) and the lever
    arm with its standard error."""
    t, g = data.time, data.gyro
    return {
        "lever_arm": {
            "metres": [float(x) for x in state.lever],
            "std_m": [float(x) for x in cov.stds(list(LEVER_NAMES))],
        },
        "gyro_check": gyro_check(state.gyro_gain, cov),
        "gyro_units_ratio": gyro_units_ratio(t, data.mag, g),
        "field_check": field_check(state, data, length),
        "turn_check": turn_check(t, rates, g),
    }


def _starting(data: Data, given: str, held: Held | None) -> tuple[State, dict[str, Any], Prior]:
    """The start (:func:`.initial.start`), the sampling convention (:func:`_sampling`, set on
    ``data``), the held blocks put in place and the prior that holds them."""
    first = start(data)
    sampling = _sampling(first, data, given)
    data.hold = SAMPLINGS[sampling["used"]]
    if held is not None:
        first = held.apply(first)
    return first, sampling, _held_prior(first, held)


def _held_prior(state: State, held: Held | None) -> Prior:
    """:func:`_prior` of ``state``, its held blocks fixed at their values."""
    prior = _prior(state)
    if held is not None:
        prior.mean[held.mask] = state.vector()[: len(held.mask)][held.mask]
        prior.fixed = held.mask
    return prior


def _rounds(
    state: State,
    data: Data,
    length: int,
    gyro_noise: float | None,
    rounds: int,
    max_iter: int,
    tol: float,
    on_progress: Callable[[str], None] | None,
    prior: Prior | None = None,
    allow: bool = False,
) -> tuple[State, Weights, dict[str, Array], int, bool]:
    """Levenberg–Marquardt from ``state``, the noise levels re-estimated after each round
    (Eq. C6): the state, the last weights and levels, the iterations and convergence.
    ``prior``: by default :func:`_prior` of ``state``."""
    prior = _prior(state) if prior is None else prior
    if gyro_noise is None:
        # the first round trusts the gyroscope little (WEAK_GYRO of its rates): a log whose
        # factors are noisier than the raw rates' white noise says must not drag the
        # trajectory away from the field sensors before its noise is measured
        white = gyro_rate_variance(data.gyro, state.gyro_gain)
        rate_var = max(white, float(np.mean(data.gyro**2)) * WEAK_GYRO**2)
    else:
        rate_var = float(gyro_noise) ** 2
    w, levels = _weights(state, data, length, rate_var, np.ones(3), allow)
    w.prior = prior
    total = 0
    converged = False
    for r in range(max(1, rounds)):
        state, iterations, converged = levenberg_marquardt(
            state, data, w, max_iter=max_iter, tol=tol
        )
        total += iterations
        kept = kept_shares(state, data, w)
        if gyro_noise is None:
            rate_var = _gyro_variance(state, data, w, rate_var, float(kept[2]))
        if on_progress is not None:
            on_progress(
                f"continuous fit: round {r + 1}, {iterations} iterations, gyroscope noise "
                f"{np.sqrt(rate_var):.3g} rad/s"
            )
        w, levels = _weights(state, data, length, rate_var, kept, allow)
        w.prior = prior
    return state, w, levels, total, converged


def _fit(
    time: ArrayLike,
    accel: ArrayLike,
    mag: ArrayLike,
    gyro: ArrayLike,
    rows: ArrayLike | None,
    max_iter: int,
    rounds: int,
    tol: float,
    gravity: float | None,
    hold: str | Sequence[str] | None,
    gyro_noise: float | None,
    on_progress: Callable[[str], None] | None,
    temperature: ArrayLike | None = None,
    gyro_sampling: str = "auto",
    prior_cal: object = None,
    allowances: bool = False,
) -> Calibration:
    """:func:`fit_continuous` without the thread limit."""
    if isinstance(hold, str) and hold in HOLDS:  # the former spelling of the convention
        gyro_sampling = next(k for k, v in SAMPLINGS.items() if v == hold)
        hold = None
    _check_options(max_iter, rounds, tol, gyro_sampling, gyro_noise)
    held = held_blocks(hold, prior_cal)
    data = _inputs(time, accel, mag, gyro)
    thermal: dict[str, Any] | None = None
    if temperature is not None:
        data.temperature, thermal = temperature_record(
            _array("temperature", temperature, len(data.time), 1)
        )
    t, a, g = data.time, data.accel, data.gyro
    n, dt = len(t), np.diff(t)
    index = np.arange(n) if rows is None else np.asarray(rows, dtype=int)
    rate = 1.0 / float(np.median(dt))
    length = max(1, round(STRETCH * rate))
    check_motion(a, g, t)
    batch = max(2, round(BATCH * rate))
    first, sampling, base_prior = _starting(data, gyro_sampling, held)
    again = partial(_rounds, data=data, length=length, gyro_noise=gyro_noise, rounds=int(rounds))
    again = partial(again, allow=bool(allowances))
    again = partial(again, max_iter=int(max_iter), tol=float(tol), on_progress=on_progress)
    state, w, levels, total, converged = again(first, prior=base_prior)
    if thermal is not None and thermal["allowed_order"] > 0:
        allowed = thermal["allowed_order"]
        plain = _plain_weights(state, data, w, length, levels) if allowances else w
        state, thermal["tests"] = choose_orders(state, data, plain, allowed, batch, max_iter, tol)
        thermal["orders"] = {s: len(c) for s, c in state.temps.items()}
        if state.temps:  # the noise levels again, with the terms
            state, w, levels, more, converged = again(state, prior=base_prior)
            total += more
    state = _canonical(state)
    ra = accel_of(state, data).residual
    rm = mag_block(state, data.mag, data.temperature).residual
    f = state_factors(state, data)
    cov, crb, _ = sandwich(state, data, w, batch)
    widening = {
        group: float(np.sqrt(np.mean((cov.stds(names) / np.maximum(crb.stds(names), 1e-300)) ** 2)))
        for group, names in _GROUPS.items()
    }
    gains = {"accel": state.accel_gain, "mag": state.mag_gain, "gyro": state.gyro_gain}
    # the residual in units of |g|
    body = np.asarray(np.linalg.solve(state.accel_gain, ra.T).T, dtype=np.float64)
    trajectory, motion = summary(t, state.rotations, f.rates, body, gravity)
    # what the motion determines is the Fisher information's to say (the Cramér–Rao bound);
    # the widening for correlated residuals is a property of the disturbances, not the motion
    check = identifiability(
        crb, gains, trajectory["turned_deg"], float(trajectory["gravity_coverage"])
    )
    disturbed = downweighted(levels["accel"], length, t, body, index)
    cost = 0.5 * float(
        np.sum(w.accel * np.sum(ra**2, 1))
        + np.sum(w.mag * np.sum(rm**2, 1))
        + np.sum(w.gyro * np.sum(f.residual**2, 1))
    )
    dof = 3 * n + 3 * n + 3 * (n - 1) - 3 * n - len(state.vector())
    rate_var = float(levels["gyro"][0])
    gyro_source = _gyro_source(gyro_noise, rate_var, gyro_rate_variance(g, state.gyro_gain))
    step = max(1, round(EPOCH_SECONDS * rate))
    lacking = None
    if not converged or check.unsettled:  # blame the motion only if it lacks something
        # on the readings as logged: a fit that did not settle has no trajectory to trust
        raw_turned = np.degrees(np.sum(np.abs(0.5 * (g[1:] + g[:-1])) * dt[:, None], axis=0))
        lacking = motion_advice(a, raw_turned)
    measured = _measured(state, data, cov, f.rates, length)
    findings = _findings(check, disturbed, trajectory, lacking, thermal, measured)
    options: dict[str, Any] = {
        "mode": "continuous",
        "allowances": bool(allowances),  # Eq. C6a–C6b
        "trajectory": trajectory,
        "motion": motion,
        "downweighted": disturbed,
        "noise": {
            "accel_quiet_std": float(np.sqrt(np.quantile(levels["accel"], 0.1))),
            "mag_std": float(np.sqrt(np.median(levels["mag"]))),
            "gyro_rate_std": float(np.sqrt(rate_var)),
        },
        "error_bars": {"batch_seconds": float(batch / rate), "widening": widening},
        "identifiability": {
            "relative_std": check.relative_std,
            "advice": check.advice,
            "unsettled": check.unsettled,
        },
        **measured,
        "epoch_seconds": float(step / rate),
        "epoch_step": int(step),
        "hold": data.hold,
        "gyro_sampling": sampling,
        "held": [] if held is None else list(held.names),
        "max_iter": int(max_iter),
        "rounds": int(rounds),
    }
    if thermal is not None:
        options["temperature"] = thermal
    temps = {} if thermal is None else models(state, thermal)
    Kg = state.gyro_gain
    return Calibration(
        accel=SensorCalibration(
            gain=state.accel_gain,
            bias=state.accel_bias,
            noise_cov=np.quantile(levels["accel"], 0.1) * np.eye(3),
            noise_source="continuous residuals (quietest tenth)",
            temperature=temps.get("accel"),
        ),
        mag=SensorCalibration(
            gain=state.mag_gain,
            bias=state.mag_bias,
            noise_cov=float(np.median(levels["mag"])) * np.eye(3),
            noise_source="continuous residuals",
            temperature=temps.get("mag"),
        ),
        gravity=GRAVITY,
        magnetic=magnetic_reference(state.dip),
        rotations=state.rotations[::step],
        method="continuous",
        iterations=total,
        converged=converged,
        message=f"{total} Levenberg-Marquardt iterations over {rounds} noise rounds",
        options=options,
        covariance=cov,
        diagnostics=Diagnostics(2.0 * cost, dof, float(chdtrc(dof, 2.0 * cost)), np.zeros(0)),
        findings=findings,
        gyro=SensorCalibration(
            gain=Kg,
            bias=state.gyro_bias,
            noise_cov=rate_var * Kg @ Kg.T,
            noise_source=gyro_source,
            temperature=temps.get("gyro"),
        ),
    )
