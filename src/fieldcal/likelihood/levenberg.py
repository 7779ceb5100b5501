"""Levenberg-Marquardt on SO(3)^N × R^G with the pose blocks eliminated (Schur complement).

Each pose's residuals depend on its own rotation (3 angles, 2 with one sensor) and on the G
global parameters only, so the Gauss-Newton matrix is an arrow matrix::

    [ U   W ]   U = blockdiag(U_i)  (N blocks of 3x3)
    [ Wᵀ  V ]   V: G x G

and the damped system is solved, as in bundle adjustment, through the reduced (Schur) system
``S = V − Σ_i W_iᵀ U_i⁻¹ W_i`` of size G: O(N) work per iteration, all batched over poses.
At λ = 0, ``S⁻¹`` is the covariance of the globals (the Cramér-Rao bound, see
:mod:`.uncertainty`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesv as _dgesv

from .marquardt import Schedule, minimise
from .pose_model import (
    Problem,
    State,
    apply_step,
    jacobian,
    residuals,
    rotated_fields,
    rotation_basis,
)

Array = NDArray[np.float64]


@dataclass
class Normal:
    """Blocks of the Gauss-Newton system ``JᵀJ`` and gradient ``Jᵀe`` at one point.

    Built as two products (:func:`gram`): ``UWg = Jpᵀ [Jp | Jg | e]`` per pose and
    ``Vx = [Jg | e]ᵀ [Jg | e]``; the blocks are views of them."""

    UWg: Array  # (N, p, p + G + 1): [U | W | gp]
    Vx: Array  # (G + 1, G + 1): [[V, gg], [ggᵀ, J]]
    J: Array  # (N, m, p + G + 1): [Jp | Jg | e]
    basis: Array | None

    @property
    def U(self) -> Array:  # noqa: N802
        """(N, p, p)"""
        return self.UWg[..., : self.p]

    @property
    def W(self) -> Array:  # noqa: N802
        """(N, p, G)"""
        return self.UWg[..., self.p : -1]

    @property
    def V(self) -> Array:  # noqa: N802
        """(G, G)"""
        return self.Vx[..., :-1, :-1]

    @property
    def gp(self) -> Array:
        """(N, p)"""
        return self.UWg[..., -1]

    @property
    def gg(self) -> Array:
        """(G,)"""
        return self.Vx[..., :-1, -1]

    @property
    def Jp(self) -> Array:  # noqa: N802
        return self.J[..., : self.p]

    @property
    def Jg(self) -> Array:  # noqa: N802
        return self.J[..., self.p : -1]

    @property
    def p(self) -> int:
        return int(self.UWg.shape[-2])


def gram(J: Array, p: int) -> tuple[Array, Array]:
    """``Jpᵀ J`` per pose and the Gram matrix of the globals' and residuals' columns, for
    ``J`` (..., N, m, p + G + 1) of one problem or many stacked (the same products)."""
    UWg: Array = J[..., :p].swapaxes(-1, -2) @ J
    flat = J.reshape(*J.shape[:-3], -1, J.shape[-1])[..., p:]
    Vx: Array = flat.swapaxes(-1, -2) @ flat
    return UWg, Vx


def normal_equations(problem: Problem, state: State, e: Array, VV: Array | None = None) -> Normal:
    """The blocks at ``state`` with residuals ``e`` (``VV``: :func:`.pose_model.rotated_fields`
    at the state when the caller has it, as the solver has from the residuals)."""
    if VV is None:
        VV = rotated_fields(problem, state)
    basis = rotation_basis(problem, state, VV)
    J = jacobian(problem, state, basis, VV)
    J[..., -1] = e
    UWg, Vx = gram(J, J.shape[-1] - problem.n_global - 1)
    return Normal(UWg, Vx, J, basis)


def _adjugate_index() -> NDArray[np.intp]:
    """(4, 9) positions in a row-major 3x3 block of the four factors of each entry of its
    adjugate (row-major): ``adj[j, i] = A[i1, j1] A[i2, j2] − A[i1, j2] A[i2, j1]`` with
    ``i1, i2 = i + 1, i + 2`` (mod 3), the cofactor of ``A[i, j]`` (cyclic indices carry the
    sign)."""
    out = np.empty((4, 9), dtype=np.intp)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            out[:, 3 * j + i] = (3 * i1 + j1, 3 * i2 + j2, 3 * i1 + j2, 3 * i2 + j1)
    return out


_ADJ3 = _adjugate_index()
#: 2x2 adjugate ``[[d, −b], [−c, a]]`` of ``[a, b, c, d]``: a gather and a sign
_ADJ2 = np.array([3, 1, 2, 0])
_SIGN2 = np.array([1.0, -1.0, -1.0, 1.0])


def damped_inverse(U: Array, lam: float | Array) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Inverses of the damped pose blocks (Marquardt: ``λ`` times the diagonal, plus a floor of
    1e-12), the damping added and which problems have a singular block (an exact zero
    determinant, where ``np.linalg.inv`` raises; its inverse is NaN). ``U`` (..., N, p, p) of
    one problem or many stacked with ``lam`` shaped to broadcast (B, 1, 1).

    The blocks are 3x3 (2x2 with one sensor): the adjugate over the determinant (a gather and a
    few products for all of them) costs less than ``np.linalg.inv``'s wrapper."""
    p = U.shape[-1]
    lead = U.shape[:-2]
    # the blocks flat (M, p²), a copy to damp: U is a view of [U | W | gp], which reshape
    # copies; a contiguous U (a caller's own array) is copied explicitly
    damped: Array = U.reshape(-1, p * p)
    if np.may_share_memory(damped, U):
        damped = damped.copy()
    diagonal = damped[:, :: p + 1].reshape(*lead, p)
    damp_p: Array = diagonal * (lam + 1e-12)
    damp_p += 1e-12
    diagonal += damp_p
    if p == 3:
        F = damped[:, _ADJ3]  # (M, 4, 9)
        adj = F[:, 0] * F[:, 1]
        adj -= F[:, 2] * F[:, 3]
    else:
        adj = damped[:, _ADJ2] * _SIGN2
    det: Array = np.vecdot(damped[:, :p], adj[:, ::p])  # the first row · its cofactors
    singular = np.zeros(lead[:-1], dtype=bool)
    if np.count_nonzero(det) < det.size:
        zero = det == 0.0
        singular = zero.reshape(lead).any(axis=-1)
        det = np.where(zero, np.nan, det)  # NaN, not a division warning
    adj /= det[:, None]
    return adj.reshape(U.shape), damp_p, singular


