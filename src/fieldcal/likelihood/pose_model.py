"""The joint problem of Eq. 8 as a least-squares problem: parameters, residuals, Jacobians.

Whitened residual of sensor ``s`` in pose ``i`` (Eq. 6, 8)::

    e_s[i] = sqrt(Δ_s[i]) L_s⁻¹ (K_s R_i f_s + b_s − μ̂_s[i]),     Σ_s = L_s L_sᵀ

so that Eq. 8's ``J = Σ ‖e‖²`` (twice the usual least-squares cost ``½‖e‖²``).

Parameters. The 22 globals (joint problem) are, in order: the frame sensor's symmetric gain
(6 entries, Sec. 4.3), its bias (3), the other sensor's full gain (9), its bias (3) and the dip
(1, radians); the accelerometer comes first whichever sensor fixes the frame. Rotations are
updated multiplicatively, ``R_i ← exp(ω_i^) R_i`` (a perturbation in the body frame), 3 angles
per pose. With one sensor the rotation about its field is unobservable: each pose then has
2 angles, a basis of the plane orthogonal to ``R_i f``.

Temperature (``stats.temperature`` with orders, ``docs/methods/temperature.md``): the bias of
sensor ``s`` in pose ``i`` is ``b_s + Σ_k c_sk (T_i − T_ref)^k``; the coefficients ``c_sk`` (3
per order, k-major) are globals after the dip, so a problem without them is laid out, and
computed, exactly as before.
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..geometry.frames import GRAVITY, magnetic_reference
from ..stats.pose_stats import PoseStats

Array = NDArray[np.float64]
Index = NDArray[np.intp]
#: the types of two memo entries, built once (a subscripted type in a hot function costs µs)
_ArrayPair = tuple[Array, Array]
_IndexPair = tuple[Index, Index]

SENSORS = ("accel", "mag")
#: Entries (j, k) of a symmetric gain kept as parameters, row-major upper triangle.
SYM_ENTRIES = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _sym_map() -> Array:
    """(9, 6) matrix taking the 6 symmetric parameters to the row-major 3x3 gain."""
    T = np.zeros((9, 6))
    for p, (j, k) in enumerate(SYM_ENTRIES):
        T[3 * j + k, p] = T[3 * k + j, p] = 1.0
    return T


SYM_MAP = _sym_map()
#: The parameter of each row-major entry of a symmetric gain: ``d[SYM_INDEX]`` is ``SYM_MAP @ d``
SYM_INDEX = np.argmax(SYM_MAP, axis=1)
SYM_INDEX.setflags(write=False)
# Levi-Civita symbol: (K hat(v))[a, k] = -Σ K[a, j] ε[j, k, l] v[l]
_EPS = np.zeros((3, 3, 3))
for _a, _b, _c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _EPS[_a, _b, _c], _EPS[_a, _c, _b] = 1.0, -1.0
#: ``v @ HAT_T`` is ``hat(v)ᵀ = −hat(v)`` row-major (9 entries): one product for a batch
HAT_T = _EPS.transpose(2, 0, 1).reshape(3, 9).copy()
HAT_T.setflags(write=False)
#: ``ω @ HAT`` is ``hat(ω)`` row-major
HAT = -HAT_T
HAT.setflags(write=False)
_I9 = np.eye(3).ravel()
_I9.setflags(write=False)


@dataclass(frozen=True)
class Problem:
    """Whitened data and the parameter layout of one calibration problem."""

    sensors: tuple[str, ...]
    frame: str
    n: int
    linv: dict[str, Array]  # (N, 3, 3): L_si⁻¹, whitening each pose mean
    means: dict[str, Array]  # (N, 3): μ̂_s[i]
    # The closed-form starts whiten with one matrix per sensor and weigh the poses:
    # C_si ≈ C_s / w_si (exact, with w = Δ, when there is no pose-level noise).
    start_chol: dict[str, Array]  # (3, 3)
    start_weight: dict[str, Array]  # (N,)
    start_mu: dict[str, Array]  # (N, 3): means whitened by start_chol
    gain_slice: dict[str, slice]
    bias_slice: dict[str, slice]
    dip_index: int | None
    n_global: int
    #: (N, K): ``(T_i − T_ref)^k``, k = 1..K (the highest order of any sensor); None without
    temp_powers: Array | None = None
    #: each sensor with temperature terms: its coefficients' slice of the globals
    temp_slice: dict[str, slice] = dataclass_field(default_factory=dict)
    #: derived once per problem (e.g. the Cholesky factors back from ``linv``)
    memo: dict[object, object] = dataclass_field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @property
    def joint(self) -> bool:
        return self.dip_index is not None

    @property
    def rot_dim(self) -> int:
        return 3 if self.joint else 2

    @property
    def dof(self) -> int:
        """Observations minus parameters: ``3N − 22`` joint, ``N − 9`` for one sensor."""
        return 3 * len(self.sensors) * self.n - self.rot_dim * self.n - self.n_global

    def symmetric(self, sensor: str) -> bool:
        return sensor == self.frame

    def temp_order(self, sensor: str) -> int:
        """The order of ``sensor``'s bias polynomial in temperature (0: none)."""
        sl = self.temp_slice.get(sensor)
        return 0 if sl is None else (sl.stop - sl.start) // 3


