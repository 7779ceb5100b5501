"""Ellipsoid fitting on (n, 3) point clouds, reusable by every method.

Pure functions; the seed referred to is the CK-Explorer note
(``../shared/seeds/004_bce6d316cac7a7b6.txt``). A fitted ellipsoid is always returned as a
:class:`Quadric`: the centre ``c`` and the shape ``M`` of ``(x − c)ᵀ M (x − c) = 1`` (Eq. 6),
together with the coefficients ``v0..v9`` of the algebraic form (Eq. 8) and ``κ`` (Eq. 11).

- :func:`algebraic_fit` — the quadric of Eq. 8 with nine free parameters and the trace
  constraint ``v0 + v1 + v2 = −3`` (the parameterisation of Petrov's ``ellipsoid_fit``, which
  the seed uses). ``conditioned=False`` reproduces the seed literally (raw coordinates, normal
  equations); the default centres and scales the points and solves by least squares.
- :func:`li_griffiths_fit` — Li & Griffiths (2004), "Least squares ellipsoid specific fitting":
  the constraint ``4J − I² = 1`` guarantees an ellipsoid, whatever the coverage.
- :func:`reverse_triangular_factor` — Eq. 13: the lower-triangular ``L`` with ``LᵀL = M``.
- :func:`quadric_from_coefficients` — Eq. 9-12: centre, ``κ`` and ``M`` from ``v0..v9``.
- :func:`family_fit` — a weighted algebraic fit within a family (full, axis-aligned, sphere),
  returned as a symmetric gain and centre (the joint method's closed-form starts).
- :func:`pencil_fits` — the pencil of ellipsoids through too few points (8-11 poses).

Every fit takes optional per-point ``weights`` (e.g. sample counts when fitting pose means).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "MIN_POINTS",
    "Quadric",
    "algebraic_fit",
    "ellipsoid_radii",
    "family_design",
    "family_fit",
    "family_fits",
    "li_griffiths_fit",
    "pencil_fits",
    "quadric_from_coefficients",
    "reverse_triangular_factor",
    "spd_sqrt",
]

Array = NDArray[np.float64]

#: Eq. 8 has nine free parameters once the trace constraint fixes the scale.
MIN_POINTS = 9


@dataclass(frozen=True, eq=False)
class Quadric:
    """A fitted quadric ``(x − center)ᵀ shape (x − center) = 1``.

    Attributes
    ----------
    coefficients : (10,) array
        ``v0..v9`` of Eq. 8, scaled so that ``v0 + v1 + v2 = −3`` (the trace constraint).
    center : (3,) array
        ``(x_o, y_o, z_o)``, Eq. 6.
    kappa : float
        ``κ`` of Eq. 11 for these coefficients, so that ``shape = V / κ`` (Eq. 12).
    shape : (3, 3) array
        ``M = LᵀL`` (Eq. 5, 12); positive definite exactly when the quadric is an ellipsoid.
    """

    coefficients: Array
    center: Array
    kappa: float
    shape: Array

    @property
    def is_ellipsoid(self) -> bool:
        """True when ``shape`` is finite and positive definite (else Eq. 13 gives NaN)."""
        if not (np.all(np.isfinite(self.shape)) and np.all(np.isfinite(self.center))):
            return False
        return bool(np.all(np.linalg.eigvalsh(0.5 * (self.shape + self.shape.T)) > 0))


# --------------------------------------------------------------------------- helpers
def _check_points(points: ArrayLike, weights: ArrayLike | None) -> tuple[Array, Array]:
    x = np.asarray(points, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"points must be an (n, 3) array, got shape {x.shape}")
    if x.shape[0] < MIN_POINTS:
        raise ValueError(
            f"{x.shape[0]} points given; an ellipsoid (Eq. 8) has {MIN_POINTS} free parameters, "
            f"so at least {MIN_POINTS} points spread over the surface are needed"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError("points contain NaN or inf; remove those rows before fitting")
    if weights is None:
        return x, np.ones(x.shape[0])
    w = np.asarray(weights, dtype=float)
    if w.shape != (x.shape[0],) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"weights must be {x.shape[0]} finite non-negative numbers")
    return x, w


def _normalisation(x: Array, w: Array) -> tuple[Array, float]:
    """Weighted centroid and RMS radius: the affine map that makes the cloud O(1).

    Without it the columns ``x²`` and ``1`` of the design matrix differ by the square of the
    raw magnitude (1e8 for 16-bit counts), and the normal equations square that again.
    """
    mean = w @ x / w.sum()
    scale = float(np.sqrt(w @ np.sum((x - mean) ** 2, axis=1) / w.sum()))
    if not scale > 0:
        raise ValueError("all points coincide; rotate the sensor through many orientations")
    return mean, scale


def _quadratic_terms(x: Array) -> Array:
    """Columns ``x², y², z², 2xy, 2xz, 2yz, 2x, 2y, 2z, 1`` in the order of Eq. 8."""
    X, Y, Z = x.T
    one = np.ones_like(X)
    return np.stack(
        [X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z, 2 * X, 2 * Y, 2 * Z, one], 1
    )


def _split(v: Array) -> tuple[Array, Array, float]:
    V = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    return V, v[6:9], float(v[9])


def quadric_from_coefficients(v: ArrayLike) -> Quadric:
    """Eq. 9-12 literally: centre ``−V⁻¹ (v6, v7, v8)``, ``κ = cᵀ V c − v9``, ``M = V / κ``.

    No check is made: a hyperboloid gives an indefinite ``M`` (see :attr:`Quadric.is_ellipsoid`).
    """
    v = np.asarray(v, dtype=float)
    V, linear, constant = _split(v)
    with np.errstate(all="ignore"):
        try:
            center = -cast(Array, np.linalg.solve(V, linear))
        except np.linalg.LinAlgError:
            center = np.full(3, np.nan)
        kappa = float(center @ V @ center - constant)  # Eq. 11
        shape = V / kappa  # Eq. 12
    return Quadric(v, center, kappa, shape)


def _from_normalised(center_n: Array, shape_n: Array, mean: Array, scale: float) -> Quadric:
    """Map a quadric fitted on ``(x − mean) / scale`` back to the original coordinates.

    Centre and shape are mapped directly (``c = mean + scale c'``, ``M = M' / scale²``); the
    coefficients of Eq. 8 are rebuilt from them, scaled to the trace constraint.
    """
    center = mean + scale * center_n
    shape = shape_n / scale**2
    kappa = -3.0 / float(np.trace(shape))
    V = kappa * shape
    linear = -V @ center
    constant = float(center @ V @ center - kappa)
    v = np.array([V[0, 0], V[1, 1], V[2, 2], V[0, 1], V[0, 2], V[1, 2], *linear, constant])
    return Quadric(v, center, kappa, shape)


def _triangular_factor(A: Array) -> Array:
    """``R`` of a thin QR (numpy's stubs type ``mode="r"`` as the ``(Q, R)`` pair)."""
    return cast(Array, np.linalg.qr(A, mode="r"))


def _check_rank(R: Array, what: str) -> None:
    """Refuse a rank-deficient design, judged on the singular values of its R factor."""
    s = np.linalg.svd(R, compute_uv=False)
    if s[-1] <= s[0] * 1e3 * np.finfo(float).eps:
        raise ValueError(
            f"the points do not determine {what} (rank-deficient design matrix): they lie on a "
            "plane, a line or too few orientations; rotate the sensor through more orientations"
        )


def _lstsq_qr(A: Array, b: Array, what: str) -> Array:
    """Least squares by one thin QR of ``[A | b]``: stable (no normal equations) and fast for
    tall A, and the triangular factor also serves the rank check."""
    R = _triangular_factor(np.column_stack([A, b]))
    k = A.shape[1]
    _check_rank(R[:k, :k], what)
    return cast(Array, np.linalg.solve(R[:k, :k], R[:k, k]))


# --------------------------------------------------------------------------- fits
def algebraic_fit(
    points: ArrayLike, weights: ArrayLike | None = None, *, conditioned: bool = True
) -> Quadric:
    """Fit the quadric of Eq. 8 with the trace constraint ``v0 + v1 + v2 = −3``.

    Petrov's parameterisation (used by the seed's ``ellipsoid_fit_new``): with
    ``d² = x² + y² + z²``, solve ``D u ≈ d²`` for nine ``u`` where
    ``D = [x²+y²−2z², x²+z²−2y², 2xy, 2xz, 2yz, 2x, 2y, 2z, 1]``, then
    ``v0 = u0 + u1 − 1``, ``v1 = u0 − 2u1 − 1``, ``v2 = u1 − 2u0 − 1``, ``v3..v9 = u2..u8``.

    Parameters
    ----------
    points : (n, 3) array
    weights : (n,) array, optional
        Non-negative weight per point (rows of ``D`` are scaled by ``√w``).
    conditioned : bool
        ``True`` (default): fit on ``(x − centroid) / rms_radius`` by least squares (SVD), map
        back, and refuse a rank-deficient design. ``False``: the seed's literal computation on
        raw coordinates through the normal equations ``(DᵀD) u = Dᵀ d²``.

    Returns
    -------
    Quadric
        Possibly not an ellipsoid (check :attr:`Quadric.is_ellipsoid`).
    """
    x, w = _check_points(points, weights)
    if conditioned:
        mean, scale = _normalisation(x, w)
        x = (x - mean) / scale
    q = _quadratic_terms(x)
    d2 = q[:, 0] + q[:, 1] + q[:, 2]
    D = np.column_stack(
        [q[:, 0] + q[:, 1] - 2 * q[:, 2], q[:, 0] + q[:, 2] - 2 * q[:, 1], q[:, 3:]]
    )
    sw = np.sqrt(w)
    if conditioned:
        u = _lstsq_qr(D * sw[:, None], d2 * sw, "an ellipsoid")
    else:
        Dw = D * w[:, None]
        # the seed's normal equations, as published
        u = cast(Array, np.linalg.solve(Dw.T @ D, Dw.T @ d2))
    v = np.concatenate([[u[0] + u[1] - 1, u[0] - 2 * u[1] - 1, u[1] - 2 * u[0] - 1], u[2:]])
    quadric = quadric_from_coefficients(v)
    if not conditioned:
        return quadric
    return _from_normalised(quadric.center, quadric.shape, mean, scale)


#: Li & Griffiths' constraint ``vᵀ C v = 4J − I²`` on the quadratic coefficients (k = 4), in the
#: order v0..v5 of Eq. 8: ``−a² − b² − c² + 2(ab + bc + ca) − 4(f² + g² + h²)``.
_LG_CONSTRAINT = np.block(
    [[np.ones((3, 3)) - 2 * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), -4 * np.eye(3)]]
)