def schur(
    Uinv: Array, UWg: Array, Vx: Array, lam: float | Array
) -> tuple[Array, Array, Array, Array]:
    """``[Y | z] = U⁻¹ [W | gp]``, the damped reduced matrix S (Schur complement), its right
    side ``Wᵀz − gg`` and the damping added to the globals' diagonal (one problem, or many
    stacked with ``lam`` shaped (B, 1)). S is a view of a (G, G + 1) array."""
    p = UWg.shape[-2]
    G = Vx.shape[-1] - 1
    lead = UWg.shape[:-3]
    Wg = UWg[..., p:]
    Yz: Array = Uinv @ Wg
    WtYz = Wg[..., :G].reshape(*lead, -1, G).swapaxes(-1, -2) @ Yz.reshape(*lead, -1, G + 1)
    SS: Array = Vx[..., :G, :] - WtYz  # [S | gg − Wᵀz] before the damping
    dV = Vx.reshape(*lead, (G + 1) ** 2)[..., :: G + 2][..., :G]
    damp_g: Array = (lam + 1e-12) * dV + 1e-12
    SS.reshape(*lead, G * (G + 1))[..., :: G + 2] += damp_g
    rhs: Array = -SS[..., G]
    return Yz, SS[..., :G], rhs, damp_g


def reduce(ne: Normal, lam: float) -> tuple[Array, Array, Array, Array, Array]:
    """Damped pose blocks' inverses, ``U⁻¹W``, the reduced matrix S (Schur complement) and the
    damping added to the pose and global diagonals (Marquardt: proportional to the diagonal)."""
    Uinv, damp_p, singular = damped_inverse(ne.U, lam)
    if singular:
        raise np.linalg.LinAlgError("Singular matrix")
    Yz, S, _, damp_g = schur(Uinv, ne.UWg, ne.Vx, lam)
    return Uinv, Yz[..., :-1], S, damp_p, damp_g


def predicted(dg: Array, dp: Array, gg: Array, gp: Array, damp_g: Array, damp_p: Array) -> Array:
    """The decrease of J the linearised model predicts for the step (one problem or many):
    ``J(0) − J_lin(δ) = −2δᵀg − δᵀHδ = δᵀ(Λδ − g)`` since ``(H + Λ)δ = −g``."""
    lead = dg.shape[:-1]
    tp = damp_p * dp - gp
    out: Array = np.vecdot(damp_g * dg - gg, dg) + np.vecdot(
        tp.reshape(*lead, -1), dp.reshape(*lead, -1)
    )
    return out


