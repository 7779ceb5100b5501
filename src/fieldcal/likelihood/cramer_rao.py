"""Uncertainty at the optimum: Cramér-Rao bound from the reduced (Schur) system.

With whitened residuals the Fisher information is ``JᵀJ``; eliminating the rotations, the
covariance of the G globals is ``S⁻¹`` with ``S = V − Σ W_iᵀ U_i⁻¹ W_i`` (undamped). The named
parameters are linear in the globals (entries of symmetric gains, both off-diagonal copies; the
dip in degrees). The hat matrix's diagonal blocks give each pose's leverage: they split the
residual degrees of freedom between sensors (pose-level noise) and standardise each pose's
residual (outlier tests).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..calibration import Calibration, ParameterCovariance
from ..stats.pose_stats import PoseStats, SensorStats
from ..thermal import temperature_names
from .information import jacobi_scaled, scaled_inverse
from .levenberg import Normal, normal_equations, reduce
from .pose_model import SYM_MAP, Problem, State, build_problem, residuals

Array = NDArray[np.float64]


@dataclass
class Uncertainty:
    """Cramér-Rao covariance of the named parameters, the reduced system's condition number and
    the hat matrix's diagonal blocks (N, m, m): how much of each pose's whitened residual the
    fit itself absorbs (leverage).

    Built from the globals' covariance ``C`` and the Jacobi-scaled reduced matrix; the named
    covariance and the condition number are derived on first use (the trust path's
    intermediate evaluations need the leverage only)."""

    leverage: Array
    globals_covariance: Array  # (G, G): C = S⁻¹
    scaled_reduced: Array  # (G, G): S with unit diagonal, for the condition number
    problem: Problem

    @functools.cached_property
    def covariance(self) -> ParameterCovariance:
        """Covariance of the named parameters, ``T C Tᵀ``."""
        names, T = named_map(self.problem)
        Cn = T @ self.globals_covariance @ T.T
        return ParameterCovariance(tuple(names), 0.5 * (Cn + Cn.T))

    @functools.cached_property
    def condition(self) -> float:
        """S's condition number after Jacobi scaling (large: the poses do not determine every
        parameter)."""
        return _condition(self.scaled_reduced)

    def dof_share(self, problem: Problem) -> dict[str, float]:
        """Expected share of Eq. 8's J per sensor, ``3N − tr(H_ss)``."""
        diag = np.einsum("nii->ni", self.leverage)
        return {
            s: float(3 * problem.n - np.sum(diag[:, 3 * k : 3 * k + 3]))
            for k, s in enumerate(problem.sensors)
        }


