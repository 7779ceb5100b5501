"""The segments' residual covariance, kept in its structure so that every use is linear in the
number of poses: the poses' orientation errors seen through each segment (each segment touches
its two poses only) plus the integrated white noise of the rate; the whitened normal equations
of one Gauss-Newton round, each segment's own χ², and the orientation variance estimated when
the poses' covariance is not given.

``Σ = B (blockdiag(P_i) + F Fᵀ) Bᵀ + blockdiag(D_k)``: ``B`` the segments' response to the
poses' errors, ``P_i`` each pose's own covariance, ``F`` (N, 3, G) the part the poses share
(:class:`~fieldcal.likelihood.cramer_rao.PoseCovariance`), ``D_k = H_k C_int H_kᵀ`` the
integration noise. The poses' errors are carried as latent unknowns ``δ_i = S_i ξ_i + F_i ζ``
(``S_i S_iᵀ = P_i``, ``ξ``, ``ζ`` standard normal): minimising over them gives exactly
``rᵀ Σ⁻¹ r``, and the normal equations in (biases, ξ; gain, ζ) are block tridiagonal over the
poses with a border of ``9 + G`` unknowns (:class:`.banded.Arrow`)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import chdtri

from ..errors import InputError
from ..likelihood.cramer_rao import PoseCovariance
from .banded import Arrow
from .model import Array, Evaluation, SegmentModel


@dataclass
class PoseErrors:
    """The poses' part of the segments' covariance: ``blockdiag(blocks) + F Fᵀ``, or, when
    ``estimated``, ``s²`` times ``blockdiag(blocks)`` (the shape; ``s²`` fitted)."""

    blocks: Array  # (N, 3, 3)
    factor: Array  # (N, 3, G)
    estimated: bool

    def segment_covariance(
        self, model: SegmentModel, ev: Evaluation, scale2: float
    ) -> SegmentNoise:
        """The segments' covariance at ``ev`` (``scale2``: ``s²`` when estimated)."""
        return SegmentNoise(model, ev, self, scale2)


def pose_covariance(value: ArrayLike | PoseCovariance, n: int, name: str) -> PoseCovariance:
    """A given covariance of the poses, checked, in its structure: a
    :class:`~fieldcal.likelihood.cramer_rao.PoseCovariance` as it is, ``(N, 3, 3)`` as blocks,
    a dense ``(3N, 3N)`` matrix factored (its cost cubic in N: pass the structure instead)."""
    if isinstance(value, PoseCovariance):
        if value.blocks.shape != (n, 3, 3) or value.factor.shape[:2] != (n, 3):
            raise InputError(f"{name} must describe {n} poses; got {value.n}")
        if not (np.all(np.isfinite(value.blocks)) and np.all(np.isfinite(value.factor))):
            raise InputError(f"{name} has a NaN or inf value")
        return value
    C = np.asarray(value, dtype=float)
    if C.shape == (n, 3, 3) and np.all(np.isfinite(C)):
        return PoseCovariance(0.5 * (C + np.transpose(C, (0, 2, 1))), np.zeros((n, 3, 0)))
    if C.shape != (3 * n, 3 * n) or not np.all(np.isfinite(C)):
        raise InputError(f"{name} must have shape ({n}, 3, 3) or ({3 * n}, {3 * n})")
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    keep = w > 0
    factor = (V[:, keep] * np.sqrt(w[keep])).reshape(n, 3, -1)
    return PoseCovariance(np.zeros((n, 3, 3)), factor)


def _root(P: Array) -> Array:
    """``S`` (N, 3, 3) with ``S Sᵀ = P`` for symmetric positive semi-definite blocks."""
    w, V = np.linalg.eigh(P)
    out: Array = V * np.sqrt(np.clip(w, 0.0, None))[:, None, :]
    return out


