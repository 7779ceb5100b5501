"""The seed paper's error measure (Eq. 19) and related comparisons with a known truth."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["reconstruction_error"]


def reconstruction_error(
    true_means: ArrayLike, predicted_means: ArrayLike, cov: ArrayLike, counts: ArrayLike
) -> float:
    """δ of Eq. 19: the count-weighted RMS Mahalanobis distance of the reconstructed means.

    ``δ_s = sqrt( Σ_i Δ[i] (μ_s[i] − μ̃_s[i])ᵀ Σ_s⁻¹ (μ_s[i] − μ̃_s[i]) / Σ_i Δ[i] )``

    Parameters
    ----------
    true_means, predicted_means : (N, 3)
        ``μ_s[i]`` (the truth) and ``μ̃_s[i]`` (rebuilt from the estimate).
    cov : (3, 3)
        ``Σ_s``, the true noise covariance of one sample.
    counts : (N,)
        ``Δ[i]``, samples per pose.

    δ is in units of the noise standard deviation of one sample: 0.1 means the model's mean
    reading is off by a tenth of a sample's noise.
    """
    true_means = _numbers(true_means, "true_means")
    predicted_means = _numbers(predicted_means, "predicted_means")
    counts = _numbers(counts, "counts")
    cov = _numbers(cov, "cov")
    if (
        true_means.shape != predicted_means.shape
        or true_means.ndim != 2
        or true_means.shape[-1] != 3
    ):
        raise ValueError(
            f"true_means {true_means.shape} and predicted_means {predicted_means.shape} must both "
            "be (N, 3)"
        )
    if counts.shape != true_means.shape[:1]:
        raise ValueError(f"counts has shape {counts.shape}; expected ({true_means.shape[0]},)")
    if (counts < 0).any() or not counts.sum() > 0:
        raise ValueError("counts must be samples per pose: none negative, at least one positive")
    if cov.shape != (3, 3) or not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0):
        raise ValueError(f"cov must be a symmetric 3x3 covariance, got shape {cov.shape}")
    try:  # Σ = L Lᵀ: the Mahalanobis distance is |L⁻¹ d|², and only a positive-definite Σ has L
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise ValueError("cov must be positive definite (a noise covariance)") from None
    whitened = np.linalg.solve(chol, (true_means - predicted_means).T)
    mahalanobis = np.sum(whitened * whitened, axis=0)
    return float(np.sqrt(np.sum(counts * mahalanobis) / np.sum(counts)))


def _numbers(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """``value`` as a finite float array, or a one-line ``ValueError`` naming ``name``."""
    try:
        raw = np.asarray(value)
        # complex to float would drop the imaginary part with a warning: refused below
        out = None if raw.dtype.kind == "c" else raw.astype(float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of numbers") from None
    if out is None:
        raise ValueError(f"{name} holds complex numbers; give real ones")
    if not np.isfinite(out).all():
        raise ValueError(f"{name} holds NaN or inf; give finite numbers")
    return out
