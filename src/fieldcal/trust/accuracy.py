"""Predicted errors after calibration in the user's terms: tilt, heading, |a|, |m|.

A corrected reading is ``v̂ = K̂⁻¹ (raw − b̂)`` with ``raw = K v + b + n``. To first order its
error is ``δv = K⁻¹ (n − δK v − δb)``: the parameters' errors (covariance from the fit) and the
pose-level noise ``n ~ N(0, q² I)``, the part of a still reading's error that does not average
away. From ``δv`` (``docs/trust.md``):

- tilt: the angle between the true and corrected gravity directions, ``|(I − vvᵀ) δv|``;
- ``|a|``, ``|m|``: the relative error of the norm, ``vᵀ δv``;

each as an RMS over orientations spread evenly on the sphere (a Fibonacci lattice);

- heading: a tilt-compensated compass heading for a level device (body z down), RMS over
  headings, with the gradient with respect to every gain and bias of both sensors and both
  noise vectors taken by finite differences of the heading formula itself.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from numpy.typing import NDArray

from ..calibration import Accuracy, Calibration, ParameterCovariance
from ..covariance import BlockIndex
from ..geometry.orientations import fibonacci_sphere

__all__ = ["over_span", "predict_accuracy", "temperature_span"]

Array = NDArray[np.float64]

_ORIENTATIONS = 128
_HEADINGS = 36


_SPHERE = fibonacci_sphere(_ORIENTATIONS)
_SPHERE.setflags(write=False)


def _level(n: int) -> Array:
    """World → body rotations of a level device at ``n`` headings: yaws about the down axis."""
    psi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    c, s = np.cos(psi), np.sin(psi)
    R = np.zeros((n, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, s, -s, c, 1.0
    return R


_LEVEL = _level(_HEADINGS)
_LEVEL.setflags(write=False)
_EYE = np.eye(3)
_EYE.setflags(write=False)


def _param_block(cov: ParameterCovariance | None, sensor: str) -> Array:
    """(12, 12) covariance of ``vec(K)`` (row-major) and ``b`` of one sensor (zeros if none)."""
    block = None if cov is None else cov.sensor_blocks.get(sensor)
    if block is None or len(block.names) != 12:  # gains and biases, in this order, or nothing
        return np.zeros((12, 12))
    return block.matrix


def _moments(v: Array) -> tuple[Array, Array, Array, Array]:
    """The means of ``v``, ``v vᵀ``, ``v ⊗ v ⊗ v`` and ``v ⊗ v ⊗ v ⊗ v`` over the rows of
    ``v``: the RMS errors over the orientations are means of quadratic forms in these."""
    n = len(v)
    return (
        v.mean(axis=0),
        v.T @ v / n,
        np.einsum("ni,nj,nk->ijk", v, v, v) / n,
        np.einsum("ni,nj,nk,nl->ijkl", v, v, v, v) / n,
    )


_S1, _S2, _S3, _S4 = _moments(_SPHERE)


def _norm_and_direction(
    cal: Calibration, sensor: str, direction: bool = True, inverse: Array | None = None
) -> tuple[float, float]:
    """RMS relative norm error and RMS direction error (degrees; 0 unless ``direction``) of a
    corrected reading, over the orientations of :data:`_SPHERE`.

    ``δv = K⁻¹ (n − δK u − δb)`` relative to the field's magnitude ``|f|`` (``u = |f| v``):
    along a unit vector ``w`` its variance is ``zᵀ (G P Gᵀ + q² I) z / |f|²`` with
    ``z = K⁻ᵀ w`` and ``G`` the Jacobian of ``K u + b`` in ``[vec K, b]`` (row-major), so
    ``Gᵀ z = [z ⊗ u, z]``. The radial part takes ``w = v``, the trace the rows of ``K⁻¹``;
    their means over the orientations are ``Σ P ∘ E[g gᵀ]`` with the moments of ``v``
    (:func:`_moments`), not one 3x3 covariance per orientation. ``inverse``: the gain's
    inverse when the caller has it already (the heading's solve gives it)."""
    sc = cal.sensor(sensor)
    f = cal.reference(sensor)
    ref = math.sqrt(float(f @ f))  # np.linalg.norm's number, without its wrapper
    P = _param_block(cal.covariance, sensor)
    q2 = sc.pose_noise_std**2
    Kinv = np.linalg.inv(sc.gain) if inverse is None else inverse
    # radial: z = K⁻ᵀ v, g = [z ⊗ u, z]; E[z_j u_a z_k u_b] = |f|² Σ K⁻¹_cj K⁻¹_dk E[v v v v]
    E = np.empty((12, 12))
    KT = Kinv.T
    E[:9, :9] = (KT @ (KT @ _S4.reshape(3, 27)).reshape(9, 3, 3)).reshape(9, 9) * (ref * ref)
    E[:9, 9:] = (KT @ _S3.reshape(3, 9)).reshape(9, 3) @ Kinv * ref
    E[9:, :9] = E[:9, 9:].T
    E[9:, 9:] = KT @ _S2 @ Kinv
    radial = (float(np.vdot(P, E)) + q2 * float(E[9, 9] + E[10, 10] + E[11, 11])) / (ref * ref)
    if not direction:
        return float(np.sqrt(radial)), 0.0
    # the trace: the rows k_r of K⁻¹ for z, summed (Σ_r k_r k_rᵀ = K⁻ᵀ K⁻¹)
    A = KT @ Kinv
    E[:9, :9] = (A[:, None, :, None] * _S2[None, :, None, :]).reshape(9, 9) * (ref * ref)
    E[:9, 9:] = (A[:, None, :] * _S1[None, :, None]).reshape(9, 3) * ref
    E[9:, :9] = E[:9, 9:].T
    E[9:, 9:] = A
    trace = (float(np.vdot(P, E)) + q2 * float(A[0, 0] + A[1, 1] + A[2, 2])) / (ref * ref)
    return float(np.sqrt(radial)), float(np.degrees(np.sqrt(max(trace - radial, 0.0))))


def _heading(a: Array, m: Array) -> Array:
    """Heading (rad) of the body x axis from body-frame specific force and field, (..., 3).

    North in the body frame is ``(d × m) × d = m |d|² − d (d·m)`` with ``d = −a`` the down
    direction (the field's horizontal part): scale does not change its heading, so nothing is
    normalised."""
    return _heading_of(np.moveaxis(a, -1, 0), np.moveaxis(m, -1, 0))


def _heading_of(a: Array, m: Array) -> Array:
    """:func:`_heading` with the components first, (3, ...): each a contiguous array when the
    caller lays its readings out so (the heading error's 31 x 36 readings per sensor)."""
    d0, d1, d2 = -a[0], -a[1], -a[2]
    m0, m1, m2 = m[0], m[1], m[2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    dm = d0 * m0 + d1 * m1 + d2 * m2
    return np.asarray(np.arctan2(d1 * dm - m1 * dd, m0 * dd - d0 * dm))


#: Each sensor's gain and bias names, in the order of its 12 heading parameters.
_NAMES = {
    s: [f"{s}.gain[{j},{k}]" for j in range(3) for k in range(3)]
    + [f"{s}.bias[{j}]" for j in range(3)]
    for s in ("accel", "mag")
}
#: Sherman-Morrison's indices: the gain entry ``K[j, l]`` of each of the 9 parameters.
_ROW, _COL = np.divmod(np.arange(9), 3)


@functools.lru_cache(maxsize=64)
def _positions(names: tuple[str, ...]) -> BlockIndex | None:
    """The index that takes both sensors' 24 gain and bias parameters, in order, out of the
    covariance of ``names`` (``None``: not all there): two slices when they run in order (the
    usual layout; a view instead of fancy indexing), else :func:`numpy.ix_` of their
    positions. One look-up per set of names, not per calibration."""
    where = {n: i for i, n in reversed(list(enumerate(names)))}
    wanted = _NAMES["accel"] + _NAMES["mag"]
    if not all(n in where for n in wanted):
        return None
    at = [where[n] for n in wanted]
    if at == list(range(at[0], at[0] + 24)):
        return (slice(at[0], at[0] + 24),) * 2
    return np.ix_(at, at)


def _parameter_cov(cal: Calibration) -> Array:
    """(30, 30) covariance of the heading's parameters: ``vec K_a, b_a, vec K_m, b_m`` (their
    own blocks as :func:`_param_block` gives them, the cross block from the joint covariance)
    and the two sensors' pose-level noise."""
    C = np.zeros((30, 30))
    cov = cal.covariance
    at = None if cov is None else _positions(cov.names)
    if cov is not None and at is not None:  # correlated through the poses
        C[:24, :24] = cov.matrix[at]
    for k, name in enumerate(("accel", "mag")):
        block = slice(12 * k, 12 * k + 12)
        if at is None or len(cov.sensor_blocks[name].names) != 12:  # type: ignore[union-attr]
            C[block, block] = _param_block(cov, name)
        q2 = cal.sensor(name).pose_noise_std ** 2
        C.reshape(-1)[(24 + 3 * k) * 31 : (27 + 3 * k) * 31 : 31] = q2
    return C


#: Which sensor's step each of the 30 heading parameters is perturbed by (accel 0, mag 1).
_OWNER = np.repeat([0, 1, 0, 1], [12, 12, 3, 3])


def _heading_error(cal: Calibration) -> float | None:
    """The predicted heading error (degrees, RMS over headings); ``None`` without both sensors
    and their fields."""
    found = _heading_and_inverses(cal)
    return None if found is None else found[0]


def _heading_and_inverses(cal: Calibration) -> tuple[float, Array] | None:
    """:func:`_heading_error` and the inverses of the two gains (2, 3, 3), which its solve
    gives and the norm errors use."""
    if cal.accel is None or cal.mag is None or cal.gravity is None or cal.magnetic is None:
        return None
    # parameters: vec K_a, b_a, vec K_m, b_m (24), then noise n_a, n_m (6); both sensors at
    # once, the same arithmetic per sensor as one at a time
    K = np.array([cal.accel.gain, cal.mag.gain])
    b = np.array([cal.accel.bias, cal.mag.bias])
    raw = (_LEVEL @ np.array([cal.gravity, cal.magnetic]).T).transpose(2, 0, 1)
    raw = raw @ K.transpose(0, 2, 1) + b[:, None, :]
    # one step per sensor, in its own raw units (the two gains may differ by 10^4): each
    # sensor's parameter and noise rows are perturbed by its step and divided by it below
    step = 1e-6 * np.abs(K).max(axis=(1, 2))
    # one solve gives the corrected readings and K⁻¹ (the right-hand sides' last columns)
    rhs = np.concatenate(
        [(raw - b[:, None, :]).transpose(0, 2, 1), np.broadcast_to(_EYE, K.shape)], 2
    )
    solved = np.linalg.solve(K, rhs)
    u, Kinv = solved[:, :, :_HEADINGS].transpose(0, 2, 1), solved[:, :, _HEADINGS:]
    # corrected readings (3, 31, H) per sensor, components first (each a contiguous block
    # for the heading's arithmetic): unperturbed, then one row per parameter
    rows = np.broadcast_to(u.transpose(0, 2, 1)[:, :, None], (2, 3, 31, _HEADINGS)).copy()
    # a gain entry K[j, l] + s: Sherman-Morrison, u − s K⁻¹e_j u_l / (1 + s K⁻¹[l, j])
    s = step[:, None]
    denom = 1.0 + s * Kinv[:, _COL, _ROW]
    along = s[:, :, None] * u[:, :, _COL].transpose(0, 2, 1) / denom[:, :, None]  # (2, 9, H)
    change = along[:, None] * Kinv[:, :, _ROW][..., None]  # (2, 3, 9, H)
    # a bias b_j + s moves the reading by −s K⁻¹e_j, a noise n_j + s by +s K⁻¹e_j
    shift = (s[:, :, None] * Kinv)[..., None]  # (2, 3, 3, 1): component, parameter
    for k in range(2):
        first = 1 + 12 * k
        rows[k, :, first : first + 9] -= change[k]
        rows[k, :, first + 9 : first + 12] -= shift[k]
        rows[k, :, 25 + 3 * k : 28 + 3 * k] += shift[k]
    both = _heading_of(rows[0], rows[1])
    wrapped = np.remainder(both[1:] - both[0] + np.pi, 2.0 * np.pi) - np.pi
    J = (wrapped / step[_OWNER, None]).T  # (H, 30)
    # the mean over headings of each heading's variance Jₕ C Jₕᵀ, as one sum
    var = float(np.vdot(J @ _parameter_cov(cal), J)) / _HEADINGS
    return math.degrees(math.sqrt(max(var, 0.0))), Kinv


#: Gauss-Legendre nodes for the mean over the logged temperatures: exact for the products of
#: two bias polynomials of order up to 3 (degree 6 needs 4 nodes; 8 leave room).
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(8)


def temperature_span(cal: Calibration) -> tuple[float, float] | None:
    """The temperatures logged (°C, lowest and highest over the sensors with temperature
    terms) over which the predicted errors average the terms' uncertainty; ``None`` without
    terms."""
    spans = [
        sc.temperature.span
        for sc in (cal.accel, cal.mag)
        if sc is not None and sc.temperature is not None and sc.temperature.order > 0
    ]
    if not spans:
        return None
    return float(min(s[0] for s in spans)), float(max(s[1] for s in spans))


def over_span(cal: Calibration) -> Calibration:
    """``cal`` with the covariance of its biases averaged over the logged temperatures: the
    bias at ``T`` is ``b + Σ_k c_k d^k`` (``d = T − T_ref``, :mod:`fieldcal.thermal`), so its
    error is ``T(d) [δvec K, δb, δc]`` and its covariance ``T(d) C T(d)ᵀ``; the mean of that
    over ``T`` uniform on the span (Gauss-Legendre) replaces the bias block, the terms' names
    dropped. A calibration without temperature terms is returned as it is."""
    cov, span = cal.covariance, temperature_span(cal)
    if cov is None or span is None:
        return cal
    names = list(cov.names)
    keep = [i for i, n in enumerate(names) if ".temp[" not in n]
    where = {n: i for i, n in enumerate(names)}
    # (node, kept, all): the map from every parameter to the kept ones at each temperature
    T = np.zeros((len(_NODES), len(keep), len(names)))
    T[:, np.arange(len(keep)), keep] = 1.0
    row = {names[i]: r for r, i in enumerate(keep)}
    temps = span[0] + (span[1] - span[0]) * (_NODES + 1.0) / 2.0
    for sensor in ("accel", "mag"):
        sc = cal.sensor(sensor) if getattr(cal, sensor) is not None else None
        model = None if sc is None else sc.temperature
        if model is None or model.order == 0:
            continue
        d = np.clip(temps, model.span[0], model.span[1]) - model.reference
        for k in range(1, model.order + 1):
            for j in range(3):
                term, bias = f"{sensor}.temp[{k},{j}]", f"{sensor}.bias[{j}]"
                if term in where and bias in row:
                    T[:, row[bias], where[term]] = d**k
    averaged = np.einsum("n,nkl,lm,njm->kj", _WEIGHTS / 2.0, T, cov.matrix, T)
    kept = ParameterCovariance(tuple(names[i] for i in keep), (averaged + averaged.T) / 2.0)
    return dataclasses.replace(cal, covariance=kept)


def predict_accuracy(cal: Calibration) -> Accuracy:
    """The predicted 1σ (RMS) errors of :class:`~fieldcal.calibration.Accuracy` for ``cal``;
    with temperature terms, RMS over the logged temperatures too (:func:`over_span`)."""
    cal = over_span(cal)
    accel_norm = tilt = mag_norm = heading = None
    inverses: Array | list[None] = [None, None]
    found = _heading_and_inverses(cal)
    if found is not None:  # both sensors: the gains' inverses come with the heading
        heading, inverses = found
    if cal.accel is not None and cal.gravity is not None:
        accel_norm, tilt = _norm_and_direction(cal, "accel", inverse=inverses[0])
    if cal.mag is not None and cal.magnetic is not None:
        mag_norm, _ = _norm_and_direction(cal, "mag", direction=False, inverse=inverses[1])
    return Accuracy(
        tilt_deg=tilt,
        heading_deg=heading,
        accel_norm_rel=accel_norm,
        mag_norm_rel=mag_norm,
    )