@dataclass
class State:
    """Current estimate: gains, biases, dip (radians) and world→body rotations."""

    gains: dict[str, Array]
    biases: dict[str, Array]
    dip: float
    rotations: Array
    #: (K, 3) temperature coefficients per sensor with temperature terms (missing: zeros)
    temps: dict[str, Array] = dataclass_field(default_factory=dict)

    def copy(self) -> State:
        return State(
            {k: v.copy() for k, v in self.gains.items()},
            {k: v.copy() for k, v in self.biases.items()},
            float(self.dip),
            self.rotations.copy(),
            {k: v.copy() for k, v in self.temps.items()},
        )

    def temp(self, problem: Problem, sensor: str) -> Array:
        """(K, 3) coefficients of ``sensor`` for ``problem``'s order, zero-padded or cut."""
        order = problem.temp_order(sensor)
        out = np.zeros((order, 3))
        given = self.temps.get(sensor)
        if given is not None and order:
            k = min(order, len(given))
            out[:k] = given[:k]
        return out


def build_problem(stats: PoseStats, frame: str) -> Problem:
    """Whiten the pose means (Eq. 5) with their covariances (Eq. 7 plus pose-level noise) and
    lay out the parameters. Built once per statistics and frame (kept in ``stats.memo``): the
    fit and the evaluation of its result share it."""
    key = ("mle.problem", frame)
    cached = stats.memo.get(key)
    if isinstance(cached, Problem):
        return cached
    problem = _build_problem(stats, frame)
    stats.memo[key] = problem
    return problem


