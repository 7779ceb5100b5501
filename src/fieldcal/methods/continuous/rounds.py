"""The continuous fit's rounds: Levenberg–Marquardt on the knots, the noise levels between.

:func:`run_rounds` runs the rounds of ``docs/methods/continuous.md`` (Algorithm, step 3): the
first on sparser knots (it walks from the start), each later one on the chosen knots reduced
again at the gyroscope found so far (:func:`.knots.reduce`), the noise levels re-estimated
after each (Eq. C6: :func:`weights_at`, :func:`gyro_variance`), then a settling fit;
:class:`Progress` turns its iterations into progress lines (fractions, time left).
"""

from __future__ import annotations

import dataclasses
import time as time_module
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .covariates import Inputs
from .knots import reduce, sample_rotations
from .model import Data, State, residuals
from .motion_noise import field_direction_variance, once_per_stretch, sample_excess
from .solver import Prior, Weights, levenberg_marquardt, state_factors
from .uncertainty import BATCH, kept_shares
from .weights import STRETCH, gyro_rate_variance, stretch_variance

__all__ = [
    "COARSE",
    "Options",
    "Plan",
    "Progress",
    "gyro_variance",
    "plain_weights",
    "run_rounds",
    "weights_at",
]

Array = NDArray[np.float64]

#: The first round's gyroscope noise, as a share of its RMS rate (unless ``gyro_noise`` is
#: given): weak, so that the field sensors lead until the factors' noise is measured.
WEAK_GYRO = 0.02
#: Factor (standard deviation) by which the gyroscope's factors must misfit beyond the raw
#: rates' white noise before the fit's own measure of their noise replaces it (Eq. C6).
GYRO_MISFIT = 20.0
#: The first round's knots are this many times sparser (:func:`run_rounds`), when there are at
#: least :data:`MIN_COARSE_KNOTS` of them.
COARSE = 4
MIN_COARSE_KNOTS = 200
#: Seconds between progress lines within a round.
PROGRESS_SECONDS = 0.5


def weights_at(
    state: State,
    knots: Data,
    length: int,
    rate_var: float,
    kept: Array,
    allow: bool = False,
    samples: tuple[Data, int] | None = None,
) -> tuple[Weights, dict[str, Array]]:
    """Inverse variances (Eq. C6): each field sensor's per stretch from its residuals at the
    knots, divided by the share of its errors the fit keeps (``kept``,
    :func:`.uncertainty.kept_shares`); the gyroscope's factor between knots from ``rate_var``
    (rad²/s² per axis) times its intervals' ``Σ Δt²``; with ``allow``, the allowances for
    what the model leaves out (Eq. C6a–C6b, :mod:`.motion_noise`); ``samples`` (the samples
    and the knots' step) lets C6a read the excess from the samples' residuals."""
    ra, rm = residuals(state, knots)
    va, per_a = stretch_variance(ra / np.sqrt(kept[0]), length, 0.0)
    vm, per_m = stretch_variance(rm / np.sqrt(kept[1]), length, 0.0)
    floor_a = max(1e-4 * float(np.median(per_a)), 1e-300)
    floor_m = max(1e-4 * float(np.median(per_m)), 1e-300)
    va, per_a = np.maximum(va, floor_a), np.maximum(per_a, floor_a)
    vm, per_m = np.maximum(vm, floor_m), np.maximum(per_m, floor_m)
    if allow and samples is not None:  # C6a's excess as the samples show it, once per stretch
        excess = _sample_excess(state, *samples, length, float(kept[0]))
        va = va + length * np.repeat(excess, length)[: len(va)]
    elif allow:  # what the model leaves out, counted as it is
        va = once_per_stretch(va, length)
    if allow:
        vm = vm + field_direction_variance(knots.mag, state.mag_bias)
    assert knots.factors is not None
    w = Weights(1.0 / va, 1.0 / vm, 1.0 / (rate_var * knots.factors.dt2))
    return w, {"accel": per_a, "mag": per_m, "gyro": np.array([rate_var])}