def li_griffiths_fit(points: ArrayLike, weights: ArrayLike | None = None) -> Quadric:
    """Ellipsoid-specific least squares (Li & Griffiths 2004) with ``k = 4``.

    Minimises ``|D v|²`` over the ten coefficients of Eq. 8 subject to ``4J − I² = 1``, which
    admits only ellipsoids (those whose shortest axis is at least half the longest, which
    covers every sensor worth calibrating). The linear part is eliminated with a QR projection
    (the Schur complement ``S11 − S12 S22⁻¹ S21`` without forming ``S22⁻¹``) and the
    six quadratic coefficients come from the generalised eigenproblem ``S v = λ C v``: the
    eigenvector with ``vᵀ C v > 0`` and the smallest ``λ ≥ 0``. Always run on centred and
    scaled points.
    """
    x, w = _check_points(points, weights)
    mean, scale = _normalisation(x, w)
    D = _quadratic_terms((x - mean) / scale) * np.sqrt(w)[:, None]
    _check_rank(_triangular_factor(D[:, :9]), "an ellipsoid")
    quad, lin = D[:, :6], D[:, 6:]
    Q, _ = np.linalg.qr(lin)
    reduced = quad - Q @ (Q.T @ quad)  # quadratic columns orthogonal to the linear ones
    S = reduced.T @ reduced
    eigvals, eigvecs = np.linalg.eig(np.linalg.solve(_LG_CONSTRAINT, S))
    eigvecs = np.real(eigvecs[:, np.abs(np.imag(eigvals)) < 1e-9 * (1 + np.abs(eigvals))])
    c_norm = np.einsum("ik,ij,jk->k", eigvecs, _LG_CONSTRAINT, eigvecs)
    if not np.any(c_norm > 0):
        raise ValueError(
            "no ellipsoid fits these points; rotate the sensor through more orientations"
        )
    candidates = eigvecs[:, c_norm > 0] / np.sqrt(c_norm[c_norm > 0])
    cost = np.einsum("ik,ij,jk->k", candidates, S, candidates)
    v_quad = candidates[:, int(np.argmin(cost))]
    v_lin = -np.linalg.lstsq(lin, quad @ v_quad, rcond=None)[0]
    quadric = quadric_from_coefficients(np.concatenate([v_quad, v_lin]))
    return _from_normalised(quadric.center, quadric.shape, mean, scale)


