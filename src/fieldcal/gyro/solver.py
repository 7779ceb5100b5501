"""The gyroscope's solver: Levenberg-Marquardt on the whitened segments, the continuation from
the segments that turn least to all of them, and the segments left out as not fitting."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtrc, chdtri

from ..likelihood.marquardt import Schedule, minimise
from .data import build_segments
from .integrate import Hold
from .model import Array, SegmentModel
from .noise import PoseErrors, SegmentNoise, prior_cost, robust_scale, segment_statistics
from .normal import NormalSystem

#: Fewest motion segments: 3 turns (9 residuals) about independent axes for the 9 gain entries.
MIN_SEGMENTS = 3


#: Family-wise false-alarm rate of the segment tests (Bonferroni over the segments).
REJECT_ALPHA = 0.01


#: The same before a stage is fitted, against the bulk of the segments at the current gain:
#: only gross misfits (a jump in the log) are left out before the fit.
PRESCREEN_ALPHA = 1e-4


class _Segments:
    """The segments' problem for the shared loop (:func:`fieldcal.likelihood.marquardt.
    minimise`): a point is the parameter vector; its linearisation the normal system with its
    gradient and diagonal."""

    def __init__(
        self,
        model: SegmentModel,
        noise: SegmentNoise,
        prior_inv: Array,
        p: Array,
        basis: Array | None,
    ) -> None:
        self.model, self.noise, self.prior_inv, self.p, self.basis = (
            model,
            noise,
            prior_inv,
            p,
            basis,
        )

    def linearise(self, x: Array) -> tuple[Array, NormalSystem, Array, Array]:
        ne = NormalSystem(self.noise, self.model.evaluate(x), x, self.p, self.prior_inv, self.basis)
        return x, ne, ne.gradient(), ne.diagonal()

    def propose(
        self, linear: tuple[Array, NormalSystem, Array, Array], lam: float
    ) -> tuple[Array, float]:
        x, ne, g, diag = linear
        step = ne.step(lam * np.maximum(diag, 1e-12))
        basis = self.basis
        full = (
            step
            if basis is None
            else np.concatenate([basis @ step[: basis.shape[1]], step[basis.shape[1] :]])
        )
        return x + full, float(-(step @ g))

    def level(self, linear: tuple[Array, NormalSystem, Array, Array]) -> float | None:
        return None

    def cost(self, y: Array) -> float:
        try:
            c = self.noise.quadratic(self.model.residuals(y)) + prior_cost(
                self.prior_inv, y[9:].reshape(-1, 3), self.p
            )
        except (FloatingPointError, np.linalg.LinAlgError):
            return math.inf
        return c if math.isfinite(c) else math.inf


class _Tenfold(Schedule):
    """The gyroscope's rules: an iteration is a linearisation, its refused trials raise λ
    tenfold (beyond 1e12 no descent is left: the minimum, to round-off); a step is taken when it
    lowers J, λ shrinks threefold after a good one (ρ > 0.75), and the loop stops when J moved
    by less than 1e-6 relative — J is a χ² variate of size ~dof, so that means nothing
    statistically."""

    count_trials = False

    def __init__(self) -> None:
        super().__init__(1e-3)

    def ratio(self, gain: float, predicted: float) -> float:
        return gain / max(predicted, 1e-300)

    def accepts(self, gain: float, rho: float, new: float, cost: float) -> bool:
        return new < cost

    def accepted(self, gain: float, rho: float, cost: float) -> bool:
        self.lam = max(self.lam * (1.0 / 3.0 if rho > 0.75 else 1.0), 1e-12)
        return gain <= 1e-6 * (1.0 + cost)

    def refused(self, predicted: float, cost: float) -> bool | None:
        self.lam *= 10.0
        return True if self.lam > 1e12 else None


def gauss_newton(
    model: SegmentModel,
    noise: SegmentNoise,
    prior_inv: Array,
    x: Array,
    p: Array,
    basis: Array | None,
    max_iter: int,
) -> tuple[Array, float, int, bool]:
    """Levenberg-Marquardt on the whitened residuals (the segments' covariance ``noise`` fixed,
    the biases' priors ``prior_inv``); ``basis`` (9, r) restricts the gain's step to the
    determined directions (``None``: all). The shared loop with the rules of :class:`_Tenfold`."""
    problem = _Segments(model, noise, prior_inv, p, basis)
    out = minimise(problem, x, problem.cost(x), _Tenfold(), max_iter)
    return out.point, out.cost, out.iterations, out.converged


def stages(path: Array) -> list[NDArray[np.int64]]:
    """Growing sets of segments, by the angle each turns through: those under half a turn
    (at least the four shortest), then each doubling of the limit, the last set all of them."""
    order = np.argsort(path)
    out: list[NDArray[np.int64]] = []
    limit = np.pi
    while True:
        count = max(int(np.count_nonzero(path <= limit)), min(4, len(path)))
        chosen = np.sort(order[:count])
        if not out or len(chosen) > len(out[-1]):
            out.append(chosen)
        if count == len(path):
            return out
        limit *= 2.0


class Rounds:
    """The fit over growing sets of segments, with the rejected ones remembered: the motion
    (``t``, ``raw``, pose ``rows``, the ``link`` segments) and what every round shares."""

    def __init__(
        self,
        full: SegmentModel,
        motion: tuple[Array, Array, NDArray[np.int64], NDArray[np.int64], Array, Hold],
        pose: PoseErrors,
        prior_cov: Array,
        means: Array,
        max_iter: int,
        on_progress: Callable[[str], None] | None = None,
    ) -> None:
        self.on_progress = on_progress
        self.prior_inv: Array = np.asarray(np.linalg.inv(prior_cov), dtype=float)
        self.full = full
        self.motion = motion
        self.pose = pose
        self.prior_cov = prior_cov
        self.means = means
        self.max_iter = max_iter
        self.m = len(full.data.first)
        self.restrict: Array | None = None
        self.iterations = 0
        self.converged = False
        self.dropped: list[int] = []  # segments (positions in link) refused as not fitting
        self.models: dict[tuple[int, ...], SegmentModel] = {}

    def model_of(self, chosen: Sequence[int]) -> SegmentModel:
        """The model of the ``chosen`` segments (positions in ``link``), cached."""
        key = tuple(int(k) for k in chosen)
        if len(key) == self.m:
            return self.full
        if key not in self.models:
            t, raw, rows, link, times, hold = self.motion
            picked = build_segments(t, raw, rows, link[list(key)], times, hold)
            full = self.full
            # most of the segments: the full model's passes serve (one pass where two were)
            share = (full, np.array(key, dtype=np.int64)) if 2 * len(key) >= self.m else None
            self.models[key] = SegmentModel(
                picked, full.method, full.n, full.observed_poses, full.Q, share=share
            )
        return self.models[key]

    def used(self) -> list[int]:
        """The segments kept so far (positions in ``link``)."""
        out = set(self.dropped)  # (a set: linear in the segments however many are dropped)
        return [k for k in range(self.m) if k not in out]

    def run(self, x: Array, scale2: float) -> tuple[Array, float]:
        """Continuation: the segments that turn least first (a gain error of ε puts a segment's
        integral off by ε times the angle it turns through, and a residual past half a turn
        wraps), then ever longer ones, until every segment is in."""
        path = self.full.path_length(x)
        for stage in stages(path):
            if self.on_progress is not None:
                self.on_progress(f"gyroscope: segment {len(stage)}/{self.m}")
            out = set(self.dropped)
            chosen = [int(k) for k in stage if int(k) not in out]
            x, scale2 = self.fit_set(chosen, x, scale2, len(stage) == self.m)
        return x, scale2

    def _prescreen(self, chosen: list[int], x: Array, scale2: float) -> list[int]:
        """Before fitting, refuse the segments that stand out from the rest at the current gain
        (a jump in the log: a turn the gyroscope never saw); their size against the bulk's, so a
        rough start does not condemn good segments."""
        d = self.full.d
        model = self.model_of(chosen)
        ev = model.evaluate(x)  # with the Jacobian: the fit starts from the same point
        stat = segment_statistics(ev, self.pose.segment_covariance(model, ev, scale2), d)
        bulk = max(float(np.median(stat)) / float(chdtri(d, 0.5)), 1.0)
        p_seg = chdtrc(d, stat / bulk)
        for k in np.argsort(p_seg):
            # only the gross ones: the fit's own tests below catch the rest
            if p_seg[k] >= PRESCREEN_ALPHA / len(chosen) or len(self.dropped) + 1 > self.m // 2:
                break
            if len(chosen) - 1 < MIN_SEGMENTS:
                break
            self.dropped.append(chosen[k])
        out = set(self.dropped)
        return [k for k in chosen if k not in out]

    def fit_set(
        self, chosen: list[int], x: Array, scale2: float, last: bool
    ) -> tuple[Array, float]:
        """Fit the chosen segments; drop the worst one that fails its test and refit, until
        none fails (at most half of all segments dropped, at least 3 kept)."""
        d = self.full.d
        chosen = self._prescreen(chosen, x, scale2)
        free = self.pose.estimated
        while True:
            model = self.model_of(chosen)
            ev = model.evaluate(x)
            cov_of = functools.partial(self.pose.segment_covariance, model)
            if free:
                scale2 = robust_scale(ev, cov_of, d)
            for _ in range(4 if last else 1):
                noise = cov_of(ev, scale2)
                x, _, it, self.converged = gauss_newton(
                    model, noise, self.prior_inv, x, self.means, self.restrict, self.max_iter
                )
                self.iterations += it
                ev = model.evaluate(x)
                if free:
                    new = robust_scale(ev, cov_of, d)
                    done = abs(new - scale2) <= 1e-3 * max(scale2, 1e-300)
                    scale2 = new
                    if done:
                        break
                elif self.converged:
                    break
            stat = segment_statistics(ev, cov_of(ev, scale2), d)
            p_seg = chdtrc(d, stat)
            worst = int(np.argmin(p_seg))
            if p_seg[worst] >= REJECT_ALPHA / len(chosen):
                return x, scale2
            if len(self.dropped) + 1 > self.m // 2 or len(chosen) - 1 < MIN_SEGMENTS:
                return x, scale2
            self.dropped.append(chosen.pop(worst))