def _sample_excess(state: State, data: Data, step: int, length: int, kept: float) -> Array:
    """Per stretch of ``length`` knots, the accelerometer's excess over its white noise in the
    samples' residuals (:func:`.motion_noise.sample_excess`), each sample at its rotation from
    the knots' and the gyroscope (:func:`.knots.sample_rotations`)."""
    rotations = sample_rotations(data, state, step)
    ra, _ = residuals(dataclasses.replace(state, rotations=rotations), data)
    return sample_excess(np.sum(ra**2, axis=1) / (3.0 * kept), length * step)


def plain_weights(state: State, knots: Data, w: Weights, length: int, rate_var: float) -> Weights:
    """:func:`weights_at` without the allowances (C6a–C6b), ``w``'s prior kept: the temperature
    terms are chosen on the noise's own weights, as C6a would count a drift not yet modelled
    as body acceleration and hide it."""
    plain, _ = weights_at(state, knots, length, rate_var, kept_shares(state, knots, w))
    plain.prior = w.prior
    return plain


def gyro_variance(state: State, knots: Data, white: float, kept: float) -> float:
    """The gyroscope's rate variance for the next round (Eq. C6): the raw rates' white noise
    ``white`` (:func:`.weights.gyro_rate_variance` of the samples), unless its factors misfit
    by more than :data:`GYRO_MISFIT` times that in standard deviation — their mean square
    over the share the fit keeps (:func:`.uncertainty.kept_shares`), each over its ``Σ Δt²``,
    is then the variance. A log without time stamps, sampled by a loop that sleeps (the
    ICM-20948 sessions: 62 times), turns by more or less than its rate times the nominal
    interval, and only the fit sees it. Below the threshold the white noise stands: the
    moment estimate also takes in the field sensors' correlated errors, which the trajectory
    passes on to the gyroscope's residuals (BROAD: 6 times), and trusting the gyroscope less
    for them made the trajectory and the gains worse against the motion capture."""
    f = state_factors(state, knots)
    # per factor, the rate error it implies (rad/s)²; f.dt is √ΣΔt²
    mean_square = float(np.mean(np.sum(f.residual**2, axis=1) / f.dt**2) / 3.0)
    misfit = mean_square / kept
    return misfit if misfit > GYRO_MISFIT**2 * white else white


@dataclass
class Options:
    """The options of ``fit_continuous`` (checked there before the fit)."""

    max_iter: int
    rounds: int
    tol: float
    gravity: float | None
    hold: str | Sequence[str] | None
    gyro_noise: float | None
    gyro_sampling: str
    prior: object
    #: The interference term's inputs and the autopilot's attitude (:mod:`.covariates`,
    #: :mod:`.autopilot_aid`).
    inputs: Mapping[str, ArrayLike] | None = None
    attitude: ArrayLike | None = None
    #: The weights' allowances for what the model leaves out (Eq. C6a–C6b).
    allowances: bool = False


@dataclass
class Plan:
    """What the fit works on: the samples, the knots' spacing (:func:`.knots.knot_step`) and the
    stretches and batches in knots, the options and the progress line."""

    data: Data
    step: int
    rule: str
    rate: float
    options: Options
    progress: Progress | None
    #: The interference term's inputs as checked (:func:`.covariates.interference_inputs`).
    drive: Inputs | None = None

    @property
    def knot_rate(self) -> float:
        return self.rate / self.step

    @property
    def length(self) -> int:
        """Knots per stretch of the field sensors' variances (:data:`.weights.STRETCH`)."""
        return max(1, round(STRETCH * self.knot_rate))

    @property
    def batch(self) -> int:
        """Knots per batch of the long-run covariance (:data:`.uncertainty.BATCH`)."""
        return max(2, round(BATCH * self.knot_rate))

    def fit(self, state: State, knots: Data, w: Weights) -> tuple[State, int, bool]:
        """Levenberg–Marquardt on the knots, the progress line told each iteration."""
        hear = None if self.progress is None else self.progress.iteration
        o = self.options
        return levenberg_marquardt(
            state, knots, w, max_iter=int(o.max_iter), tol=float(o.tol), on_iteration=hear
        )