class SegmentNoise:
    """The segments' covariance ``Σ`` at one evaluation, fixed during one round of
    Gauss-Newton: whitened by each segment's integration noise, the poses' errors as latent
    unknowns (:mod:`module docstring <.gyro_noise>`)."""

    def __init__(
        self, model: SegmentModel, ev: Evaluation, pose: PoseErrors, scale2: float
    ) -> None:
        self.model = model
        n, d = model.n, model.d
        # (M,) the pose before each segment, the one after is a + 1: distinct poses (one
        # segment from each), so sums per pose are plain indexed additions
        self.a = model.data.before
        Ba, Bb = model.pose_blocks(ev)
        P = scale2 * pose.blocks if pose.estimated else pose.blocks
        F = np.zeros((n, 3, 0)) if pose.estimated else pose.factor
        a = self.a
        Gk = Ba @ F[a] + Bb @ F[a + 1]  # (M, d, G)
        D = ev.H @ ev.cov_int @ np.transpose(ev.H, (0, 2, 1))
        blocks = (
            Ba @ P[a] @ Ba.transpose(0, 2, 1)
            + Bb @ P[a + 1] @ Bb.transpose(0, 2, 1)
            + Gk @ Gk.transpose(0, 2, 1)
            + D
        )
        # the smallest part any residual may carry: round-off, not information
        jitter = 1e-12 * float(np.max(np.einsum("mii->mi", blocks)))
        self.blocks = blocks + jitter * np.eye(d)  # Σ_kk, each segment's own
        self.W = np.linalg.inv(np.linalg.cholesky(D + jitter * np.eye(d)))  # D_k^(−1/2)
        S = _root(P)
        self.Ua = -self.W @ Ba @ S[a]  # (M, d, 3) whitened response to ξ of the pose before
        self.Ub = -self.W @ Bb @ S[a + 1]
        self.Uz = -self.W @ Gk  # (M, d, G)
        self.n_shared = F.shape[2]

    @functools.cached_property
    def latent(self) -> Arrow:
        """The latent unknowns' normal matrix ``Uᵀ U + I`` (ξ per pose, ζ the border)."""
        n, g, a = self.model.n, self.n_shared, self.a
        Ua, Ub, Uz = self.Ua, self.Ub, self.Uz
        diag = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        diag[a] += _tt(Ua, Ua)
        diag[a + 1] += _tt(Ub, Ub)
        lower = np.zeros((max(n - 1, 0), 3, 3))
        lower[a] += _tt(Ub, Ua)
        border = np.zeros((n, 3, g))
        border[a] += _tt(Ua, Uz)
        border[a + 1] += _tt(Ub, Uz)
        return Arrow(diag, lower, border, np.eye(g) + np.einsum("mdg,mdh->gh", Uz, Uz))

    def _latent_rhs(self, R: Array) -> tuple[Array, Array]:
        """``Uᵀ R`` for whitened segment rows ``R`` (M, d, c): per pose (N, 3, c) and shared."""
        n, a = self.model.n, self.a
        local = np.zeros((n, 3, R.shape[2]))
        local[a] += _tt(self.Ua, R)
        local[a + 1] += _tt(self.Ub, R)
        return local, np.einsum("mdg,mdc->gc", self.Uz, R)

    def _latent_apply(self, local: Array, shared: Array) -> Array:
        """``U [ξ; ζ]`` (M, d, c) for latent values per pose (N, 3, c) and shared (G, c)."""
        a = self.a
        out: Array = self.Ua @ local[a] + self.Ub @ local[a + 1] + self.Uz @ shared
        return out

    def project(self, R: Array) -> Array:
        """``R − U (UᵀU + I)⁻¹ Uᵀ R`` for whitened rows ``R`` (M, d, c): with ``R = D^(−1/2) X``
        its inner product with whitened rows ``Y`` is ``Yᵀ Σ⁻¹ X``."""
        local, shared = self.latent.solve(*self._latent_rhs(R))
        return R - self._latent_apply(local, shared)

    def quadratic(self, r: Array) -> float:
        """``rᵀ Σ⁻¹ r`` for residuals ``r`` (M, d)."""
        w = self.W @ r[:, :, None]
        return float(np.sum(w * self.project(w)))


def _tt(X: Array, Y: Array) -> Array:
    """``X_kᵀ Y_k`` for stacks of matrices."""
    out: Array = np.transpose(X, (0, 2, 1)) @ Y
    return out


def segment_statistics(ev: Evaluation, cov: SegmentNoise, d: int) -> Array:
    """Each segment's ``rᵀ Σ_kk⁻¹ r`` with its own block of the joint covariance: χ²(d) for a
    segment that fits (a little less, as the fit absorbs part of every residual)."""
    solved = np.linalg.solve(cov.blocks, ev.r[:, :, None])[:, :, 0]
    out: Array = np.einsum("mi,mi->m", ev.r, solved)
    return out


def robust_scale(ev: Evaluation, cov: Callable[[Evaluation, float], SegmentNoise], d: int) -> float:
    """The orientation variance ``s²`` at which the median segment statistic is χ²(d)'s
    median: a few segments that do not fit cannot inflate it."""
    target = float(chdtri(d, 0.5))

    def median_stat(s2: float) -> float:
        return float(np.median(segment_statistics(ev, cov(ev, s2), d)))

    return falls_to(median_stat, target, initial_scale(ev), 50)


def initial_scale(ev: Evaluation) -> float:
    """A first orientation variance: the residuals' mean square per component."""
    return max(float(np.mean(ev.r * ev.r)), 1e-12)


def match_chi2(
    ev: Evaluation, cov: Callable[[Evaluation, float], SegmentNoise], dof: int, scale2: float
) -> float:
    """The orientation variance ``s²`` at which the segments' χ² equals its degrees of freedom
    (0 when the integration noise alone already explains the residuals)."""

    def chi2(s2: float) -> float:
        return cov(ev, s2).quadratic(ev.r)

    return falls_to(chi2, dof, scale2, 60)


def falls_to(f: Callable[[float], float], target: float, start: float, steps: int) -> float:
    """The variance ``s ≥ 0`` at which the decreasing ``f(s)`` falls to ``target`` (0 when
    ``f(0)`` already does): bracketed by quadrupling from ``start`` (given up above 10⁶),
    then ``steps`` bisections."""
    if f(0.0) <= target:
        return 0.0
    lo, hi = 0.0, max(start, 1e-12)
    while f(hi) > target:
        hi *= 4.0
        if hi > 1e6:
            return hi
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if f(mid) > target:
            lo = mid
        else:
            hi = mid
    return hi


def prior_cost(prior_inv: Array, b: Array, p: Array) -> float:
    """The biases' priors: ``Σ (b_i − p_i)ᵀ C_i⁻¹ (b_i − p_i)``."""
    e = b - p
    return float(np.einsum("ni,nij,nj->", e, prior_inv, e))