def solve_step(ne: Normal, lam: float) -> tuple[Array, Array, float]:
    """The damped step and the decrease of J it predicts (linearised model)."""
    Uinv, damp_p, singular = damped_inverse(ne.U, lam)
    if singular:
        raise np.linalg.LinAlgError("Singular matrix")
    Yz, S, rhs, damp_g = schur(Uinv, ne.UWg, ne.Vx, lam)
    dg = _solve(S, rhs)
    ext = np.empty(len(dg) + 1)
    ext[:-1] = dg
    ext[-1] = 1.0
    dp = Yz @ ext  # Y dg + z
    dp = -dp
    # :func:`predicted` of one problem, with 1-D dot products (no batch axes to handle)
    tp = damp_p * dp - ne.gp
    pred = (damp_g * dg - ne.gg) @ dg + tp.ravel() @ dp.ravel()
    return dg, dp, float(pred)


def _solve(S: Array, rhs: Array) -> Array:
    """``S⁻¹ rhs`` for the small symmetric reduced system: LAPACK's LU directly (numpy's
    wrapper costs more than the 22x22 solve itself); a singular S raises as numpy does."""
    _, _, x, info = _dgesv(S, rhs)
    if info > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return cast(Array, x)


def _cost(e: Array) -> float:
    """Eq. 8's J, ``Σ e²``."""
    flat = e.ravel()
    return float(flat @ flat)


@dataclass
class Result:
    state: State
    e: Array
    cost: float
    iterations: int
    converged: bool


#: ``(problem, state, max_iter, tol, lam, known_minimum) -> Result``: a service that steps
#: this thread's runs together with other threads' (:mod:`.fleet`), set per thread by it.
Service = Callable[[Problem, State, int, float, float, float | None], Result]
SERVICE: ContextVar[Service | None] = ContextVar("fieldcal_lm_service", default=None)


def levenberg_marquardt(
    problem: Problem,
    state: State,
    *,
    max_iter: int = 100,
    tol: float = 1e-10,
    lam: float = 1e-4,
    known_minimum: float | None = None,
) -> Result:
    """Minimise Eq. 8's J from ``state``.

    Stops when an accepted step lowers J by less than ``tol·(1 + J)``, or by less than 1e-8 J
    with the linear model predicting the decrease to 10 %: with Gauss-Newton's quadratic
    convergence the next step would change J by far less than anything statistically
    meaningful (J is a χ² variate of size ~dof).

    ``known_minimum``: the J of a minimum already found from another start. Once the iterates
    are in Gauss-Newton's quadratic regime and the linear model predicts that very value, this
    start is heading for the same minimum and is abandoned (saves its last iterations).

    In a thread of a :class:`~.fleet.Fleet` (``fieldcal.calibrate_many``) the run is handed to
    the fleet, which steps it together with the other threads' runs (:mod:`.lockstep`): the
    result is the same (to rounding; bit for bit with the BLAS we test on).
    """
    service = SERVICE.get()
    if service is not None and not many_poses(problem):  # thousands: rules of their own
        return service(problem, state, max_iter, tol, lam, known_minimum)
    return solve_alone(problem, state, max_iter, tol, lam, known_minimum)


@dataclass
class _Point:
    """A state with the rotated fields and residuals its cost was computed from."""

    state: State
    VV: Array | None = None
    e: Array | None = None
    value: float | None = None  # J at the state, once computed


class _Reduced:
    """The pose problem for the shared loop (:func:`.marquardt.minimise`): the Gauss–Newton
    system with the poses eliminated (:func:`solve_step`). ``extrapolate``: a step that lowers
    J by more than :data:`EXTRAPOLATE` times the linear model's prediction is doubled while J
    keeps falling (at most 64 times): where Gauss–Newton converges linearly (below) its steps
    are several times too short, and a cost costs a fraction of a linearisation."""

    def __init__(self, problem: Problem, extrapolate: bool = False) -> None:
        self.problem = problem
        self.extrapolate = extrapolate

    def linearise(self, point: _Point) -> tuple[_Point, Normal]:
        assert point.e is not None and point.VV is not None  # its cost was computed
        return point, normal_equations(self.problem, point.state, point.e, point.VV)

    def level(self, linear: tuple[_Point, Normal]) -> float | None:
        return None

    def propose(self, linear: tuple[_Point, Normal], lam: float) -> tuple[_Point, float] | None:
        point, ne = linear
        dg, dp, pred = solve_step(ne, lam)
        # a NaN or inf in the step reaches the predicted decrease (its damping terms are sums
        # of positive weights times squares), so one scalar test stands for both arrays
        if not math.isfinite(pred) and not (np.isfinite(dg).all() and np.isfinite(dp).all()):
            return None
        trial = _Point(apply_step(self.problem, point.state, dg, dp, ne.basis))
        if not self.extrapolate or point.value is None:
            return trial, pred
        best = self.cost(trial)
        if not point.value - best > EXTRAPOLATE * pred:
            return trial, pred
        chosen, t = trial, 1.0
        while t < 64.0:
            t *= 2.0
            further = _Point(apply_step(self.problem, point.state, t * dg, t * dp, ne.basis))
            value = self.cost(further)
            if not value < best:
                break
            chosen, best = further, value
        # an extrapolated step is judged by what it achieved (ρ = 1): the linear model's
        # prediction is for the step it solved for, not for a multiple of it
        return chosen, (pred if chosen is trial else point.value - best)

    def cost(self, point: _Point) -> float:
        if point.value is not None:  # computed when the step was extrapolated
            return point.value
        point.VV = rotated_fields(self.problem, point.state)  # R_i f_s: residuals', Jacobian's
        point.e = residuals(self.problem, point.state, point.VV)
        point.value = _cost(point.e)
        return point.value