@dataclass(frozen=True)
class PoseCovariance:
    """The poses' rotation covariance kept in its structure: ``blockdiag(blocks) + F Fᵀ`` with
    ``blocks`` (N, 3, 3) each pose's own part and ``factor`` ``F`` (N, 3, G) the part the poses
    share through the G globals (``U_i⁻¹ δ_ij + Y_i C Y_jᵀ`` with ``F_i = Y_i chol(C)``): memory
    and every use linear in N, where the dense (3N, 3N) matrix is quadratic."""

    blocks: Array
    factor: Array

    @property
    def n(self) -> int:
        """The number of poses."""
        return int(self.blocks.shape[0])

    def dense(self) -> Array:
        """The (3N, 3N) matrix."""
        n = self.n
        F = self.factor.reshape(3 * n, -1)
        out = F @ F.T
        for i in range(n):
            out[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += self.blocks[i]
        return 0.5 * (out + out.T)

    def transformed(self, X: ArrayLike) -> PoseCovariance:
        """The covariance of ``(X_i δ_i)``, ``X`` (N, k, 3): ``X C Xᵀ`` with
        ``X = blockdiag(X_i)`` (e.g. ``−[g_i]×`` for the poses' gravity directions)."""
        M = np.asarray(X, dtype=float)
        blocks = M @ self.blocks @ np.transpose(M, (0, 2, 1))
        return PoseCovariance(0.5 * (blocks + np.transpose(blocks, (0, 2, 1))), M @ self.factor)


def global_covariance(ne: Normal) -> tuple[Array, Array, Array, float]:
    """``S⁻¹`` (CRB of the globals), the pose blocks' inverses, ``U⁻¹W``, and S's condition
    number after Jacobi scaling (large: the poses do not determine every parameter)."""
    C, Uinv, Y, Sn = _covariance(ne)
    return C, Uinv, Y, _condition(Sn)


def _covariance(ne: Normal) -> tuple[Array, Array, Array, Array]:
    """:func:`global_covariance` with the Jacobi-scaled S in place of its condition number."""
    Uinv, Y, S, _, _ = reduce(ne, 0.0)
    Sn, _ = jacobi_scaled(S)
    return scaled_inverse(S), Uinv, Y, Sn


def _condition(Sn: Array) -> float:
    ev = np.linalg.eigvalsh(Sn)
    return float(ev[-1] / max(ev[0], 1e-300))


#: names and the map of :func:`named_map` (the type built once: it is checked per call)
_NamedMap = tuple[list[str], Array]
#: The named map of each parameter layout seen (a layout is a few integers: the same for every
#: problem of a session, whatever its noise model or subset of poses).
_NAMED_MAPS: dict[tuple[object, ...], tuple[list[str], Array]] = {}


def named_map(problem: Problem) -> tuple[list[str], Array]:
    """Names and the linear map from the G globals to the named parameters."""
    cached = problem.memo.get("named_map")
    if cached is None:
        layout = (
            problem.sensors,
            problem.frame,
            problem.dip_index,
            problem.n_global,
            *(
                (s, sl.start, sl.stop)
                for part in (problem.gain_slice, problem.bias_slice, problem.temp_slice)
                for s, sl in part.items()
            ),
        )
        cached = _NAMED_MAPS.get(layout)
        if cached is None:
            names, T = _named_map(problem)
            T.setflags(write=False)
            if len(_NAMED_MAPS) >= 64:  # a bound, not a leak, for a long-running process
                _NAMED_MAPS.clear()
            cached = _NAMED_MAPS[layout] = (names, T)
        problem.memo["named_map"] = cached
    names, T = cast(_NamedMap, cached)
    return list(names), T


def _named_map(problem: Problem) -> tuple[list[str], Array]:
    names: list[str] = []
    blocks = []
    G = problem.n_global
    for s in problem.sensors:
        gs = problem.gain_slice[s]
        T = np.zeros((9, G))
        T[:, gs] = SYM_MAP if problem.symmetric(s) else np.eye(9)
        names += [f"{s}.gain[{j},{k}]" for j in range(3) for k in range(3)]
        blocks.append(T)
        B = np.zeros((3, G))
        B[:, problem.bias_slice[s]] = np.eye(3)
        names += [f"{s}.bias[{j}]" for j in range(3)]
        blocks.append(B)
    if problem.joint:
        D = np.zeros((1, G))
        D[0, problem.dip_index] = np.degrees(1.0)
        names.append("dip_deg")
        blocks.append(D)
    for s, sl in problem.temp_slice.items():  # after the dip: the names before are unchanged
        names += [f"{s}.{name}" for name in temperature_names(problem.temp_order(s))]
        P = np.zeros((sl.stop - sl.start, G))
        P[:, sl] = np.eye(sl.stop - sl.start)
        blocks.append(P)
    return names, np.vstack(blocks)


def leverage_blocks(ne: Normal, C: Array, Uinv: Array, Y: Array) -> Array:
    """Diagonal blocks of the hat matrix ``J (JᵀJ)⁻¹ Jᵀ`` per pose, (N, m, m).

    With the arrow structure, ``H_ii = Jp_i U_i⁻¹ Jp_iᵀ + X_i C X_iᵀ`` and
    ``X_i = Jg_i − Jp_i U_i⁻¹ W_i`` (block inverse through the Schur complement)."""
    Jp, Jg = ne.Jp, ne.Jg
    # matrix products, not three-operand einsums (those loop over every index combination)
    H = (Jp @ Uinv) @ Jp.transpose(0, 2, 1)
    X = Jg - Jp @ Y
    return H + (X @ C) @ X.transpose(0, 2, 1)


def uncertainty(problem: Problem, ne: Normal) -> Uncertainty:
    """Covariance of the named parameters (CRB), condition number and leverage at a point."""
    C, Uinv, Y, Sn = _covariance(ne)
    return Uncertainty(leverage_blocks(ne, C, Uinv, Y), C, Sn, problem)


def wishart_std(cov: Array, dof: int) -> Array:
    """Standard error of Eq. 7's entries: ``Var Σ̂_ij = (Σ_ij² + Σ_ii Σ_jj)/ν``."""
    d = np.diag(cov)
    return np.sqrt((cov**2 + np.outer(d, d)) / max(dof, 1))


def pose_rotation_factors(
    cal: Calibration, counts: Mapping[str, ArrayLike] | None = None
) -> PoseCovariance:
    """:func:`pose_rotation_covariance` in its structure, :class:`PoseCovariance`: each pose's
    own block and the shared part's factor, in memory linear in the number of poses (what
    :func:`fieldcal.gyro.fit_gyro` takes for a log of many poses).

    Parameters
    ----------
    cal : Calibration
        As for :func:`pose_rotation_covariance`.
    counts : mapping, optional
        As for :func:`pose_rotation_covariance`.

    Returns
    -------
    PoseCovariance
        ``blockdiag(blocks) + F Fᵀ`` equals :func:`pose_rotation_covariance` (to round-off).

    Raises
    ------
    ValueError
        As :func:`pose_rotation_covariance`.
    """
    ne, (C, Uinv, Y, _) = _pose_information(cal, counts)
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    root = V * np.sqrt(np.clip(w, 0.0, None))  # C = root rootᵀ
    blocks, factor = Uinv, Y @ root
    if ne.basis is not None:  # one sensor: the two tilt angles, back in the body frame
        blocks = ne.basis @ Uinv @ np.transpose(ne.basis, (0, 2, 1))
        factor = ne.basis @ factor
    return PoseCovariance(0.5 * (blocks + np.transpose(blocks, (0, 2, 1))), factor)


def _pose_information(
    cal: Calibration, counts: Mapping[str, ArrayLike] | None
) -> tuple[Normal, tuple[Array, Array, Array, float]]:
    """The joint fit's normal equations at ``cal`` (its noise model, zero means) and their
    :func:`global_covariance`.
    """
    n = cal.n_poses
    sensors = {
        s: sensor
        for s, sensor in (("accel", cal.accel), ("mag", cal.mag))
        if sensor is not None and (cal.gravity if s == "accel" else cal.magnetic) is not None
    }
    if not sensors:
        raise ValueError("the calibration has no sensor with a reference field")
    if counts is None:
        rows = [r for r in cal.poses if all(f"{s}_samples" in r for s in sensors)]
        if len(rows) != n:
            raise ValueError(
                f"cal.poses lists samples for {len(rows)} poses but the fit has {n}; "
                "pass counts={'accel': ..., 'mag': ...}"
            )
        counts = {s: [int(r[f"{s}_samples"]) for r in rows] for s in sensors}
    magnitudes = {"accel": cal.gravity_norm or 1.0, "mag": cal.field_strength or 1.0}
    stats_of: dict[str, SensorStats | None] = {"accel": None, "mag": None}
    for s, sensor in sensors.items():
        c = np.asarray(counts[s], dtype=np.int64)
        if c.shape != (n,) or np.any(c < 1):
            raise ValueError(f"counts[{s!r}] must hold {n} sample counts of at least 1")
        stats_of[s] = SensorStats(
            means=np.zeros((n, 3)),
            counts=c,
            cov=np.array(sensor.noise_cov, dtype=float),
            dof=int(c.sum() - n),
            pose_var=float(sensor.pose_noise_std) ** 2,
        )

    def symmetric(K: Array) -> bool:
        return bool(np.allclose(K, K.T, rtol=0, atol=1e-9 * np.abs(K).max()))

    frame = next((s for s in sensors if symmetric(sensors[s].gain)), None)
    if frame is None:
        raise ValueError(
            "no sensor's gain is symmetric, so the calibration is not in fieldcal's gauge; "
            "pass the calibration as fitted (before an axis map was folded into the frame sensor)"
        )
    problem = build_problem(PoseStats(stats_of["accel"], stats_of["mag"]), frame)
    dip = 0.0
    if cal.magnetic is not None and problem.joint:
        dip = float(np.arctan2(cal.magnetic[2], cal.magnetic[0]))
    rotations = np.array(cal.rotations)
    if not problem.joint and "mag" in sensors:
        # one magnetometer: the model's field is north, (1, 0, 0); the calibration's may not be
        h = np.asarray(cal.magnetic, dtype=float) / magnitudes["mag"]
        rotations = rotations @ _world_turn(h, np.array([1.0, 0.0, 0.0])).T
    state = State(
        {s: np.array(sensors[s].gain) * magnitudes[s] for s in sensors},
        {s: np.array(sensors[s].bias) for s in sensors},
        dip,
        rotations,
    )
    # the Fisher matrix JᵀJ does not depend on the means (zeros stand in for them)
    ne = normal_equations(problem, state, residuals(problem, state))
    return ne, global_covariance(ne)


def pose_rotation_covariance(
    cal: Calibration, counts: Mapping[str, ArrayLike] | None = None
) -> Array:
    """Cramér-Rao covariance (3N, 3N) of the poses' rotations.

    Each pose's rotation is perturbed in the body frame, ``R_i ← exp([δ_i]×) R_i`` (as the
    optimiser updates it); the result is the covariance of the stacked ``δ = (δ_0, …, δ_{N−1})``
    (radians), the pose block of the inverse Fisher matrix: ``U_i⁻¹ δ_ij + Y_i C Y_jᵀ`` with
    ``Y_i = U_i⁻¹ W_i`` and ``C`` the globals' covariance, so the poses' shared errors (through
    the gains and the dip) are included. Its 3x3 diagonal blocks are each pose's own. With one
    sensor the rotation about its field is not determined: the covariance then holds the two
    tilt angles only (zero along ``R_i f``), which is what the field's direction in the body
    frame, ``R_i f``, needs: its covariance is ``X C Xᵀ`` with ``X = blockdiag(−[R_i f]×)``.
    :func:`pose_rotation_factors` gives the same in its structure (linear in N).

    Parameters
    ----------
    cal : Calibration
        A calibration with its noise model: ``noise_cov`` and ``pose_noise_std`` of each sensor
        (those of :func:`fieldcal.calibrate`), in fieldcal's gauge (the frame sensor's gain
        symmetric).
    counts : mapping, optional
        Samples per pose of each sensor (``{"accel": (N,), "mag": (N,)}``); by default the
        ``accel_samples`` / ``mag_samples`` entries of ``cal.poses`` for the poses in the fit.

    Returns
    -------
    (3N, 3N) array
        Covariance of the poses' small-angle rotation errors, body frame, radians².

    Raises
    ------
    ValueError
        When the counts are missing or wrong, or neither sensor's gain is symmetric (no
        fieldcal gauge to evaluate it in).
    """
    ne, (C, Uinv, Y, _) = _pose_information(cal, counts)
    n = len(Uinv)
    full = np.einsum("iag,gh,jbh->iajb", Y, C, Y)
    poses = np.arange(n)
    full[poses, :, poses, :] += Uinv  # each pose's own block (shape (n, 3, 3))
    if ne.basis is not None:  # one sensor: the two tilt angles, back in the body frame
        full = np.einsum("ika,iajb,jlb->ikjl", ne.basis, full, ne.basis)
    out: Array = full.reshape(3 * n, 3 * n)
    return 0.5 * (out + out.T)


def _world_turn(a: Array, b: Array) -> Array:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    v = np.cross(a, b)
    c = float(a @ b)
    if np.linalg.norm(v) < 1e-15:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    V = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    out: Array = np.eye(3) + V + V @ V / (1.0 + c)
    return out