def _build_problem(stats: PoseStats, frame: str) -> Problem:
    sensors = tuple(stats.sensors)
    if frame not in sensors:
        frame = sensors[0]
    linv, means, start_chol, start_weight, start_mu, gs, bs = {}, {}, {}, {}, {}, {}, {}
    # every factorisation in one call: the N pose covariances and the reference C_s of each
    # sensor stacked (S, N + 1, 3, 3), Cholesky factors and their inverses
    st = [stats.sensor(s) for s in sensors]
    n = stats.n_poses
    mats = np.empty((len(st), n + 1, 3, 3))
    for k, x in enumerate(st):
        mats[k, :n] = x.mean_covariances()
        mats[k, n] = x.cov if x.cov is not None else np.eye(3) * x.pose_var
    mus = np.stack([np.asarray(x.means, dtype=float) for x in st])
    chol = np.linalg.cholesky(mats)
    inverse = np.linalg.inv(chol)
    all_linv, all_chol, ref_linv = inverse[:, :n], chol[:, n], inverse[:, n]
    # w_si = 3 / tr(C_s⁻¹ C_si), C_s⁻¹ = L⁻ᵀ L⁻¹ (symmetric: the trace is an entrywise sum)
    ref_inv = ref_linv.transpose(0, 2, 1) @ ref_linv
    all_weight = 3.0 / np.vecdot(ref_inv.reshape(-1, 1, 9), mats[:, :n].reshape(len(st), n, 9))
    all_mu = mus @ ref_linv.transpose(0, 2, 1)  # L_s⁻¹ μ̂_si
    offset = 0
    for k, s in enumerate(sensors):
        linv[s], means[s], start_chol[s] = all_linv[k], mus[k], all_chol[k]
        start_weight[s], start_mu[s] = all_weight[k], all_mu[k]
        size = 6 if s == frame else 9
        gs[s] = slice(offset, offset + size)
        bs[s] = slice(offset + size, offset + size + 3)
        offset += size + 3
    dip_index = offset if len(sensors) == 2 else None
    n_global = offset + (1 if dip_index is not None else 0)
    powers, temp_slice = None, {}
    temperature = stats.temperature
    if temperature is not None and temperature.orders:
        for s in sensors:
            k = temperature.order(s)
            if k:
                temp_slice[s] = slice(n_global, n_global + 3 * k)
                n_global += 3 * k
        powers = temperature.powers(max(temperature.order(s) for s in sensors))
    return Problem(
        sensors,
        frame,
        stats.n_poses,
        linv,
        means,
        start_chol,
        start_weight,
        start_mu,
        gs,
        bs,
        dip_index,
        n_global,
        powers,
        temp_slice,
    )


def field(problem: Problem, sensor: str, dip: float) -> Array:
    """Reference field ``f_s`` in the world frame (Eq. 2 with unit magnitudes)."""
    if sensor == "accel":
        return GRAVITY
    if problem.joint:
        return magnetic_reference(dip)
    return np.array([1.0, 0.0, 0.0])  # magnetometer alone: its field defines north


def _whiten(linv: Array, x: Array) -> Array:
    """``L_i⁻¹ x_i`` for a batch of vectors (M, 3) (one product; :mod:`.stacked` the same)."""
    out: Array = (linv @ x[:, :, None])[:, :, 0]
    return out


def bias_drift(problem: Problem, state: State, sensor: str) -> Array | None:
    """(N, 3): ``Σ_k c_k (T_i − T_ref)^k`` of ``sensor`` in each pose, None without terms."""
    order = problem.temp_order(sensor)
    if not order or problem.temp_powers is None:
        return None
    return problem.temp_powers[:, :order] @ state.temp(problem, sensor)


def stacked_data(problem: Problem) -> tuple[Array, Array]:
    """Both sensors' whitening ``L⁻¹`` (S, N, 3, 3) and means (S, N, 3) stacked, once per
    problem: the residuals and the Jacobian then take one product for all sensors."""
    cached = problem.memo.get("stacked")
    if cached is None:
        linv = np.stack([problem.linv[s] for s in problem.sensors])
        means = np.stack([problem.means[s] for s in problem.sensors])
        cached = problem.memo["stacked"] = (linv, means)
    return cast(_ArrayPair, cached)


def rotated_fields(problem: Problem, state: State) -> Array:
    """(N, 3, S + 1 or S): ``R_i f_s`` of each sensor, then (joint problems) ``R_i dh/d(dip)``:
    one product (:mod:`.stacked` the same) with the columns GRAVITY,
    magnetic_reference(dip), magnetic_derivative(dip) of frames.py."""
    if problem.joint:
        c, s = np.cos(state.dip), np.sin(state.dip)
        g = GRAVITY
        F = np.array([[g[0], c, -s], [g[1], 0.0, 0.0], [g[2], s, c]])
    else:
        F = field(problem, problem.sensors[0], state.dip)[:, None]
    out: Array = state.rotations @ F
    return out