# --------------------------------------------------------------------------- factor
def reverse_triangular_factor(M: ArrayLike) -> Array:
    """Eq. 13: the lower-triangular ``L = [[a,0,0],[b,c,0],[d,e,f]]`` with ``LᵀL = M``.

    Solved from the bottom-right corner (``f = √C, e = F/f, d = E/f, c = √(B − e²),
    b = (D − de)/c, a = √(A − b² − d²)`` with ``M = [[A,D,E],[D,B,F],[E,F,C]]``); it is not
    ``numpy.linalg.cholesky`` (which gives ``M = L Lᵀ``). The seed's Eq. 13 names ``d`` as
    ``g``; this is the same formula. Vectorised over leading axes; a matrix that is not
    positive definite gives NaN entries, exactly as the seed's square roots would.
    """
    M = np.asarray(M, dtype=float)
    A, B, C = M[..., 0, 0], M[..., 1, 1], M[..., 2, 2]
    D, E, F = M[..., 0, 1], M[..., 0, 2], M[..., 1, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.sqrt(C)
        e = F / f
        d = E / f
        c = np.sqrt(B - e**2)
        b = (D - d * e) / c
        a = np.sqrt(A - b**2 - d**2)
    zero = np.zeros_like(a)
    return np.stack(
        [np.stack([a, zero, zero], -1), np.stack([b, c, zero], -1), np.stack([d, e, f], -1)], -2
    )


def ellipsoid_radii(shape: ArrayLike) -> Array:
    """Semi-axis lengths ``1/√λ`` of ``(x − c)ᵀ M (x − c) = 1``, ascending eigenvalue order
    (so longest first); NaN for a non-positive eigenvalue."""
    lam = np.linalg.eigvalsh(0.5 * (np.asarray(shape, float) + np.asarray(shape, float).T))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(lam > 0, 1.0 / np.sqrt(np.where(lam > 0, lam, 1.0)), np.nan)


# --------------------------------------------------------------------------- families
#: Indices of the six distinct entries of a symmetric 3x3 in a coefficient vector
#: ``(a, b, c, d, e, f)`` read as ``[[a, d, e], [d, b, f], [e, f, c]]``.
SYM_INDEX = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])
# A weak pull towards a sphere that breaks the tie when the points do not fix all nine
# parameters (8 poses): the member of the quadric pencil closest to a sphere.
_SPHERE_PULL = np.zeros((5, 10))
_SPHERE_PULL[0, [0, 1]] = (1e-4, -1e-4)
_SPHERE_PULL[1, [1, 2]] = (1e-4, -1e-4)
_SPHERE_PULL[2, 3] = _SPHERE_PULL[3, 4] = _SPHERE_PULL[4, 5] = 1e-4
#: The factors of the quadratic columns ``x_i x_j``: the squares, then the cross terms.
_LEFT, _RIGHT = np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2])


