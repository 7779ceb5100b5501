"""The gyroscope's gain, misalignment and bias from a log with still poses and motion between
them, by maximum likelihood (``docs/methods/gyro.md`` derives every step).

Model: ``raw = K_g ω + b_g + ε``, ``ω`` the body-frame angular rate (rad/s) in the common body
frame of the calibration, ``dR/dt = −[ω]× R`` with ``R`` world (NED) → body.

1. **Bias.** Each still pose's mean raw rate ``p_i`` (the Earth's rotation, 7.3e-5 rad/s, is
   below a MEMS gyroscope's noise and is left in it); a straight line through them against time
   is the drift, with its significance. The bias at any time during a motion is interpolated
   linearly between the two poses around it; the poses' biases ``b_i`` are parameters of the
   fit with ``p_i`` as their prior, ``p_i ~ N(b_i, Q/T_i + v I)`` (``Q`` the rate noise
   density, ``T_i`` the pose's duration, ``v`` the poses' bias wander beyond white noise).
2. **Segments.** Between consecutive poses ``i → i+1`` the corrected rate
   ``ω = K_g⁻¹ (raw − b(t))`` is integrated exactly (quaternions, :mod:`.integrate`) into
   ``ΔR̂_i``; the observation is ``ΔR_i = R_{i+1} R_iᵀ`` of the joint fit (``method="rotations"``)
   or, with an accelerometer alone, the gravity direction at pose ``i+1`` (``"gravity"``,
   Tedaldi et al. 2014): ``u_{i+1} ≈ ΔR̂_i u_i``.
3. **Likelihood.** Residuals ``log(ΔR_iᵀ ΔR̂_i)`` (body frame at pose ``i``) or the tangent-plane
   components of ``ΔR̂_i u_i`` at ``u_{i+1}``, all segments together whitened by their joint
   covariance: the poses' orientation errors (the joint fit's Cramér-Rao covariance, shared
   between neighbouring segments) plus the integrated white noise of the rate. Gauss-Newton with
   Levenberg-Marquardt damping and analytic Jacobians, in ``M = K_g⁻¹`` (the rate is linear in
   it); the covariance of ``K_g`` and ``b_g`` is the Cramér-Rao bound at the optimum, mapped to
   ``K_g = M⁻¹``, widened by ``χ²/dof`` when the segments' χ² rejects the model at 5 %.
4. **Observability.** The information matrix of the gain, the biases eliminated, tells which
   combinations of ``K_g``'s entries the motions determine; the rest is refused with an
   :class:`~fieldcal.errors.InputError` naming them (or, with ``allow_partial=True``, held at
   the start and left out of :attr:`GyroFit.observable` and the covariance).

The steps live in their own modules: :mod:`.data` (poses, drift, segments),
:mod:`.model` (residuals, Jacobians), :mod:`.start`, :mod:`.noise` (the
segments' covariance), :mod:`.solver`, :mod:`.observability`,
:mod:`.uncertainty`; this module checks the input and runs them in order.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtrc

from ..errors import InputError
from ..likelihood.cramer_rao import PoseCovariance
from ..limits import power_of_two
from .data import build_segments, check_rows, check_saturation, drift_line, pose_statistics
from .integrate import HOLDS, Hold, effective_time
from .model import Array, Method, SegmentModel
from .noise import PoseErrors, match_chi2, pose_covariance
from .normal import NormalSystem
from .observability import null_space, reset_null, unobservable_message
from .result import BIAS_NAMES, GAIN_NAMES, GyroFit
from .solver import MIN_SEGMENTS, Rounds
from .start import guess_matrix, start_gravity, start_rotations
from .uncertainty import WIDEN_P, named_covariance, residual_degrees

__all__ = ["BIAS_NAMES", "GAIN_NAMES", "GyroFit", "fit_gyro"]


def fit_gyro(
    time: ArrayLike,
    gyro_raw: ArrayLike,
    poses: Sequence[Sequence[int]],
    rotations: ArrayLike | None = None,
    *,
    rotation_cov: ArrayLike | PoseCovariance | None = None,
    gravity_body: ArrayLike | None = None,
    gravity_cov: ArrayLike | PoseCovariance | None = None,
    links: Sequence[int] | None = None,
    gain_guess: float | ArrayLike | None = None,
    full_scale: float | None = None,
    hold: Hold = "midpoint",
    allow_partial: bool = False,
    max_iter: int = 50,
    on_progress: Callable[[str], None] | None = None,
) -> GyroFit:
    """Fit the gyroscope's gain and bias from still poses and the motion between them.

    Parameters
    ----------
    time : (n,) array_like
        Seconds, non-decreasing (repeated timestamps are spread, :func:`.effective_time`).
    gyro_raw : (n, 3) array_like
        Raw gyroscope readings, any units.
    poses : sequence of (start, stop)
        Rows of each still pose (stop exclusive), in time order.
    rotations : (N, 3, 3) array_like, optional
        Each pose's rotation world (NED) → body from the joint fit (``cal.rotations``):
        ``method="rotations"``.
    rotation_cov : (N, 3, 3) or (3N, 3N) array_like, or PoseCovariance, optional
        Covariance of the poses' small body-frame rotation errors (``R ← exp([δ]×) R``),
        radians²: per pose, or joint with the poses' shared errors, best in its structure
        (:func:`fieldcal.likelihood.cramer_rao.pose_rotation_factors`: time and memory linear
        in the number of poses; a dense (3N, 3N) matrix is factored first, cubic in N).
        Without it an isotropic orientation error is estimated from the fit (needs more than
        3 segments).
    gravity_body : (N, 3) array_like, optional
        Without ``rotations``: each pose's calibrated accelerometer reading (any length; the
        direction is used), ``method="gravity"``.
    gravity_cov : (N, 3, 3) or (3N, 3N) array_like, or PoseCovariance, optional
        Covariance of ``gravity_body`` (its units squared), per pose or joint; for an
        accelerometer calibration ``X C Xᵀ`` with ``X = blockdiag(−[g_i]×)`` and ``C`` its
        :func:`~fieldcal.likelihood.cramer_rao.pose_rotation_covariance`
        (structured: ``pose_rotation_factors(cal).transformed(X_i)``). Without it an
        isotropic direction error is estimated from the fit.
    links : sequence of int, optional
        The segments to use, ``k`` for the motion from pose ``k`` to ``k + 1`` (default all):
        leave out gaps where the log was cut.
    gain_guess : float or (3, 3) array_like, optional
        An approximate gain (raw units per rad/s, e.g. the datasheet's), to count the turns of
        segments that turn by more than half a turn (a full turn ends where it began).
    full_scale : float, optional
        The gyroscope's range in raw units: readings beyond 99.9 % of it during a turn are
        refused as saturated (without it, a reading held at the log's extreme for 4 rows is).
    hold : {"midpoint", "previous"}
        The rate over each interval between samples (:mod:`.integrate`).
    allow_partial : bool
        Fit what the data determine instead of refusing: the fit moves only along the
        determined combinations of the gain's entries and puts the undetermined ones back at
        the start's values (``gain_guess``, else the linear start); the entries they touch are
        left out of ``observable`` and the covariance (their values are not to be trusted).
    max_iter : int
        Gauss-Newton iterations per round.
    on_progress : callable, optional
        Called with a line of progress as the fit takes in more segments (``"gyroscope:
        segment k/N"``).

    Returns
    -------
    GyroFit

    Raises
    ------
    InputError
        For input that cannot give a calibration, in one line naming the fix: too few poses or
        motion segments, time going backwards, a saturating gyroscope, turns that do not
        determine every gain entry (unless ``allow_partial``).
    """
    t, raw, unit = _rates(time, gyro_raw, hold)
    rows = check_rows(poses, len(t))
    n_poses, link = len(rows), _links(links, len(rows))
    method, observed = _observations(rotations, gravity_body, n_poses)
    means, times, durations, noise_cov, _, Q = pose_statistics(t, raw, rows)
    scale_limit = None if full_scale is None else full_scale / unit
    slope, drift_p, wander, prior_cov = _bias_priors(
        raw, rows, link, scale_limit, means, times, durations, noise_cov, Q
    )
    data = build_segments(t, raw, rows, link, times, hold)
    full = SegmentModel(data, method, n_poses, observed, Q)
    M0 = _start(full, means, observed, guess_matrix(gain_guess, unit))
    x = np.concatenate([M0.ravel(), means.ravel()])
    pose = _pose_errors(method, observed, rotation_cov, gravity_body, gravity_cov)
    if pose.estimated and full.d * len(link) - 9 < 1:
        raise InputError(_no_residual_message(len(link), method))
    motion = (t, raw, rows, link, times, hold)
    rounds = Rounds(full, motion, pose, prior_cov, means, max_iter, on_progress)
    x, scale2, unobservable = _fit(rounds, x, M0, method, allow_partial)
    stats = _PoseRates(unit, n_poses, means, times, durations, noise_cov, Q, slope, drift_p, wander)
    return _gyro_fit(rounds, pose, stats, x, M0, scale2, unobservable, method, full.d)


def _start(full: SegmentModel, means: Array, observed: Array, guess: Array | None) -> Array:
    """The linear start of the gain's inverse: from the poses' rotations, or from gravity's
    directions (:mod:`.start`)."""
    if full.method == "rotations":
        return start_rotations(full.data, means, full.observed, guess)
    return start_gravity(full.data, means, observed, guess, full.n)


@dataclass(frozen=True)
class _PoseRates:
    """What the poses' readings say before the fit, for the result: the unit (raw per rad/s
    of the start), each pose's mean rate, time, duration, the rate noise, and the bias drift
    (slope, its p-value, the wander between poses)."""

    unit: float
    n_poses: int
    means: Array
    times: Array
    durations: Array
    noise_cov: Array
    Q: Array
    slope: Array | None
    drift_p: float | None
    wander: float


def _gyro_fit(
    rounds: Rounds,
    pose: PoseErrors,
    stats: _PoseRates,
    x: Array,
    M0: Array,
    scale2: float,
    unobservable: tuple[str, ...],
    method: str,
    d: int,
) -> GyroFit:
    """The fitted gain and bias with their covariance and the checks the verdict reads (the
    segments' χ² and p-value, a widening when a given pose covariance is rejected, the
    segments refused), in the readings' units."""
    unit, n_poses, means, times = stats.unit, stats.n_poses, stats.means, stats.times
    durations, noise_cov, Q = stats.durations, stats.noise_cov, stats.Q
    slope, drift_p, wander = stats.slope, stats.drift_p, stats.wander
    final = rounds.model_of(rounds.used())
    ev = final.evaluate(x)
    dof = d * len(rounds.used()) - 9
    if pose.estimated:
        scale2 = match_chi2(ev, lambda e, s2: pose.segment_covariance(final, e, s2), dof, scale2)
    noise = pose.segment_covariance(final, ev, scale2)
    chi2 = noise.quadratic(ev.r)
    normal = NormalSystem(noise, ev, x, means, rounds.prior_inv, rounds.restrict)
    if rounds.restrict is not None:  # the undetermined part back at the start's values
        x[:9] = reset_null(x[:9].reshape(3, 3), rounds.restrict, M0).ravel()
        ev = final.evaluate(x)
    K: Array = np.asarray(np.linalg.inv(x[:9].reshape(3, 3)), dtype=float)
    weights = durations / durations.sum()
    p_value = float(chdtrc(dof, chi2)) if dof > 0 else 1.0
    # a given covariance the segments reject: widened by χ²/dof
    widen = chi2 / dof if not pose.estimated and dof > 0 and p_value < WIDEN_P else 1.0
    covariance = named_covariance(
        normal, K, rounds.restrict, weights, widen * unit * unit, unobservable
    )
    refused, refused_deg = _refused(rounds, x, method)
    return GyroFit(
        gain=K * unit,
        bias=weights @ x[9:].reshape(n_poses, 3) * unit,
        noise_cov=noise_cov * unit * unit,
        covariance=covariance,
        pose_bias=means * unit,
        pose_time=times,
        pose_duration=durations,
        drift=None if slope is None else float(np.linalg.norm(slope)) * unit,
        segment_residual_deg=residual_degrees(ev.r, method),
        segments=final.data.rows,
        observable=_observable(unobservable),
        method=method,
        drift_rate=None if slope is None else slope * unit,
        drift_p_value=drift_p,
        bias_wander=math.sqrt(wander) * unit,
        rate_noise=Q * unit * unit,
        statistic=chi2,
        dof=dof,
        p_value=p_value,
        widening=widen,
        iterations=rounds.iterations,
        converged=rounds.converged,
        rejected=refused,
        rejected_residual_deg=refused_deg,
    )


def _bias_priors(
    raw: Array,
    rows: NDArray[np.int64],
    link: NDArray[np.int64],
    full_scale: float | None,
    means: Array,
    times: Array,
    durations: Array,
    noise_cov: Array,
    Q: Array,
) -> tuple[Array | None, float | None, float, Array]:
    """The still poses checked (time order, no clipping during the turns, some noise) and the
    drift line through their means: slope, its p-value, the wander and the biases' priors."""
    if np.any(np.diff(times) <= 0):
        raise InputError("the still poses must be in time order")
    sigma = np.sqrt(np.diag(noise_cov))
    check_saturation(raw, rows, link, full_scale, means.mean(0), sigma)
    slope, drift_p, wander, prior_cov = drift_line(means, times, durations, Q)
    if not np.all(np.linalg.eigvalsh(prior_cov) > 0):
        raise InputError(
            "the still poses show no gyroscope noise at all (identical readings); give the raw "
            "readings, not a smoothed or constant column"
        )
    return slope, drift_p, wander, prior_cov


def _no_residual_message(m: int, method: str) -> str:
    """Too few segments to estimate the poses' orientation error from."""
    given = "rotation_cov" if method == "rotations" else "gravity_cov"
    return (
        f"{m} motion segments leave no residual to estimate the poses' orientation error "
        f"from; give {given} or record more poses"
    )


def _refused(rounds: Rounds, x: Array, method: str) -> tuple[tuple[tuple[int, int], ...], Array]:
    """The rows of the segments left out and their residual angles at ``x``."""
    if not rounds.dropped:
        return (), np.zeros(0)
    out = rounds.model_of(sorted(rounds.dropped))
    return out.data.rows, residual_degrees(out.residuals(x), method)


def _observable(unobservable: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(n for n in GAIN_NAMES + BIAS_NAMES if n not in unobservable)


def _fit(
    rounds: Rounds, x: Array, M0: Array, method: str, allow_partial: bool
) -> tuple[Array, float, tuple[str, ...]]:
    """The rounds, between two checks of what the turns determine: at the start (linearised)
    and at the optimum (a full turn ends where it began whatever its axis: the turns may
    determine less there), refitting what is determined. Returns ``x``, the orientation
    variance and the gain entries left undetermined."""
    full, pose = rounds.full, rounds.pose
    ev = full.evaluate(x, linear=True)
    scale2 = max(float(np.mean(ev.r * ev.r)), 1e-12)  # the residuals' mean square
    noise = pose.segment_covariance(full, ev, scale2)
    info = NormalSystem(noise, ev, x, rounds.means, rounds.prior_inv).gain_information()
    basis, unobservable = null_space(info, np.asarray(np.linalg.inv(M0), dtype=float))
    if unobservable and not allow_partial:
        raise InputError(unobservable_message(unobservable, method))
    rounds.restrict = None if basis.shape[1] == 9 else basis
    x, scale2 = rounds.run(x, scale2)
    final = rounds.model_of(rounds.used())
    ev = final.evaluate(x)
    noise = pose.segment_covariance(final, ev, scale2)
    info = NormalSystem(noise, ev, x, rounds.means, rounds.prior_inv).gain_information()
    basis, more = null_space(info, np.asarray(np.linalg.inv(x[:9].reshape(3, 3)), dtype=float))
    if set(more) - set(unobservable):
        if not allow_partial:
            raise InputError(unobservable_message(more, method))
        unobservable = tuple(n for n in GAIN_NAMES if n in set(more) | set(unobservable))
        rounds.restrict = basis
        x[:9] = reset_null(x[:9].reshape(3, 3), basis, M0).ravel()
        x, scale2 = rounds.fit_set(rounds.used(), x, scale2, True)
    return x, scale2, unobservable


def _rates(time: ArrayLike, gyro_raw: ArrayLike, hold: Hold) -> tuple[Array, Array, float]:
    """The effective time and the raw readings, checked, in units of an exact power of two
    (the same numbers whatever the raw unit), and that unit."""
    raw_given = np.asarray(gyro_raw, dtype=float)
    if raw_given.ndim != 2 or raw_given.shape[1] != 3:
        raise InputError(f"gyro_raw must have shape (n, 3), got {raw_given.shape}")
    if not np.all(np.isfinite(raw_given)):
        row = int(np.argmin(np.all(np.isfinite(raw_given), axis=1)))
        raise InputError(f"gyro_raw has a NaN or inf value at row {row}; drop or fix that row")
    if hold not in HOLDS:
        raise InputError(f"hold must be one of {', '.join(HOLDS)}; got {hold!r}")
    t = effective_time(time)
    if len(t) != len(raw_given):
        raise InputError(
            f"time has {len(t)} rows but gyro_raw has {len(raw_given)}; pass equal rows"
        )
    unit = power_of_two(float(np.max(np.abs(raw_given))) or 1.0)
    return t, raw_given / unit, unit


def _links(links: Sequence[int] | None, n_poses: int) -> NDArray[np.int64]:
    """The segments to use (``k``: pose ``k`` to ``k + 1``), checked."""
    if links is None:
        link = np.arange(n_poses - 1, dtype=np.int64)
    else:
        link = np.unique(np.asarray(list(links), dtype=np.int64))
        if link.size and (link.min() < 0 or link.max() > n_poses - 2):
            raise InputError(f"links must be pose numbers from 0 to {n_poses - 2}")
    if len(link) < MIN_SEGMENTS:
        raise InputError(
            f"{len(link)} motion segment(s) between still poses; the gyroscope's 9 gain entries "
            f"need at least {MIN_SEGMENTS} turns about different axes, each between two rests"
        )
    return link


def _observations(
    rotations: ArrayLike | None, gravity_body: ArrayLike | None, n_poses: int
) -> tuple[Method, Array]:
    """The method and what it observes per pose: rotations, or unit gravity directions."""
    if rotations is not None:
        Rs = np.asarray(rotations, dtype=float)
        if Rs.shape != (n_poses, 3, 3) or not np.all(np.isfinite(Rs)):
            raise InputError(
                f"rotations must have shape ({n_poses}, 3, 3), one per pose; got {Rs.shape}"
            )
        if not np.allclose(Rs @ np.transpose(Rs, (0, 2, 1)), np.eye(3), atol=1e-6):
            raise InputError("rotations must be rotation matrices (orthonormal, det +1)")
        return "rotations", Rs
    if gravity_body is not None:
        g = np.asarray(gravity_body, dtype=float)
        if g.shape != (n_poses, 3) or not np.all(np.isfinite(g)):
            raise InputError(f"gravity_body must have shape ({n_poses}, 3), one per pose")
        norm = np.linalg.norm(g, axis=1)
        if not np.all(norm > 0):
            raise InputError("gravity_body has a zero vector; give calibrated accelerometer means")
        return "gravity", g / norm[:, None]
    raise InputError(
        "give the poses' rotations (a joint calibration's cal.rotations) or, with an "
        "accelerometer alone, gravity_body (its calibrated pose means)"
    )


def _pose_errors(
    method: Method,
    observed: Array,
    rotation_cov: ArrayLike | PoseCovariance | None,
    gravity_body: ArrayLike | None,
    gravity_cov: ArrayLike | PoseCovariance | None,
) -> PoseErrors:
    """The poses' part of the residual covariance: given, or s² times a unit shape."""
    n_poses = len(observed)
    none = np.zeros((n_poses, 3, 0))
    if method == "rotations":
        if rotation_cov is None:
            return PoseErrors(np.broadcast_to(np.eye(3), (n_poses, 3, 3)).copy(), none, True)
        given = pose_covariance(rotation_cov, n_poses, "rotation_cov")
        return PoseErrors(given.blocks, given.factor, False)
    across = np.eye(3) - np.einsum("ni,nj->nij", observed, observed)
    if gravity_cov is None:
        return PoseErrors(across, none, True)
    C = pose_covariance(gravity_cov, n_poses, "gravity_cov")
    gnorm = np.linalg.norm(np.asarray(gravity_body, dtype=float), axis=1)
    # the unit direction's error: the part across the vector, over its length
    given = C.transformed(across / gnorm[:, None, None])
    return PoseErrors(given.blocks, given.factor, False)
