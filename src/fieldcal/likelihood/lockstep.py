"""Levenberg-Marquardt stepped for many problems at once, each deciding as it would alone.

:func:`lockstep` takes B problems of one layout (:func:`.stacked.layout`: same sensors, frame,
poses, globals, temperature orders) with their starts and steps them together: one stacked
normal-equation build, one batched Schur reduction (over B and the N pose blocks), one exp-map
step and one residual evaluation per round for every problem still running. Each problem keeps
its own λ, ν, acceptance, stopping tests and iteration count, exactly as
:func:`.levenberg.levenberg_marquardt` keeps them; a problem that stops is left out of the
following rounds. The decisions are not copied: each problem carries the single solver's own
:class:`.levenberg.Nielsen` schedule (the shared loop's :class:`.marquardt.Schedule`), asked
for its step's acceptance, λ and stopping exactly as :func:`.marquardt.minimise` asks it. The
stacked model (:mod:`.stacked`) and the reductions here are computed
with the same numpy and LAPACK calls per problem as the single solver's, and the scalar
decisions with the same IEEE operations (λ's update with Python's ``pow``, which numpy's
``power`` does not always equal), so each problem's result is the single solver's: bit for
bit with OpenBLAS on x86-64; a BLAS that rounds a batched product differently may differ in
the last bits, which ``tests/likelihood/test_lockstep.py`` allows (1e-9 relative).

A problem whose pose blocks or reduced system are singular gets the ``LinAlgError`` the single
solver would raise, in its place in the answer; the others go on.

The cost of a round is the fixed cost of ~40 numpy calls on small arrays plus a per-problem
LAPACK solve of the G x G reduced system: for many problems, far less per problem than one
problem's round alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesv as _dgesv

from .levenberg import Nielsen, Result, damped_inverse, gram, predicted, schur
from .pose_model import Problem, State
from .stacked import (
    Stack,
    StackState,
    apply_steps,
    jacobian,
    residuals,
    rotation_bases,
    stack,
    stack_states,
    unstack_state,
)

Array = NDArray[np.float64]
Index = NDArray[np.intp]

__all__ = ["Request", "lockstep"]


@dataclass(frozen=True)
class Request:
    """One problem for :func:`lockstep`: :func:`.levenberg.levenberg_marquardt`'s arguments."""

    problem: Problem
    state: State
    max_iter: int = 100
    tol: float = 1e-10
    lam: float = 1e-4
    known_minimum: float | None = None


@dataclass
class _Normal:
    """:class:`.levenberg.Normal`'s products of B problems (without the Jacobians)."""

    UWg: Array  # (B, N, p, p + G + 1): [U | W | gp]
    Vx: Array  # (B, G + 1, G + 1): [[V, gg], [ggᵀ, J]]
    basis: Array | None  # (B, N, 3, 2)

    def take(self, idx: Index) -> _Normal:
        return _Normal(self.UWg[idx], self.Vx[idx], None if self.basis is None else self.basis[idx])

    def put(self, idx: Index, other: _Normal) -> None:
        self.UWg[idx], self.Vx[idx] = other.UWg, other.Vx
        if self.basis is not None and other.basis is not None:
            self.basis[idx] = other.basis


def _normal(sp: Stack, st: StackState, e: Array) -> _Normal:
    """:func:`.levenberg.normal_equations` of each problem (the same products)."""
    basis = rotation_bases(sp, st)
    J = jacobian(sp, st, basis)
    J[..., -1] = e
    UWg, Vx = gram(J, J.shape[-1] - sp.first.n_global - 1)
    return _Normal(UWg, Vx, basis)


def _costs(e: Array) -> Array:
    """Eq. 8's J of each problem."""
    flat = e.reshape(len(e), -1)
    out: Array = np.vecdot(flat, flat)
    return out


def _steps(ne: _Normal, lam: Array) -> tuple[Array, Array, Array, list[int]]:
    """:func:`.levenberg.solve_step` of each problem: the damped steps (B, G), (B, N, p), the
    predicted decreases (B,) and the problems whose system is singular."""
    B, _, p, _ = ne.UWg.shape
    G = ne.Vx.shape[1] - 1
    Uinv, damp_p, singular = damped_inverse(ne.UWg[..., :p], lam[:, None, None])
    bad = np.flatnonzero(singular).tolist()
    Yz, S, rhs, damp_g = schur(Uinv, ne.UWg, ne.Vx, lam[:, None])
    ext = np.zeros((B, G + 1))
    ext[:, -1] = 1.0
    for b in range(B):
        if bad and b in bad:
            continue
        _, _, x, info = _dgesv(S[b], rhs[b])
        if info > 0:
            bad.append(b)
        else:
            ext[b, :-1] = x
    dp = (Yz @ ext[:, None, :, None])[..., 0]  # Y dg + z
    dp = -dp
    dg = ext[:, :-1]
    pred = predicted(dg, dp, ne.Vx[:, :G, G], ne.UWg[..., -1], damp_g, damp_p)
    return dg, dp, pred, bad


def _pick(x: Array, idx: Index) -> Array:
    """``x[idx]``, or ``x`` itself when ``idx`` is every row in order (no copy)."""
    return x if idx.size == len(x) else x[idx]


