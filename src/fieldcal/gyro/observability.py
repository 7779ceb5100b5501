"""Which combinations of the gyroscope's gain the turns determine: the gain's information with
the biases eliminated, its null space in ``K``'s entries, and the one-line message naming what
to record."""

from __future__ import annotations

import math

import numpy as np

from .model import Array
from .result import GAIN_NAMES

#: A combination of the gain's entries whose standard error exceeds this fraction of the gain's
#: size (``|K|_F/√3``) is not determined by the turns (refused, or left out with
#: ``allow_partial``): a 10 % uncertain gyroscope gain is no calibration.
NULL_STD = 0.1


#: A gain entry whose weight in a unit null vector exceeds this is not determined.
NULL_LOADING = 0.1


def null_space(information: Array, K: Array) -> tuple[Array, tuple[str, ...]]:
    """The gain's undetermined combinations at ``K``: an orthonormal basis (9, r) of the
    directions of ``M = K⁻¹`` the fit may move along (those orthogonal to the undetermined ones)
    and the names of the ``K`` entries the undetermined combinations touch.

    ``information`` is the gain's information matrix in ``M``'s entries (biases eliminated);
    mapped to ``K``'s entries (``dK = −K dM K``), a combination is undetermined when its
    standard error exceeds :data:`NULL_STD` of the gain's size."""
    T = -np.kron(K, K.T)  # dK = −K dM K, row-major
    Tinv = np.linalg.inv(T)
    IK = Tinv.T @ information @ Tinv
    w, V = np.linalg.eigh(0.5 * (IK + IK.T))
    size = float(np.linalg.norm(K)) / math.sqrt(3.0)
    null = w * (NULL_STD * size) ** 2 < 1.0
    if not np.any(null):
        return np.eye(9), ()
    touched = np.max(np.abs(V[:, null]), axis=1) > NULL_LOADING
    names = tuple(n for n, hit in zip(GAIN_NAMES, touched, strict=True) if hit)
    in_M, _ = np.linalg.qr(Tinv @ V[:, null])
    return complement(in_M), names


def reset_null(M: Array, basis: Array, M0: Array) -> Array:
    """``M`` with its undetermined part (orthogonal to ``basis``) put back at the start's: those
    directions change no prediction (to first order), so the gain keeps the start's values
    there (``K``'s entries along the null directions, least squares)."""
    K = np.linalg.inv(M)
    null = -np.kron(K, K.T) @ complement(basis)
    a = np.linalg.lstsq(null, (np.linalg.inv(M0) - K).ravel(), rcond=None)[0]
    out: Array = np.linalg.inv(K + (null @ a).reshape(3, 3))
    return out


def complement(basis: Array) -> Array:
    """An orthonormal basis (9, 9 − r) of the complement of an orthonormal basis (9, r)."""
    U, _, _ = np.linalg.svd(basis, full_matrices=True)
    out: Array = U[:, basis.shape[1] :]
    return out


def unobservable_message(names: tuple[str, ...], method: str) -> str:
    """One line naming the gain entries the turns leave free and what to record."""
    rows = sorted({int(n[-4]) for n in names})  # gyro.gain[j,k]: j the raw axis, k the body's
    columns = sorted({int(n[-2]) for n in names})
    turn = ", ".join("xyz"[a] for a in columns)
    if len(names) == 9:
        why = (
            "no turn tilts the device (gravity sees only tilts)"
            if method == "gravity"
            else "the turns do not span the body axes"
        )
    elif len(columns) < 3:
        why = "no turn is about body axis " + " or ".join("xyz"[a] for a in columns)
    elif len(rows) == 1:
        why = f"the turns kept hardly move the gyroscope's raw axis {'xyz'[rows[0]]}"
        turn = "x, y and z"
    else:
        why = "the turns do not span the body axes"
    return (
        f"the turns between the poses do not determine {', '.join(names)} ({why}): add turns "
        f"about body axis {turn} (library: allow_partial=True fits the rest)"
    )