def model_readings(problem: Problem, state: State, VV: Array | None = None) -> Array:
    """(S, N, 3): ``K_s R_i f_s``, the model's field in each sensor's raw frame, both sensors
    in one product (``VV`` from :func:`rotated_fields` when the caller has it)."""
    S = len(problem.sensors)
    if VV is None:
        VV = rotated_fields(problem, state)
    K = np.empty((S, 3, 3))  # faster than np.array of a list
    for k, s in enumerate(problem.sensors):
        K[k] = state.gains[s].T
    out: Array = VV[:, :, :S].transpose(2, 0, 1) @ K
    return out


def raw_residuals(problem: Problem, state: State, readings: Array | None = None) -> Array:
    """(S, N, 3): ``K_s R_i f_s + b_s (+ drift) − μ̂_s[i]`` in raw units (Eq. 6 before the
    whitening); ``readings`` from :func:`model_readings` when the caller has them (turned into
    the residuals in place)."""
    _, means = stacked_data(problem)
    raw = model_readings(problem, state) if readings is None else readings
    b = np.empty((len(raw), 1, 3))
    for k, s in enumerate(problem.sensors):
        b[k, 0] = state.biases[s]
    raw += b
    raw -= means
    if problem.temp_slice:
        for k, s in enumerate(problem.sensors):
            drift = bias_drift(problem, state, s)
            if drift is not None:
                raw[k] += drift
    return raw


def whiten(problem: Problem, raw: Array) -> Array:
    """Whitened residuals (N, 3·S), accelerometer block first, of :func:`raw_residuals`:
    ``L_si⁻¹ r_si`` (Eq. 6, 8)."""
    linv, _ = stacked_data(problem)
    w = (linv @ raw[..., None])[..., 0]
    if len(w) == 1:
        return cast(Array, w[0])
    return w.transpose(1, 0, 2).reshape(problem.n, -1)


def residuals(problem: Problem, state: State, VV: Array | None = None) -> Array:
    """Whitened residuals (N, 3·#sensors), accelerometer block first (``VV`` from
    :func:`rotated_fields` when the caller has it: the Jacobian at the state uses it too)."""
    return whiten(problem, raw_residuals(problem, state, model_readings(problem, state, VV)))


def rotation_basis(problem: Problem, state: State, VV: Array | None = None) -> Array | None:
    """(N, 3, 2) tangent basis orthogonal to ``R_i f`` for one-sensor problems, else None
    (``VV`` from :func:`rotated_fields` when the caller has it)."""
    if problem.joint:
        return None
    v = (rotated_fields(problem, state) if VV is None else VV)[:, :, 0]
    helper = np.eye(3)[np.argmin(np.abs(v), axis=1)]
    b1 = np.cross(v, helper)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    b2 = np.cross(v, b1)
    return np.stack([b1, b2], axis=-1)


def jacobians(problem: Problem, state: State, basis: Array | None) -> tuple[Array, Array]:
    """Analytic Jacobians of :func:`residuals`: per-pose rotation block (N, m, 3 or 2) and
    global block (N, m, G), with m = 3·#sensors rows per pose."""
    J = jacobian(problem, state, basis)
    P = J.shape[-1] - problem.n_global - 1
    return J[..., :P], J[..., P:-1]


