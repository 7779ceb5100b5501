"""Calibration from continuous motion: the gyroscope ties the orientations together.

Orchestration only; the pieces live in

- :mod:`.model` — parameters, the field sensors' residuals and analytic Jacobians (Eq. C1–C2);
- :mod:`.preintegration` — the gyroscope's factor between epochs and its Jacobians (C3–C5);
- :mod:`.knots` — the trajectory at knots: windows of samples reduced, the gyroscope
  pre-integrated between knots (C1′–C3′);
- :mod:`.initial` — the start (ellipsoids, constant-angle alignment, Wahba per epoch);
- :mod:`.solver` — Levenberg–Marquardt on the block-banded normal equations;
- :mod:`.rounds` — the rounds of fits and noise levels, the progress lines;
- :mod:`.weights` — per-stretch variances (body acceleration), the gyroscope's noise (C6);
- :mod:`.uncertainty` — the covariance with the trajectory marginalised (Schur complement):
  Cramér–Rao (C8) and the sandwich over the scores' long-run covariance (C9), reported;
- :mod:`.observability` — which parameters the motion leaves undetermined, and the turns to add;
- :mod:`.trajectory` — the trajectory's summary, the motion statistics, down-weighted stretches;
- :mod:`.thermal_terms` — the biases' temperature terms: the orders the log identifies;
- :mod:`.covariates` — the magnetometer's interference term in current or throttle (Eq. C2i);
- :mod:`.autopilot_aid` — a flight log's accelerometer and gyroscope gain held at the
  autopilot's calibration, its attitude estimate as the start.

``docs/methods/continuous.md`` describes the method.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtrc
from threadpoolctl import threadpool_limits

from ...calibration import Calibration, Diagnostics, ParameterCovariance, SensorCalibration
from ...errors import InputError
from ...findings import Findings, MotionFindings, TemperatureSpan
from ...geometry.frames import GRAVITY, HALF_TURN_DOWN, magnetic_reference, twin_flip
from ...interference import InterferenceModel
from .autopilot_aid import attitude_start
from .covariates import Inputs, interference_inputs, interference_model
from .held_blocks import Held, held_blocks
from .initial import start
from .knots import knot_step, sample_rates, sample_rotations
from .model import LEVER, Data, State, residuals
from .motion_checks import field_check, gyro_check, gyro_units_ratio, turn_check
from .observability import Identifiability, check_motion, identifiability, motion_advice
from .preintegration import HOLDS, SAMPLINGS, sampling_evidence
from .rounds import Options, Plan, Progress, plain_weights, run_rounds
from .solver import Prior, Weights, state_factors
from .thermal_terms import choose_orders, models, temperature_record
from .trajectory import downweighted, summary
from .uncertainty import LEVER_NAMES, NAMES, sandwich
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
#: Shortest log the method takes, seconds.
MIN_SECONDS = 5.0
#: The groups of parameters whose widening (sandwich ÷ Cramér–Rao) the result records.
_GROUPS = {
    group: [n for n in NAMES if n.startswith(group)] for group in ("accel", "mag", "dip", "gyro")
}


def _array(name: str, value: ArrayLike, n: int | None, width: int) -> Array:
    a = np.asarray(value, dtype=float)
    shape = (n, width) if width > 1 else (n,)
    if (
        a.ndim != len(shape)
        or (width > 1 and a.shape[1] != width)
        or (n is not None and len(a) != n)
    ):
        raise InputError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} has NaN or inf values; drop those rows (--drop-nan)")
    return a


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
    inputs: Mapping[str, ArrayLike] | None = None,
    attitude: ArrayLike | None = None,
    allowances: bool = False,
) -> Calibration:
    """Calibrate accelerometer, magnetometer and gyroscope from a log in continuous motion.

    Maximum likelihood over the three sensors' gains and biases, the dip, the noise levels
    and the orientation at knots a few hundredths of a second apart, the calibrated gyroscope
    pre-integrated between them (:mod:`.knots`; ``docs/methods/continuous.md``, Eq. C1–C6).

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
    max_iter, rounds : int
        Levenberg–Marquardt iterations per round; rounds of noise estimation and refitting.
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
        measured from the raw rates' fourth differences in the log's quietest stretches (white
        jitter of the true rate at every sample is indistinguishable: give it then, e.g. from a
        datasheet or a still log).
    gyro_sampling : {"auto", "instant", "mean"}
        A gyroscope reading is the rate at its instant, or the mean rate over the interval
        that follows it; ``"auto"``: detected (:func:`.preintegration.sampling_evidence`),
        ``"instant"`` when the data cannot tell (``options["gyro_sampling"]`` says which).
    prior : Calibration or path, optional
        The earlier calibration (a ``cal.json``) the ``hold`` blocks are held at; or the
        blocks held themselves (:func:`.autopilot_aid.autopilot_held`: a flight log's
        accelerometer and gyroscope gain at the autopilot's calibration).
    inputs : mapping, optional
        ``{"current": (n,)}`` (A) or ``{"throttle": (n,)}`` (0–1): the magnetometer's
        interference term ``C (u − ū)`` fitted jointly (:mod:`.covariates`, Eq. C2i), in
        ``cal.mag.interference`` (zeros and the reason when it is not identifiable).
    attitude : (n, 4) array_like, optional
        The autopilot's attitude (body → NED quaternions, w first): the start's trajectory.
    on_progress : callable, optional
        Hears the round and iteration as fractions and the time left (:mod:`.rounds`).
    allowances : bool
        Weigh for what the model leaves out (Eq. C6a–C6b, :mod:`.motion_noise`).
    temperature : (n,) array_like, optional
        The die temperature at each sample (°C): each sensor's bias gets the terms in
        ``T − T_ref`` the log identifies (:mod:`.thermal_terms`, ``cal.<sensor>.temperature``).

    Returns
    -------
    Calibration
        ``method == "continuous"``; ``gyro`` filled; ``covariance`` the sandwich covariance with
        the trajectory marginalised (:func:`.uncertainty.sandwich`: the Cramér–Rao bound
        widened per parameter for time-correlated residuals; gyroscope included, correlations
        kept); ``rotations`` every :data:`EPOCH_SECONDS` (``options["epoch_step"]`` samples);
        ``options`` records ``mode``, ``knots`` (count, step in samples, seconds, the rule),
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
    given = (gyro_noise, gyro_sampling, prior, inputs, attitude, allowances)
    options = Options(max_iter, rounds, tol, gravity, hold, *given)
    with threadpool_limits(limits=1), np.errstate(all="ignore"):
        return _fit((time, accel, mag, gyro), temperature, rows, options, on_progress)


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
    """Where the gyroscope's noise level came from (Eq. C6, :func:`.rounds.gyro_variance`):
    the misfit replaces the white noise only beyond :data:`.rounds.GYRO_MISFIT`² times it, so
    anything within twice ``white`` (the settling fit moves the gain a little after the
    level was taken) is the white noise."""
    if gyro_noise is not None:
        return "given (gyro_noise)"
    if rate_var <= 2.0 * white:
        return "raw rates' quiet fourth differences"
    return "the factors' misfit (beyond the raw rates' white noise)"


def _measured(
    state: State, data: Data, cov: ParameterCovariance, rates: Array, length: int, held: Held | None
) -> dict[str, Any]:
    """The options the verdict's continuous rules read (:mod:`.motion_checks`) and the lever
    arm with its standard error (a gyroscope's gain held in rad/s: its unit not in question)."""
    t, g = data.time, data.gyro
    units = None if held is not None and held.mask[22] else gyro_units_ratio(t, data.mag, g)
    return {
        "lever_arm": {
            "metres": [float(x) for x in state.lever],
            "std_m": [float(x) for x in cov.stds(list(LEVER_NAMES))],
        },
        "gyro_check": gyro_check(state.gyro_gain, cov),
        "gyro_units_ratio": units,
        "field_check": field_check(state, data, length),
        "turn_check": turn_check(t, rates, g),
    }


def _starting(
    data: Data,
    given: str,
    held: Held | None,
    drive: Inputs | None = None,
    attitude: ArrayLike | None = None,
) -> tuple[State, dict[str, Any], Prior]:
    """The motion checked (:func:`.observability.check_motion`, unless the accelerometer is
    held: it needs no tilts), the start (:func:`.initial.start`; the autopilot's ``attitude``
    when given, :func:`.autopilot_aid.attitude_start`), the sampling convention
    (:func:`_sampling`, set on ``data``), the interference term's inputs, the held blocks put in
    place and the prior that holds them."""
    if held is None or not held.mask[0]:
        check_motion(data.accel, data.gyro, data.time)
    first = start(data)
    sampling = _sampling(first, data, given)
    data.hold = SAMPLINGS[sampling["used"]]
    if held is not None:
        first = held.apply(first)
    first = _with_inputs(first, data, drive)
    if attitude is not None:
        first = attitude_start(first, data, _array("attitude", attitude, len(data.time), 4))
    return first, sampling, _held_prior(first, held)


def _interference(
    state: State,
    drive: Inputs | None,
    rotations: Array,
    covariances: tuple[ParameterCovariance, ParameterCovariance],
) -> InterferenceModel | None:
    """The fitted term (:func:`.covariates.interference_model`; ``rotations`` at every
    sample, as the inputs), ``None`` without inputs."""
    if drive is None:
        return None
    gain, dip = state.mag_gain, state.dip
    return interference_model(state.interference, drive, rotations, gain, dip, covariances)


def _with_inputs(state: State, data: Data, drive: Inputs | None) -> State:
    """``state`` with zero interference coefficients and ``data`` with the centred inputs,
    when ``drive`` varies enough to fit the term (:mod:`.covariates`)."""
    if drive is None or drive.missing:
        return state
    data.inputs = drive.centred
    out = state.copy()
    out.interference = np.zeros((len(drive.names), 3))
    return out


def _held_prior(state: State, held: Held | None) -> Prior:
    """:func:`_prior` of ``state``, its held blocks fixed at their values."""
    prior = _prior(state)
    if held is not None:
        prior.mean[held.mask] = state.vector()[: len(held.mask)][held.mask]
        prior.fixed = held.mask
    return prior


@dataclass
class _Solution:
    """The optimum (rotations at the knots), its knots and weights, the noise levels at the
    knots, the iterations, convergence, and the choices made on the way."""

    state: State
    knots: Data
    w: Weights
    levels: dict[str, Array]
    iterations: int
    converged: bool
    sampling: dict[str, Any]
    thermal: dict[str, Any] | None


def _prepare(
    readings: tuple[ArrayLike, ArrayLike, ArrayLike, ArrayLike],
    temperature: ArrayLike | None,
    options: Options,
    on_progress: Callable[[str], None] | None,
) -> tuple[Plan, Held | None, dict[str, Any] | None]:
    """The options and readings checked, the temperature's record, the held blocks and the
    knots' spacing (:func:`.knots.knot_step`)."""
    if isinstance(options.hold, str) and options.hold in HOLDS:  # the convention's old name
        options.gyro_sampling = next(k for k, v in SAMPLINGS.items() if v == options.hold)
        options.hold = None
    o = options
    _check_options(o.max_iter, o.rounds, o.tol, o.gyro_sampling, o.gyro_noise)
    held = o.prior if isinstance(o.prior, Held) else held_blocks(o.hold, o.prior)
    data = _inputs(*readings)
    drive = interference_inputs(o.inputs, len(data.time))  # :mod:`.covariates`
    thermal: dict[str, Any] | None = None
    if temperature is not None:
        data.temperature, thermal = temperature_record(
            _array("temperature", temperature, len(data.time), 1)
        )
    step, rule = knot_step(data.time, data.gyro)
    rate = 1.0 / float(np.median(np.diff(data.time)))
    knots = -(-len(data.time) // step)
    progress = None if on_progress is None else Progress(on_progress, knots, int(o.max_iter))
    return Plan(data, step, rule, rate, options, progress, drive), held, thermal


def _solve(plan: Plan, held: Held | None, thermal: dict[str, Any] | None) -> _Solution:
    """The start, the rounds (:func:`_rounds`), the temperature terms the log identifies
    (:func:`.thermal_terms.choose_orders`, then the rounds again) and fieldcal's gauge."""
    o = plan.options
    drive = plan.drive
    first, sampling, base_prior = _starting(plan.data, o.gyro_sampling, held, drive, o.attitude)
    first.rotations = np.ascontiguousarray(first.rotations[:: plan.step])
    state, knots, w, levels, total, converged = run_rounds(first, plan, base_prior)
    if thermal is not None and thermal["allowed_order"] > 0:
        allowed, o = thermal["allowed_order"], plan.options
        if plan.progress is not None:
            plan.progress.say("temperature terms")
        chosen_on = w  # the allowances would hide a drift not yet modelled (C6a)
        if o.allowances:
            chosen_on = plain_weights(state, knots, w, plan.length, float(levels["gyro"][0]))
        state, thermal["tests"] = choose_orders(
            state, knots, chosen_on, allowed, plan.batch, int(o.max_iter), float(o.tol)
        )
        thermal["orders"] = {s: len(c) for s, c in state.temps.items()}
        if state.temps:  # the noise levels again, with the terms
            state, knots, w, levels, more, converged = run_rounds(state, plan, base_prior)
            total += more
    state = _canonical(state)
    return _Solution(state, knots, w, levels, total, converged, sampling, thermal)


def _samples(plan: Plan, sol: _Solution) -> dict[str, Any]:
    """The optimum at every sample (:func:`.knots.sample_rotations`, :func:`.knots.sample_rates`,
    :func:`.model.residuals`): the rotations, rates, the accelerometer's residual in
    units of |g| (the body's acceleration) and the field sensors' per-stretch variances."""
    data = plan.data
    rotations = sample_rotations(data, sol.state, plan.step)
    ra, rm = residuals(dataclasses.replace(sol.state, rotations=rotations), data)
    length = max(1, round(STRETCH * plan.rate))
    return {
        "rotations": rotations,
        "rates": sample_rates(data, sol.state),
        "body": np.asarray(np.linalg.solve(sol.state.accel_gain, ra.T).T, dtype=np.float64),
        "accel": stretch_variance(ra, length, 0.0)[1],
        "mag": stretch_variance(rm, length, 0.0)[1],
        "length": length,
    }


def _chi_square(sol: _Solution) -> tuple[float, int]:
    """``χ²`` at the optimum (the knots' residuals, weighted) and its degrees of freedom."""
    state, knots, w = sol.state, sol.knots, sol.w
    ra, rm = residuals(state, knots)
    rg = state_factors(state, knots).residual
    chi2 = float(
        np.sum(w.accel * np.sum(ra**2, 1))
        + np.sum(w.mag * np.sum(rm**2, 1))
        + np.sum(w.gyro * np.sum(rg**2, 1))
    )
    k = len(knots.time)
    return chi2, 3 * k + 3 * k + 3 * (k - 1) - 3 * k - len(state.vector())


def _fit(
    readings: tuple[ArrayLike, ArrayLike, ArrayLike, ArrayLike],
    temperature: ArrayLike | None,
    rows: ArrayLike | None,
    options: Options,
    on_progress: Callable[[str], None] | None,
) -> Calibration:
    """:func:`fit_continuous` without the thread limit."""
    plan, held, thermal = _prepare(readings, temperature, options, on_progress)
    sol = _solve(plan, held, thermal)
    if plan.progress is not None:
        plan.progress.say("error bars (sandwich covariance)")
    cov, crb, _ = sandwich(sol.state, sol.knots, sol.w, plan.batch)
    per = _samples(plan, sol)
    n = len(plan.data.time)
    index = np.arange(n) if rows is None else np.asarray(rows, dtype=int)
    options_out, findings = _record(plan, sol, cov, crb, per, index, held)
    return _calibration(plan, sol, (cov, crb), per, options_out, findings)


def _record(
    plan: Plan,
    sol: _Solution,
    cov: ParameterCovariance,
    crb: ParameterCovariance,
    per: dict[str, Any],
    index: NDArray[np.int_],
    held: Held | None,
) -> tuple[dict[str, Any], Findings]:
    """``cal.options`` (what the fit did and measured) and the findings the verdict judges."""
    state, data, o = sol.state, plan.data, plan.options
    t, g = data.time, data.gyro
    widening = {
        group: float(np.sqrt(np.mean((cov.stds(names) / np.maximum(crb.stds(names), 1e-300)) ** 2)))
        for group, names in _GROUPS.items()
    }
    gains = {"accel": state.accel_gain, "mag": state.mag_gain, "gyro": state.gyro_gain}
    trajectory, motion = summary(t, per["rotations"], per["rates"], per["body"], o.gravity)
    # what the motion determines is the Fisher information's to say (the Cramér–Rao bound);
    # the widening for correlated residuals is a property of the disturbances, not the motion
    check = identifiability(
        crb, gains, trajectory["turned_deg"], float(trajectory["gravity_coverage"])
    )
    disturbed = downweighted(per["accel"], per["length"], t, per["body"], index)
    rate_var = float(sol.levels["gyro"][0])
    lacking = None
    if not sol.converged or check.unsettled:  # blame the motion only if it lacks something
        # on the readings as logged: a fit that did not settle has no trajectory to trust
        dt = np.diff(t)
        raw_turned = np.degrees(np.sum(np.abs(0.5 * (g[1:] + g[:-1])) * dt[:, None], axis=0))
        lacking = motion_advice(data.accel, raw_turned)
    measured = _measured(state, data, cov, per["rates"], per["length"], held)
    findings = _findings(check, disturbed, trajectory, lacking, sol.thermal, measured)
    step = max(1, round(EPOCH_SECONDS * plan.rate))
    options: dict[str, Any] = {
        "mode": "continuous",
        "allowances": bool(o.allowances),  # Eq. C6a–C6b
        "trajectory": trajectory,
        "motion": motion,
        "downweighted": disturbed,
        "noise": {
            "accel_quiet_std": float(np.sqrt(np.quantile(per["accel"], 0.1))),
            "mag_std": float(np.sqrt(np.median(per["mag"]))),
            "gyro_rate_std": float(np.sqrt(rate_var)),
        },
        "error_bars": {"batch_seconds": float(plan.batch / plan.knot_rate), "widening": widening},
        "identifiability": {
            "relative_std": check.relative_std,
            "advice": check.advice,
            "unsettled": check.unsettled,
        },
        **measured,
        "knots": {
            "count": len(sol.knots.time),
            "step": int(plan.step),
            "seconds": float(plan.step / plan.rate),
            "rule": plan.rule,
        },
        "epoch_seconds": float(step / plan.rate),
        "epoch_step": int(step),
        "hold": data.hold,
        "gyro_sampling": sol.sampling,
        "held": [] if held is None else list(held.names),
        "max_iter": int(o.max_iter),
        "rounds": int(o.rounds),
    }
    if sol.thermal is not None:
        options["temperature"] = sol.thermal
    return options, findings


def _calibration(
    plan: Plan,
    sol: _Solution,
    covariances: tuple[ParameterCovariance, ParameterCovariance],
    per: dict[str, Any],
    options: dict[str, Any],
    findings: Findings,
) -> Calibration:
    """The result: the three sensors, the field, the rotations every :data:`EPOCH_SECONDS`
    (``covariances``: the sandwich and the Cramér–Rao bound)."""
    state, cov = sol.state, covariances[0]
    rate_var = float(sol.levels["gyro"][0])
    white = gyro_rate_variance(plan.data.gyro, state.gyro_gain)
    temps = {} if sol.thermal is None else models(state, sol.thermal)
    chi2, dof = _chi_square(sol)
    Kg = state.gyro_gain
    return Calibration(
        accel=SensorCalibration(
            gain=state.accel_gain,
            bias=state.accel_bias,
            noise_cov=np.quantile(per["accel"], 0.1) * np.eye(3),
            noise_source="continuous residuals (quietest tenth)",
            temperature=temps.get("accel"),
        ),
        mag=SensorCalibration(
            gain=state.mag_gain,
            bias=state.mag_bias,
            noise_cov=float(np.median(per["mag"])) * np.eye(3),
            noise_source="continuous residuals",
            temperature=temps.get("mag"),
            interference=_interference(state, plan.drive, per["rotations"], covariances),
        ),
        gravity=GRAVITY,
        magnetic=magnetic_reference(state.dip),
        rotations=per["rotations"][:: options["epoch_step"]],
        method="continuous",
        iterations=sol.iterations,
        converged=sol.converged,
        message=(
            f"{sol.iterations} Levenberg-Marquardt iterations over {plan.options.rounds} noise "
            f"rounds, {len(sol.knots.time)} knots"
        ),
        options=options,
        covariance=cov,
        diagnostics=Diagnostics(chi2, dof, float(chdtrc(dof, chi2)), np.zeros(0)),
        findings=findings,
        gyro=SensorCalibration(
            gain=Kg,
            bias=state.gyro_bias,
            noise_cov=rate_var * Kg @ Kg.T,
            noise_source=_gyro_source(plan.options.gyro_noise, rate_var, white),
            temperature=temps.get("gyro"),
        ),
    )