#: A step lowering J by more than this times the prediction is extrapolated
#: (:class:`_Reduced`): ρ stays near 1.9 through a linear convergence, near 1 otherwise.
EXTRAPOLATE = 1.5


#: From this many poses on (samples mode's one-sample poses by the thousand) a step lowering J
#: by less than ``SETTLED`` times J/dof (the variance's unit) ends the run: the misfit of a
#: real slow log is structured, its second-order terms add up over the poses, and Gauss–Newton
#: converges linearly there (ρ ≈ 1.9, each gain ~0.76 of the last), so ``tol``'s rule would
#: take some 25 iterations more for a change of J under 1e-3 of its unit: a few hundredths of
#: a standard error.
SETTLED_POSES = 2000
SETTLED = 1e-4


def many_poses(problem: Problem) -> bool:
    """Whether ``problem`` has :data:`SETTLED_POSES` or more poses: its own stopping rule and
    extrapolated steps (:func:`solve_alone`), so it is solved alone, never stepped with others
    (:mod:`.lockstep` keeps the rules of fewer poses)."""
    return problem.n >= SETTLED_POSES


class Nielsen(Schedule):
    """The pose methods' rules (Nielsen's damping): λ scaled by ``max(1/3, 1 − (2ρ − 1)³)``
    after a step taken, by a doubling factor after a refusal (beyond 1e16: given up). Stops
    when a step lowers J by less than ``tol·(1 + J)``, or by less than 1e-8 J with the linear
    model predicting the decrease to 10 % (Gauss–Newton's quadratic regime: the next step would
    change J by far less than anything statistically meaningful, J being a χ² variate of size
    ~dof), or when a refused step's prediction is below ``1e-3 tol (1 + J)`` at small λ, or
    (``settled`` > 0) when a step lowers J by less than ``settled · J``.
    ``known_minimum``: the J of a minimum already found from another start; once in the
    quadratic regime with the linear model predicting that very value, this start is heading
    for it and is abandoned."""

    def __init__(
        self, lam: float, tol: float, known_minimum: float | None, settled: float = 0.0
    ) -> None:
        super().__init__(lam)
        self.nu, self.tol, self.known, self.last_rho = 2.0, tol, known_minimum, 0.0
        self.settled = settled

    def done_before_trying(self, cost: float, predicted: float) -> bool:
        known = self.known
        return (
            known is not None
            and abs(self.last_rho - 1.0) < 0.1
            and abs(cost - predicted - known) <= 1e-6 * (1.0 + known)
        )

    def accepted(self, gain: float, rho: float, cost: float) -> bool:
        self.last_rho = rho
        self.lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        self.nu = 2.0
        quadratic = abs(rho - 1.0) < 0.1 and gain <= 1e-8 * cost
        settled = gain <= self.settled * cost
        return gain <= self.tol * (1.0 + cost) or quadratic or settled or cost < 1e-300

    def refused(self, predicted: float, cost: float) -> bool | None:
        if predicted <= self.tol * 1e-3 * (1.0 + cost) and self.lam < 1e-3:
            return True  # the model predicts nothing left to gain
        self.lam *= self.nu
        self.nu *= 2.0
        return False if self.lam > 1e16 else None


def solve_alone(
    problem: Problem,
    state: State,
    max_iter: int = 100,
    tol: float = 1e-10,
    lam: float = 1e-4,
    known_minimum: float | None = None,
) -> Result:
    """:func:`levenberg_marquardt` in this thread, whatever service is set: the shared loop
    (:func:`.marquardt.minimise`) with the rules of :class:`Nielsen`."""
    many = many_poses(problem)
    reduced = _Reduced(problem, extrapolate=many)
    start = _Point(state)
    cost = reduced.cost(start)
    settled = SETTLED / max(problem.dof, 1) if many else 0.0
    out = minimise(reduced, start, cost, Nielsen(lam, tol, known_minimum, settled), max_iter)
    assert out.point.e is not None
    return Result(out.point.state, out.point.e, out.cost, out.iterations, out.converged)