def jacobian(problem: Problem, state: State, basis: Array | None, VV: Array | None = None) -> Array:
    """:func:`jacobians` in one array (N, m, P + G + 1): rotation columns, globals and a last
    column left zero (the residuals' place in :func:`.levenberg.normal_equations`); ``VV``
    from :func:`rotated_fields` when the caller has it."""
    P = 3 if basis is None else basis.shape[-1]
    key = ("jacobian", P)
    template = problem.memo.get(key)
    if template is None:  # the constant columns (biases, temperature terms), once
        template = np.zeros((problem.n, 3 * len(problem.sensors), P + problem.n_global + 1))
        fill_constant(problem, template, problem.linv, problem.temp_powers)
        template.setflags(write=False)
        problem.memo[key] = template
    J = cast(Array, template).copy()
    linv, _ = stacked_data(problem)
    S = len(problem.sensors)
    K = np.empty((S, 1, 3, 3))
    for k, s in enumerate(problem.sensors):
        K[k, 0] = state.gains[s]
    Kw = linv @ K
    if VV is None:
        VV = rotated_fields(problem, state)
    v = VV[:, :, :S].transpose(2, 0, 1)
    fill_jacobian(problem, J, linv, Kw, v, VV[:, :, 2] if problem.joint else None, basis)
    return J


def fill_constant(problem: Problem, J: Array, linv: dict[str, Array], powers: Array | None) -> None:
    """Write the Jacobian's constant columns (biases, temperature coefficients) of M poses
    into ``J`` (M, m, P + G + 1): they depend on the whitening and temperatures only."""
    g = J.shape[-1] - problem.n_global - 1
    for k, s in enumerate(problem.sensors):
        rows = slice(3 * k, 3 * k + 3)
        L = linv[s]
        bs = problem.bias_slice[s]
        J[:, rows, g + bs.start : g + bs.stop] = L
        order = problem.temp_order(s)
        if order and powers is not None:
            # d(Σ_k c_k d_i^k)/dc_k[j] = d_i^k e_j: coefficient (k, j) at 3k + j of the slice
            ts = problem.temp_slice[s]
            Pk = powers[:, :order]
            J[:, rows, g + ts.start : g + ts.stop] = (
                L[:, :, None, :] * Pk[:, None, :, None]
            ).reshape(-1, 3, 3 * order)


def fill_jacobian(
    problem: Problem,
    J: Array,
    linv: Array,
    Kw: Array,
    v: Array,
    dv: Array | None,
    basis: Array | None,
) -> None:
    """Write the analytic Jacobian's varying columns of M poses (of one problem or of many
    stacked, flat) into ``J`` (M, m, P + G + 1), whose constant columns :func:`fill_constant`
    wrote: ``[:P]`` the rotations' (3 or, with a ``basis`` (M, 3, 2), 2), the gains' and the
    dip's. ``linv`` and ``Kw = L⁻¹K`` (S, M, 3, 3), ``v = R f`` (S, M, 3), sensors stacked
    in the problem's order (one product for all of them); ``dv = R dh/d(dip)`` (M, 3)."""
    M, S = len(J), len(problem.sensors)
    P = 3 if basis is None else basis.shape[-1]
    J4 = J.reshape(M, S, 3, J.shape[-1])  # a view: rows of sensor k at [:, k]
    # d(K exp(ω^) R f)/dω = −K hat(R f) = K hat(v)ᵀ: hat built by one product
    hat_t = (v @ HAT_T).reshape(S, M, 3, 3)
    if basis is None:
        np.matmul(Kw, hat_t, out=J4[..., :3].transpose(1, 0, 2, 3))
    else:
        J4[..., :P] = (Kw @ hat_t @ basis).transpose(1, 0, 2, 3)
    # d(K v)/dK[j, k] = e_j v_k, for every sensor in one product
    outer = (linv[..., None] * v[:, :, None, None, :]).reshape(S, M, 3, 9)
    g = P  # the globals' first column
    for k, s in enumerate(problem.sensors):
        gs = problem.gain_slice[s]
        gain = J4[:, k, :, g + gs.start : g + gs.stop]
        if problem.symmetric(s):
            np.matmul(outer[k], SYM_MAP, out=gain)
        else:
            gain[...] = outer[k]
        if s == "mag" and dv is not None and problem.dip_index is not None:
            d = g + problem.dip_index
            np.matmul(Kw[k], dv[:, :, None], out=J4[:, k, :, d : d + 1])