def run_rounds(
    state: State, plan: Plan, prior: Prior
) -> tuple[State, Data, Weights, dict[str, Array], int, bool]:
    """Levenberg–Marquardt from ``state`` (rotations at the knots), the knots reduced again at
    each round's gyroscope (:func:`.knots.reduce`) and the noise levels re-estimated after
    each round (Eq. C6), then a last reduction at the optimum and a settling fit: the state,
    the knots, the last weights and levels, the iterations and convergence. The first round
    starts far from the optimum and takes most of the iterations: on a long log it runs on
    knots :data:`COARSE` times sparser, the later rounds on the chosen ones."""
    data, gyro_noise = plan.data, plan.options.gyro_noise
    white = gyro_rate_variance(data.gyro, state.gyro_gain)
    if gyro_noise is None:
        # the first round trusts the gyroscope little (WEAK_GYRO of its rates): a log whose
        # factors are noisier than the raw rates' white noise says must not drag the
        # trajectory away from the field sensors before its noise is measured
        rate_var = max(white, float(np.mean(data.gyro**2)) * WEAK_GYRO**2)
    else:
        rate_var = float(gyro_noise) ** 2
    # the first round, which walks from the start, on knots COARSE times sparser
    factor = COARSE if len(state.rotations) >= COARSE * MIN_COARSE_KNOTS else 1
    state = dataclasses.replace(state, rotations=state.rotations[::factor])
    knots = reduce(data, state, plan.step * factor)
    length = max(1, round(plan.length / factor))
    allow = plan.options.allowances
    w, levels = weights_at(
        state, knots, length, rate_var, np.ones(3), allow, (data, plan.step * factor)
    )
    w.prior = prior
    total, rounds = 0, max(1, int(plan.options.rounds))
    kept = np.ones(3)
    for r in range(rounds + 1):
        if r and factor > 1:  # from the coarse optimum to the chosen knots
            rotations = sample_rotations(data, state, plan.step * factor)[:: plan.step]
            state, factor, length = dataclasses.replace(state, rotations=rotations), 1, plan.length
        if r:  # the pre-integration and the windows' turns at the gyroscope found so far
            knots = reduce(data, state, plan.step)
            w, levels = weights_at(state, knots, length, rate_var, kept, allow, (data, plan.step))
            w.prior = prior
        if plan.progress is not None:
            plan.progress.round(r, rounds)
        state, iterations, converged = plan.fit(state, knots, w)
        total += iterations
        if r == rounds:  # the settling fit: the weights stand
            break
        kept = kept_shares(state, knots, w)
        if gyro_noise is None:
            white = gyro_rate_variance(data.gyro, state.gyro_gain)
            rate_var = gyro_variance(state, knots, white, float(kept[2]))
    return state, knots, w, levels, total, converged


class Progress:
    """The fit's progress as lines for ``on_progress``: the round, the iteration (a fraction of
    the most allowed) and, once a round has finished, an estimate of the time left."""

    def __init__(self, hear: Callable[[str], None], knots: int, max_iter: int) -> None:
        self.hear, self.knots, self.max_iter = hear, knots, max_iter
        self.start = self.last = time_module.monotonic()
        self.at, self.of, self.done, self.finished_rounds = 0, 1, 0, 0

    def round(self, r: int, rounds: int) -> None:
        if r:
            self.finished_rounds += 1
        self.at, self.of = r, rounds + 1

    def iteration(self, i: int) -> None:
        now = time_module.monotonic()
        if i:
            self.done += 1
        if i and now - self.last < PROGRESS_SECONDS:
            return
        self.last = now
        left = ""
        if self.finished_rounds and self.done:
            per = (now - self.start) / self.done
            # the later rounds start near the optimum: as many iterations as the mean so far
            mean = self.done / (self.finished_rounds + 1)
            rest = max(mean - i, 1.0) + mean * (self.of - self.at - 1)
            left = f", about {per * rest:.0f} s left"
        self.hear(
            f"continuous fit ({self.knots} knots): round {self.at + 1}/{self.of}, "
            f"iteration {i + 1}/{self.max_iter}{left}"
        )

    def say(self, text: str) -> None:
        self.hear(f"continuous fit ({self.knots} knots): {text}")