@dataclass
class _Run:
    """The running problems' values (row j is problem ``ids[j]``), compacted as they stop."""

    ids: Index
    sp: Stack
    st: StackState
    e: Array
    cost: Array
    ne: _Normal
    #: Each problem's damping and stopping rules: the single solver's :class:`.levenberg.
    #: Nielsen` schedule itself, one per problem (the loop is batched, the decisions are not).
    rules: list[Nielsen]
    it: NDArray[np.int64]
    converged: NDArray[np.bool_]
    moved: NDArray[np.bool_]
    max_iter: NDArray[np.int64]

    def keep(self, idx: Index) -> _Run:
        """The rows ``idx`` only."""
        return _Run(
            self.ids[idx],
            self.sp.take(idx),
            self.st.take(idx),
            self.e[idx],
            self.cost[idx],
            self.ne.take(idx),
            [self.rules[i] for i in idx.tolist()],
            self.it[idx],
            self.converged[idx],
            self.moved[idx],
            self.max_iter[idx],
        )

    def lam(self) -> Array:
        """The running problems' λ."""
        return np.array([rule.lam for rule in self.rules])


def lockstep(requests: Sequence[Request]) -> list[Result | Exception]:
    """Run :func:`.levenberg.levenberg_marquardt` on each request, all stepped together.

    Parameters
    ----------
    requests : sequence of Request
        Problems of one :func:`.stacked.layout` with their starts and options.

    Returns
    -------
    list of Result or Exception
        In the order of ``requests``: what the single solver returns for that request, or the
        ``LinAlgError`` it raises.
    """
    B = len(requests)
    problems = [r.problem for r in requests]
    out: list[Result | Exception | None] = [None] * B
    if B == 0:
        return []
    sp = stack(problems)
    st = stack_states(problems, [r.state for r in requests])
    e = residuals(sp, st)
    run = _Run(
        np.arange(B),
        sp,
        st,
        e,
        _costs(e),
        _normal(sp, st, e),
        [Nielsen(float(r.lam), float(r.tol), r.known_minimum) for r in requests],
        np.zeros(B, dtype=np.int64),
        np.zeros(B, dtype=bool),
        np.zeros(B, dtype=bool),
        np.array([int(r.max_iter) for r in requests]),
    )
    stopped = run.max_iter <= 0
    while True:
        if stopped.any():
            for j in np.flatnonzero(stopped):
                if out[run.ids[j]] is None:  # not failed
                    out[run.ids[j]] = _result(run, int(j), requests[run.ids[j]].state)
            if stopped.all():
                break
            run = run.keep(np.flatnonzero(~stopped))
        done, failed = _round(run)
        for k in failed:
            out[run.ids[k]] = np.linalg.LinAlgError("Singular matrix")
        stopped = done | (run.it >= run.max_iter)
    return [r if r is not None else np.linalg.LinAlgError("no result") for r in out]


def _result(run: _Run, j: int, start: State) -> Result | Exception:
    return Result(
        unstack_state(run.st, j) if run.moved[j] else start,
        run.e[j].copy(),
        float(run.cost[j]),
        int(run.it[j]),
        bool(run.converged[j]),
    )


def _round(run: _Run) -> tuple[NDArray[np.bool_], list[int]]:
    """One iteration of :func:`.levenberg.levenberg_marquardt`'s loop for every running
    problem, each deciding by its own :class:`.levenberg.Nielsen` rules: which of them
    stopped, and which raised (singular)."""
    run.it += 1
    dg, dp, pred, bad = _steps(run.ne, run.lam())
    done = np.zeros(len(run.ids), dtype=bool)
    done[bad] = True
    cost = run.cost
    for j in np.flatnonzero(~done).tolist():
        if run.rules[j].done_before_trying(float(cost[j]), float(pred[j])):
            run.converged[j] = done[j] = True
    finite = np.isfinite(dg).all(axis=1) & np.isfinite(dp.reshape(len(dp), -1)).all(axis=1)
    blown = ~done & ~np.isfinite(pred) & ~finite
    for j in np.flatnonzero(blown).tolist():
        run.rules[j].unusable()  # Nielsen's: λ raised, the loop goes on
    go = np.flatnonzero(~done & ~blown)
    if not go.size:
        return done, bad
    whole = go.size == len(run.ids)
    basis = None if run.ne.basis is None else _pick(run.ne.basis, go)
    sub_sp = run.sp if whole else run.sp.take(go)
    sub_st = run.st if whole else run.st.take(go)
    trial = apply_steps(sub_sp, sub_st, _pick(dg, go), _pick(dp, go), basis)
    e_new = residuals(sub_sp, trial)
    cost_new = _costs(e_new)
    pred_go, cost_go = _pick(pred, go), _pick(cost, go).copy()
    with np.errstate(all="ignore"):
        gain = cost_go - cost_new
    taken: list[int] = []
    for k, j in enumerate(go.tolist()):
        rule = run.rules[j]
        rho = rule.ratio(float(gain[k]), float(pred_go[k]))
        if rule.accepts(float(gain[k]), rho, float(cost_new[k]), float(cost_go[k])):
            taken.append(k)
            if rule.accepted(float(gain[k]), rho, float(cost_new[k])):
                run.converged[j] = done[j] = True
        else:
            stop = rule.refused(float(pred_go[k]), float(cost_go[k]))
            if stop is not None:
                run.converged[j], done[j] = stop, True
    a = np.array(taken, dtype=np.intp)
    if a.size:
        ia = go[a]
        if ia.size == len(run.ids):
            run.st, run.e = trial, e_new
        else:
            run.st.put(ia, trial.take(a))
            run.e[ia] = e_new[a]
        run.moved[ia] = True
        run.cost[ia] = cost_new[a]
        more = ia[~done[ia]]
        if more.size == len(run.ids):
            run.ne = _normal(run.sp, run.st, run.e)
        elif more.size:
            run.ne.put(more, _normal(run.sp.take(more), run.st.take(more), run.e[more]))
    return done, bad