def spd_sqrt(M: Array) -> tuple[Array, Array]:
    """Symmetric square root of a symmetric positive definite matrix, and of its inverse;
    batched over leading axes."""
    w, V = np.linalg.eigh(M)
    root = np.sqrt(np.maximum(w, 1e-300))[..., None, :]
    Vt = np.swapaxes(V, -1, -2)
    return (V * root) @ Vt, (V / root) @ Vt


def family_design(y: Array, weights: Array) -> tuple[Array, Array, Array, Array]:
    """The normalised points, their centre and scale, and the rows' scaling by ``√w``, for
    point sets (..., n, 3) with weights (..., n)."""
    wsum = weights.sum(axis=-1)
    c0 = np.einsum("...n,...ni->...i", weights, y) / wsum[..., None]
    d = y - c0[..., None, :]
    s0 = np.sqrt(np.einsum("...n,...ni,...ni->...", weights, d, d) / wsum)
    z = d / np.where(s0 > 0, s0, 1.0)[..., None, None]
    return z, c0, s0, np.sqrt(weights / wsum[..., None])[..., None]


def family_fit(
    y: ArrayLike, weights: ArrayLike, family: str = "full"
) -> tuple[Array, Array] | None:
    """Weighted algebraic ellipsoid of a family: ``"full"`` (9 parameters), ``"axes"``
    (axis-aligned) or ``"sphere"``.

    Returns the symmetric "gain" ``K`` and centre ``c`` with ``x = K u + c`` for unit vectors
    ``u`` on the surface, or ``None`` when the fit is not an ellipsoid. The full family adds a
    weak pull towards a sphere that only matters when the points do not fix it (8 points).
    """
    y = np.asarray(y, dtype=float)
    K, c, ok = family_fits(y[None], np.asarray(weights, dtype=float)[None], family)
    return (K[0], c[0]) if ok[0] else None


