"""The seed paper's error measure (Eq. 19) and related comparisons with a known truth."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

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
    true_means = np.asarray(true_means, dtype=float)
    predicted_means = np.asarray(predicted_means, dtype=float)
    counts = np.asarray(counts, dtype=float)
    if true_means.shape != predicted_means.shape or true_means.shape[-1] != 3:
        raise ValueError(
            f"true_means {true_means.shape} and predicted_means {predicted_means.shape} must both "
            "be (N, 3)"
        )
    if counts.shape != true_means.shape[:1]:
        raise ValueError(f"counts has shape {counts.shape}; expected ({true_means.shape[0]},)")
    diff = true_means - predicted_means
    mahalanobis = np.einsum("ni,ni->n", diff, np.linalg.solve(np.asarray(cov, float), diff.T).T)
    return float(np.sqrt(np.sum(counts * mahalanobis) / np.sum(counts)))