def exp_map(omega: Array) -> Array:
    """Rodrigues' formula for a batch (M, 3), ``R = (1 − bθ²) I + a ω^ + b ωωᵀ``; the same as
    :func:`fieldcal.rotations.exp_so3`, written in a few batched operations because it runs
    every LM step (also for many problems stacked, :mod:`.stacked`)."""
    th2 = np.vecdot(omega, omega)
    if th2.min() >= 1e-8:  # no small angle (and no NaN): the series is not needed
        th = np.sqrt(th2)
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / (th * th)
    else:
        small = th2 < 1e-8
        th = np.sqrt(np.where(small, 1.0, th2))
        a = np.where(small, 1.0 - th2 / 6.0, np.sin(th) / th)
        b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / (th * th))
    d = 1.0 - b * th2
    R = (b[:, None] * omega)[:, :, None] * omega[:, None, :]
    R += ((a[:, None] * omega) @ HAT + d[:, None] * _I9).reshape(-1, 3, 3)
    return R


def apply_step(problem: Problem, state: State, dg: Array, dp: Array, basis: Array | None) -> State:
    """Additive update of the globals, multiplicative ``exp(ω^) R_i`` update of the rotations."""
    gain_index, bias_index = _global_index(problem)
    dK, db = dg[gain_index], dg[bias_index]  # (S, 3, 3), (S, 3): every sensor in one gather
    gains, biases, temps = {}, {}, {}
    for k, s in enumerate(problem.sensors):
        gains[s] = state.gains[s] + dK[k]
        biases[s] = state.biases[s] + db[k]
        if s in problem.temp_slice:
            temps[s] = state.temp(problem, s) + dg[problem.temp_slice[s]].reshape(-1, 3)
    dip = state.dip + (dg[problem.dip_index] if problem.dip_index is not None else 0.0)
    omega = dp if basis is None else np.einsum("nij,nj->ni", basis, dp)
    return State(gains, biases, float(dip), exp_map(omega) @ state.rotations, temps)


def _global_index(problem: Problem) -> tuple[Index, Index]:
    """Positions in the globals of each sensor's gain (S, 3, 3), row-major, a symmetric gain's
    entries from its 6 parameters (``SYM_INDEX``), and of its bias (S, 3); once per problem."""
    cached = problem.memo.get("global_index")
    if cached is None:
        gain = np.array(
            [
                (
                    problem.gain_slice[s].start
                    + (SYM_INDEX if problem.symmetric(s) else np.arange(9))
                ).reshape(3, 3)
                for s in problem.sensors
            ]
        )
        bias = np.array([np.arange(3) + problem.bias_slice[s].start for s in problem.sensors])
        cached = problem.memo["global_index"] = (gain, bias)
    return cast(_IndexPair, cached)


def sensor_costs(problem: Problem, e: Array) -> dict[str, float]:
    """Each sensor's part of Eq. 8's J."""
    return {s: float(np.sum(e[:, 3 * k : 3 * k + 3] ** 2)) for k, s in enumerate(problem.sensors)}


def state_from_calibration(problem: Problem, cal: Calibration) -> State:
    """The optimiser's state for any calibration in fieldcal's gauge."""
    gains = {s: np.array(cal.sensor(s).gain) for s in problem.sensors}
    biases = {s: np.array(cal.sensor(s).bias) for s in problem.sensors}
    gains[problem.frame] = 0.5 * (gains[problem.frame] + gains[problem.frame].T)
    dip = np.radians(cal.dip_deg or 0.0) if problem.joint else 0.0
    temps = {
        s: np.array(model.coefficients)
        for s in problem.temp_slice
        if (model := cal.sensor(s).temperature) is not None
    }
    return State(gains, biases, float(dip), np.array(cal.rotations), temps)