def family_fits(
    y: Array,
    weights: Array,
    family: str = "full",
    *,
    design: tuple[Array, Array, Array, Array] | None = None,
) -> tuple[Array, Array, NDArray[np.bool_]]:
    """:func:`family_fit` for several point sets at once, (S, n, 3) with weights (S, n): the
    gains (S, 3, 3), centres (S, 3) and which fits are ellipsoids (entries of the others are
    meaningless). One call of each LAPACK routine for all the sets. ``design``: these sets'
    :func:`family_design`, when already computed (every family of the same points shares it).
    """
    z, c0, s0, sw = family_design(y, weights) if design is None else design
    S, n = z.shape[:2]
    q = {"full": 6, "axes": 3}.get(family, 1)  # quadratic columns, then 2z and 1
    pull = len(_SPHERE_PULL) if family == "full" else 0
    D = np.empty((S, n + pull, q + 4))
    rows = D[:, :n]  # the design written in place: a few calls, not one per column
    if family == "sphere":
        x1, x2, x3 = z[..., 0], z[..., 1], z[..., 2]
        rows[..., 0] = x1 * x1 + x2 * x2 + x3 * x3
    else:
        np.multiply(z[..., _LEFT[:q]], z[..., _RIGHT[:q]], out=rows[..., :q])
        rows[..., 3:q] *= 2.0  # the cross terms' 2 x_i x_j
    np.multiply(z, 2.0, out=rows[..., q : q + 3])
    rows[..., q + 3] = 1.0
    rows *= sw
    if pull:
        D[:, n:] = _SPHERE_PULL
    theta = np.linalg.svd(D, full_matrices=False)[2][:, -1]
    if family == "full":
        A = theta[:, SYM_INDEX]
    elif family == "axes":
        A = np.zeros((S, 3, 3))
        A.reshape(S, 9)[:, ::4] = theta[:, :3]
    else:
        A = np.eye(3) * theta[:, 0, None, None]
    beta, gamma = theta[:, -4:-1], theta[:, -1]
    ok = s0 > 0
    try:
        zc = -np.linalg.solve(A, beta[..., None])[..., 0]
    except np.linalg.LinAlgError:  # one set's quadric has no centre: solve them one by one
        zc = np.full((S, 3), np.nan)
        for s in range(S):
            try:
                zc[s] = -np.linalg.solve(A[s], beta[s])
            except np.linalg.LinAlgError:
                ok[s] = False
    with np.errstate(all="ignore"):
        M = A / (np.einsum("si,sij,sj->s", zc, A, zc) - gamma)[:, None, None]
    ok &= np.isfinite(M).all(axis=(1, 2))
    w, V = np.linalg.eigh(np.where(ok[:, None, None], M, np.eye(3)))
    ok &= w[:, 0] > 0
    root = np.sqrt(np.where(w > 0, w, 1.0))[:, None, :]
    K = s0[:, None, None] * (V / root) @ V.transpose(0, 2, 1)
    return K, c0 + s0[:, None] * zc, ok


def pencil_fits(
    y: ArrayLike, weights: ArrayLike, n_grid: int
) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Ellipsoids through too few points to fix one: the pencil of the design's two smallest
    right singular vectors, sampled at ``n_grid`` members.

    Returns per member the symmetric gain ``K`` (n_grid, 3, 3), the centre (n_grid, 3) and a
    mask of the members that are ellipsoids.
    """
    z, c0, scale, sw = family_design(np.asarray(y, dtype=float), np.asarray(weights, dtype=float))
    s0 = float(scale)
    x1, x2, x3 = z.T
    D = np.column_stack(
        [x1 * x1, x2 * x2, x3 * x3, 2 * x1 * x2, 2 * x1 * x3, 2 * x2 * x3, 2 * z, np.ones(len(z))]
    )
    Z = np.linalg.svd(D * sw, full_matrices=True)[2][-2:]
    t = np.linspace(0.0, np.pi, n_grid, endpoint=False)
    theta = np.cos(t)[:, None] * Z[0] + np.sin(t)[:, None] * Z[1]
    A = theta[:, SYM_INDEX]
    beta, gamma = theta[:, 6:9], theta[:, 9]
    ok = np.abs(np.linalg.det(A)) > 1e-12
    A = np.where(ok[:, None, None], A, np.eye(3))
    zc = -np.linalg.solve(A, beta[:, :, None])[:, :, 0]
    k = np.einsum("ti,tij,tj->t", zc, A, zc) - gamma
    M = A / np.where(np.abs(k) > 1e-300, k, 1.0)[:, None, None]
    w, V = np.linalg.eigh(M)
    ok &= np.all(w > 0, axis=1)
    w = np.where(w > 0, w, 1.0)
    K = s0 * (V / np.sqrt(w)[:, None, :]) @ V.transpose(0, 2, 1)
    return K, c0 + s0 * zc, ok
