"""The shared path every method's fit goes through: noise model, robust refit, error bars,
certificate, verdict and accuracy.

1. The method fits the poses (its own algorithm, its own weights).
2. The pose-level noise is estimated (:mod:`.pose_noise`) at the maximum-likelihood point: the
   method's own result when it weighs poses by their covariance (``mle``), otherwise a
   maximum-likelihood polish started from it, so the data are judged the same way whichever
   method ran. One sample per pose is the special case without Eq. 7.
3. Robust (default): every pose and sensor is tested (:mod:`.outliers`); the worst flagged pose
   is dropped and everything refitted, until none is flagged or dropping more would leave too
   few poses.
4. The method's estimate is evaluated under the final noise model: Cramér-Rao covariance
   (widened for the estimated noise), the χ² certificate, the pose table; a non-ML method's
   distance from the ML optimum is measured.
5. The verdict (:mod:`.verdict`) and the predicted accuracy (:mod:`.accuracy`).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtrc

from ..calibration import (
    Calibration,
    ParameterCovariance,
    RejectedPose,
    SensorCalibration,
)
from ..methods import METHODS, Method
from ..reference import FieldReference
from ..settings import FitSettings, TrustSettings
from ..stats.noise_models import wishart_std
from ..stats.pose_stats import PoseStats, Samples
from .accuracy import predict_accuracy
from .certificate import certify, pose_table
from .correlation import widen_for_correlation
from .evaluate import Evaluation, evaluate
from .handedness import Handedness, decide, reference_mirrored
from .outliers import REASONS, PoseTests, pose_tests
from .pose_noise import (
    PoseNoise,
    estimate,
    initial_variances,
    noise_reported,
    widening,
    with_variances,
)
from .targets import Targets
from .verdict import PoseFindings, ReferenceCheck, judge

__all__ = ["Handedness", "decide", "fit_trusted", "reference_mirrored"]

Array = NDArray[np.float64]


def _subset(samples: Samples | None, keep: NDArray[np.int64]) -> Samples | None:
    if samples is None or (isinstance(samples, np.ndarray) and samples.ndim == 2):
        return samples
    return [samples[int(i)] for i in keep]


def _plain(stats: PoseStats) -> PoseStats:
    """Statistics for a method that weighs with Eq. 7 only: no pose-level variance; with one
    sample per pose the estimated variance stands in for Eq. 7."""
    return stats.replace(
        **{
            s: dataclasses.replace(
                stats.sensor(s), cov=noise_reported(stats.sensor(s)), pose_var=0.0
            )
            for s in stats.sensors
        }
    )


class _Runner:
    """Runs the chosen method, and the ML polish for methods that do not weigh poses."""

    def __init__(
        self,
        method: Method,
        raw: Mapping[str, Samples | None],
        body_frame: str,
        options: Mapping[str, object],
        progress: Callable[[str], None] | None = None,
    ) -> None:
        self.method = method
        self.fit = method.load()
        self.raw = raw
        self.body_frame = body_frame
        self.options = options
        self.progress = progress
        self.mle = METHODS["mle"]

    def method_fit(
        self, stats: PoseStats, keep: NDArray[np.int64], previous: Calibration | None
    ) -> Calibration:
        kwargs = dict(self.options)
        if previous is not None and self.method.warm_start and "initial" not in kwargs:
            kwargs["initial"] = previous
        given = stats if self.method.pose_weights else _plain(stats)
        return self.fit(
            given,
            raw_accel=_subset(self.raw["accel"], keep),
            raw_mag=_subset(self.raw["mag"], keep),
            body_frame=self.body_frame,
            progress=self.progress,
            **kwargs,
        )

    def polish_possible(self, stats: PoseStats) -> bool:
        return stats.n_poses >= self.mle.min_poses_for(len(stats.sensors))

    def ml_refit(self, stats: PoseStats, previous: Calibration) -> Calibration:
        """The ML fit from ``previous`` under ``stats``' noise model (the trust path's
        yardstick)."""
        fit = self.fit if self.method.pose_weights else self.mle.load()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the method's own fit already warned
            kwargs = dict(self.options) if self.method.pose_weights else {}
            kwargs["initial"] = previous
            return fit(stats, body_frame=self.body_frame, **kwargs)


def _noise_round(
    runner: _Runner,
    cal: Calibration,
    stats: PoseStats,
    keep: NDArray[np.int64],
    free: tuple[str, ...],
) -> tuple[Calibration, Calibration, PoseStats, Evaluation, PoseNoise]:
    """The pose-level noise at the ML point, for a method result ``cal`` fitted to ``stats``.

    Returns the method's result (refitted when its weights depend on the estimated noise), the
    ML point, the statistics with the estimated variances, the ML evaluation and the noise."""
    one_sample = any(stats.sensor(s).cov is None for s in stats.sensors)
    if runner.method.pose_weights or not runner.polish_possible(stats):
        if runner.method.pose_weights or one_sample:

            def refit(current: PoseStats, previous: Calibration) -> Calibration:
                return runner.method_fit(current, keep, previous)

        else:

            def refit(current: PoseStats, previous: Calibration) -> Calibration:
                return previous  # its weights do not change: nothing to refit

        fitted, current, ev, noise = estimate(refit, cal, stats, runner.body_frame, free)
        return fitted, fitted, current, ev, noise
    ml = runner.ml_refit(stats, cal)
    ml, current, ev, noise = estimate(runner.ml_refit, ml, stats, runner.body_frame, free)
    if one_sample:  # the method's weights stood on a guess of the noise: refit with the estimate
        cal = runner.method_fit(current, keep, cal)
    return cal, ml, current, ev, noise


#: From this many poses on (samples and windows modes), every flagged pose is dropped in one
#: round: each weighs about 1/N in the fit, so dropping one barely changes the others' tests,
#: and a refit per pose would cost thousands of fits on a long log.
MANY_POSES = 200


def _worst(p_min: Array, flagged: NDArray[np.bool_], spare: int) -> NDArray[np.intp]:
    """The poses to drop this round (``p_min``: each pose's smallest p-value): the worst
    flagged one, or with :data:`MANY_POSES` or more every flagged one, worst first, at most
    ``spare``."""
    order = np.argsort(np.where(flagged, p_min, np.inf), kind="stable")
    count = int(flagged.sum()) if len(p_min) >= MANY_POSES else 1
    return order[: max(1, min(count, spare))]


#: From this many poses on, the pose-level variances to estimate are first estimated on an
#: evenly spaced subset of :data:`SUBSET_POSES`, the whole problem's first fit starting from
#: them: its fixed point (:func:`.pose_noise.estimate`) is then one or two refits away instead of
#: a first fit with a guess a thousand times off and refits of tens of iterations each.
SUBSET_NOISE_POSES = 2000
SUBSET_POSES = 400


def _subset_variances(runner: _Runner, stats: PoseStats, free: tuple[str, ...]) -> PoseStats:
    """``stats`` with the variances of ``free`` estimated on :data:`SUBSET_POSES` of its poses."""
    index = np.unique(np.linspace(0, stats.n_poses - 1, SUBSET_POSES).round().astype(np.int64))
    sub = stats.subset(index)
    cal = runner.method_fit(sub, index, None)
    noise = _noise_round(runner, cal, sub, index, free)[4]
    return with_variances(stats, {s: noise.variance[s] for s in free})


def _rejections(
    tests: PoseTests,
    worst: NDArray[np.intp],
    keep: NDArray[np.intp],
    alpha: float,
    current: PoseStats,
    on_progress: Callable[[str], None] | None,
) -> list[RejectedPose]:
    """The poses ``worst`` (indices into ``keep``) as rejected, each with its test's figures."""
    out = []
    for i in worst:
        kind, why = tests.kind(int(i), alpha, current)
        column = int(np.argmin(tests.p_value[i]))
        out.append(
            RejectedPose(
                index=int(keep[i]),
                sensor=kind,
                statistic=float(tests.statistic[i, column]),
                p_value=float(tests.p_value[i, column]),
                reason=REASONS[why],
            )
        )
        if on_progress is not None:
            on_progress(f"dropped pose {int(keep[i])} ({kind})")
    return out


def fit_trusted(
    method: Method,
    stats: PoseStats,
    *,
    raw_accel: Samples | None,
    raw_mag: Samples | None,
    fit: FitSettings,
    trust: TrustSettings,
    options: Mapping[str, object],
    sources: dict[str, str],
    pose_noise: dict[str, float | None],
    reference: FieldReference | None = None,
    on_progress: Callable[[str], None] | None = None,
    targets: Targets | None = None,
    magnitudes: Mapping[str, tuple[float, float]] | None = None,
    time_ordered: bool = False,
) -> Calibration:
    """Fit with ``method`` and attach the noise model, error bars, certificate, rejected poses,
    verdict and accuracy (see the module docstring). ``stats`` must hold all the caller's poses;
    ``cal.rejected`` and ``cal.poses`` use their numbering.

    ``fit`` and ``trust`` are the settings as :func:`fieldcal.api.calibrate_with` checked them:
    ``fit.body_frame``, ``fit.robust`` (the pose tests and refits), ``fit.mag_mirrored``,
    ``trust.false_alarm`` (the tests' family-wise rate) and ``trust.dip_allowance_deg`` are
    read here. With a ``reference`` (the World Magnetic Model's field at the site) the
    magnetometer's handedness follows its dip rather than ``fit.mag_mirrored``
    (:func:`~fieldcal.trust.handedness.decide`) and the verdict compares the dips. The
    handedness is decided here, once: ``cal.options["mag_mirrored"]`` and
    ``["mag_handedness"]`` (``"stated"`` or ``"reference"``) carry the decision.

    ``targets`` are the verdict's accuracy targets (default :class:`~fieldcal.trust.targets.
    Targets` ()); ``magnitudes`` maps each sensor whose field magnitude the user gave to
    ``(factor, given)`` (:class:`~fieldcal.trust.verdict.Case`), for the gain rules.
    ``time_ordered``: the poses are consecutive pieces of one continuous motion, in time order;
    the error bars are widened for the correlation measured between neighbours
    (:func:`~fieldcal.trust.correlation.widen_for_correlation`)."""
    raw = {"accel": raw_accel, "mag": raw_mag}
    runner = _Runner(method, raw, fit.body_frame, options, on_progress)
    alpha, mag_mirrored = trust.false_alarm, bool(fit.mag_mirrored)
    n_total = stats.n_poses
    keep = np.arange(n_total)
    # one sample per pose: the pose-level variance is the only noise there is, so it is
    # estimated even under pose_noise="none" (the residual-noise special case)
    fixed = {
        s: None if stats.sensor(s).cov is None and not pose_noise.get(s) else pose_noise.get(s)
        for s in stats.sensors
    }
    free = tuple(s for s in stats.sensors if fixed[s] is None)
    start = initial_variances(stats, fixed)
    if free and n_total >= SUBSET_NOISE_POSES:
        start = _subset_variances(runner, start, free)
    cal = runner.method_fit(start, keep, None)
    first_options = dict(cal.options)  # the cold fit's account (starts tried), for provenance
    cal, ml, current, ev, noise = _noise_round(runner, cal, start, keep, free)
    rejected: list[RejectedPose] = []
    left = 0
    min_keep = max(method.min_poses_for(len(stats.sensors)), n_total - n_total // 2)
    while fit.robust:
        tests = pose_tests(ev, current, noise)
        flagged = tests.flagged(alpha)
        if not flagged.any():
            break
        if len(keep) - 1 < min_keep:
            left = int(flagged.sum())
            break
        worst = _worst(tests.p_value.min(axis=1), flagged, len(keep) - min_keep)
        rejected += _rejections(tests, worst, keep, alpha, current, on_progress)
        local = np.delete(np.arange(len(keep)), worst)
        keep = keep[local]
        sub = current.subset(local)  # the current noise model as the start
        previous = dataclasses.replace(cal, rotations=cal.rotations[local])
        cal = runner.method_fit(sub, keep, previous)
        cal, ml, current, ev, noise = _noise_round(runner, cal, sub, keep, free)
    # the cold fit's account goes into the options in _finish's one replace: ``cal`` stays the
    # very object ``ml`` is when the method is the ML fit, so it is not evaluated twice
    result, found = _finish(
        cal, ml, current, ev, noise, runner, keep, rejected, left, sources, n_total, first_options
    )
    if time_ordered:  # consecutive pieces of one motion: measured correlation widens the bars
        result = widen_for_correlation(result)
    return conclude(
        result,
        mag_mirrored,
        reference,
        trust.dip_allowance_deg,
        current=current,
        found=found,
        targets=targets,
        magnitudes=magnitudes,
    )


def conclude(
    result: Calibration,
    mag_mirrored: bool,
    reference: FieldReference | None,
    dip_allowance_deg: float,
    *,
    current: PoseStats | None = None,
    found: PoseFindings | None = None,
    targets: Targets | None = None,
    magnitudes: Mapping[str, tuple[float, float]] | None = None,
) -> Calibration:
    """The trust path's last steps, for the pose fits and the continuous fit alike: the
    magnetometer's handedness (a choice of gauge, so made before the verdict reads the dip;
    :func:`.handedness.decide`), the predicted accuracy and the verdict (:func:`.verdict.judge`
    with ``current``, ``found``, ``targets`` and ``magnitudes``), attached with the
    reference and the handedness options."""
    hand = decide(result, mag_mirrored, reference, dip_allowance_deg)
    check = None
    if reference is not None:
        check = ReferenceCheck(reference, dip_allowance_deg, mag_mirrored, hand.decided)
    result = result.with_mag_handedness(hand.mirrored)
    accuracy = predict_accuracy(result)
    verdict = judge(
        result,
        current,
        found,
        accuracy,
        check,
        targets=targets,
        magnitudes=magnitudes,
    )
    return dataclasses.replace(
        result,
        accuracy=accuracy,
        verdict=verdict,
        field_reference=reference,
        options={**result.options, **hand.options},
    )


def _finish(
    cal: Calibration,
    ml: Calibration,
    stats: PoseStats,
    ev_ml: Evaluation,
    noise: PoseNoise,
    runner: _Runner,
    keep: NDArray[np.int64],
    rejected: Sequence[RejectedPose],
    left: int,
    sources: dict[str, str],
    n_total: int,
    first_options: Mapping[str, object],
) -> tuple[Calibration, PoseFindings]:
    ev = ev_ml if cal is ml else evaluate(cal, stats, runner.body_frame)
    factor = widening(ev_ml, noise, stats)
    unc = ev.uncertainty
    covariance = unc.covariance  # as it is when not widened (its sensor blocks made once)
    if factor != 1.0:
        covariance = ParameterCovariance(covariance.names, covariance.matrix * factor)
    estimated = [s for s in noise.estimated if noise.variance[s] > 0]
    status = "pose noise estimated" if estimated else "ok"
    diagnostics = certify(ev, status)
    sensors: dict[str, SensorCalibration] = {}
    for s in stats.sensors:
        st = stats.sensor(s)
        one_sample = st.cov is None
        source = "residuals" if one_sample else sources.get(s, "scatter")
        noise_std = None
        if source == "scatter" and st.cov is not None:  # cov is None only when one_sample
            noise_std = wishart_std(st.cov, st.dof)
        elif source == "residuals":
            nu = max(ev_ml.dof_share()[s], 1.0)
            noise_std = np.eye(3) * st.pose_var * np.sqrt(2.0 / nu)
        sensors[s] = dataclasses.replace(
            cal.sensor(s),
            noise_cov=noise_reported(st),
            noise_cov_std=noise_std if noise_std is not None else np.zeros((3, 3)),
            noise_source=source,
            pose_noise_std=0.0 if one_sample else float(np.sqrt(st.pose_var)),
            covariance=covariance.sensor_blocks[s],  # the block the result will hold
            pose_noise_std_se=None if one_sample else noise.std_se.get(s),
        )
    excess = None
    if cal is not ml and runner.polish_possible(stats):
        diff = max(diagnostics.statistic - float(ev_ml.pose_cost.sum()), 0.0)
        G = ev.problem.n_global
        p = float(chdtrc(G, diff))
        if p < 0.01:
            excess = {"method": cal.method, "excess": diff, "dof": G, "p": p}
    options = {
        **cal.options,
        **first_options,
        "pose_noise": {
            s: ("estimated" if s in noise.estimated else "given") for s in stats.sensors
        },
        "noise_sources": {s: sensors[s].noise_source for s in stats.sensors},
    }
    result = dataclasses.replace(
        cal,
        covariance=covariance,
        diagnostics=diagnostics,
        poses=tuple(pose_table(ev, stats, keep)),
        rejected=tuple(rejected),
        options=options,
        accel=sensors.get("accel", cal.accel),
        mag=sensors.get("mag", cal.mag),
    )
    found = PoseFindings(
        n_total=n_total,
        rejected=[(r.index, r.sensor) for r in rejected],
        unflagged_left=left,
        condition=unc.condition,
        excess=excess,
    )
    return result, found
