"""The oracle of the accuracy and speed benchmarks: ``scipy.optimize.least_squares`` on Eq. 8,
started at the true parameters (the best any method can do on that data).

Independent of fieldcal's solver: its own residual function, scipy's finite-difference
Jacobian, rotation vectors relative to the true rotations. Same gauge as fieldcal (symmetric
accelerometer gain, g along −z, h in the x-z plane), same pose statistics (Eq. 5, 7).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

SYM = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _sym(p):
    K = np.empty((3, 3))
    for v, (j, k) in zip(p, SYM, strict=True):
        K[j, k] = K[k, j] = v
    return K


def sparsity(n):
    """Jacobian sparsity of the residuals below: pose i touches its 3 angles and its sensor."""
    from scipy.sparse import lil_matrix

    S = lil_matrix((6 * n, 22 + 3 * n), dtype=int)
    for i in range(n):
        S[3 * i : 3 * i + 3, 0:9] = 1
        S[3 * n + 3 * i : 3 * n + 3 * i + 3, 9:22] = 1
        S[3 * i : 3 * i + 3, 22 + 3 * i : 25 + 3 * i] = 1
        S[3 * n + 3 * i : 3 * n + 3 * i + 3, 22 + 3 * i : 25 + 3 * i] = 1
    return S


def oracle(stats, truth, *, sparse=False):
    """Return (predicted accel means, predicted mag means, least_squares result).

    ``sparse=True`` gives scipy the Jacobian's sparsity (grouped finite differences and the
    LSMR trust-region solver), which it needs to be usable for thousands of poses.
    """
    a, m = stats.accel, stats.mag
    La = np.linalg.inv(np.linalg.cholesky(a.cov))
    Lm = np.linalg.inv(np.linalg.cholesky(m.cov))
    wa, wm = np.sqrt(a.counts)[:, None], np.sqrt(m.counts)[:, None]
    R0 = np.array(truth.rotations)
    n = len(R0)

    def unpack(x):
        Ka = _sym(x[0:6])
        ba = x[6:9]
        Km = x[9:18].reshape(3, 3)
        bm = x[18:21]
        dip = x[21]
        R = Rotation.from_rotvec(x[22:].reshape(n, 3)).as_matrix() @ R0
        return Ka, ba, Km, bm, dip, R

    def predict(x):
        Ka, ba, Km, bm, dip, R = unpack(x)
        g = np.array([0.0, 0.0, -1.0])
        h = np.array([np.cos(dip), 0.0, np.sin(dip)])
        return (R @ g) @ Ka.T + ba, (R @ h) @ Km.T + bm

    def fun(x):
        pa, pm = predict(x)
        ra = wa * ((pa - a.means) @ La.T)
        rm = wm * ((pm - m.means) @ Lm.T)
        return np.concatenate([ra.ravel(), rm.ravel()])

    Ka = np.array(truth.accel.gain)
    x0 = np.concatenate(
        [
            [Ka[j, k] for j, k in SYM],
            truth.accel.bias,
            np.array(truth.mag.gain).ravel(),
            truth.mag.bias,
            [np.radians(truth.dip_deg)],
            np.zeros(3 * n),
        ]
    )
    extra = {"jac_sparsity": sparsity(n), "tr_solver": "lsmr"} if sparse else {}
    res = least_squares(
        fun, x0, method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12, **extra
    )
    pa, pm = predict(res.x)
    return pa, pm, res
