"""The model of :mod:`.pose_model` over a leading batch axis: B problems of one layout at once.

B independent calibration problems with the same sensors, body frame, number of poses N,
globals G and temperature orders (one :func:`layout` key) are stacked: whitening matrices
``(B, N, 3, 3)``, means ``(B, N, 3)``, gains ``(B, 3, 3)``, rotations ``(B, N, 3, 3)``, ...
Residuals (Eq. 6, 8), their analytic Jacobians and the exp-map step are computed for all of
them with the same numpy calls as one problem alone, so the fixed cost of a call (the problems
are tiny) is paid once for B problems.

Every operation is the single problem's operation with the batch axis in front: numpy's
stacked ``matmul`` runs the same BLAS call per matrix and the per-pose ``einsum`` the same
loop over a longer pose axis, so problem b's numbers are those of
:func:`.pose_model.residuals`, :func:`.pose_model.jacobians` and :func:`.pose_model.apply_step`
on problem b alone (``tests/likelihood/test_lockstep.py`` checks it), whatever B and whatever
the other problems.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..geometry.frames import GRAVITY
from .pose_model import (
    SYM_INDEX,
    Problem,
    State,
    _whiten,
    exp_map,
    fill_constant,
    fill_jacobian,
)

Array = NDArray[np.float64]
Index = NDArray[np.intp]

__all__ = [
    "Stack",
    "StackState",
    "apply_steps",
    "jacobian",
    "jacobians",
    "layout",
    "residuals",
    "rotation_bases",
    "stack",
    "stack_states",
    "unstack_state",
]


def layout(problem: Problem) -> Hashable:
    """What problems stepped together must share: sensors, frame, poses, parameter layout.

    Parameters
    ----------
    problem : Problem

    Returns
    -------
    hashable
        Equal for problems that can be stacked.
    """
    slices = tuple(
        (s, problem.gain_slice[s].start, problem.bias_slice[s].start, problem.temp_order(s))
        for s in problem.sensors
    )
    powers = None if problem.temp_powers is None else problem.temp_powers.shape[1]
    return (
        problem.sensors,
        problem.frame,
        problem.n,
        problem.n_global,
        problem.dip_index,
        slices,
        powers,
    )


@dataclass(frozen=True)
class Stack:
    """B problems of one layout: the first one's layout, the data stacked."""

    first: Problem
    linv: dict[str, Array]  # (B, N, 3, 3)
    means: dict[str, Array]  # (B, N, 3)
    powers: Array | None  # (B, N, K)

    @property
    def size(self) -> int:
        return len(next(iter(self.means.values())))

    def take(self, idx: Index) -> Stack:
        """The problems ``idx``."""
        return Stack(
            self.first,
            {s: a[idx] for s, a in self.linv.items()},
            {s: a[idx] for s, a in self.means.items()},
            None if self.powers is None else self.powers[idx],
        )


@dataclass
class StackState:
    """B states: gains (B, 3, 3), biases (B, 3), dips (B,), rotations (B, N, 3, 3) and the
    temperature coefficients (B, K_s, 3) of each sensor with temperature terms."""

    gains: dict[str, Array]
    biases: dict[str, Array]
    dip: Array
    rotations: Array
    temps: dict[str, Array]

    def take(self, idx: Index) -> StackState:
        """The states ``idx``."""
        return StackState(
            {s: a[idx] for s, a in self.gains.items()},
            {s: a[idx] for s, a in self.biases.items()},
            self.dip[idx],
            self.rotations[idx],
            {s: a[idx] for s, a in self.temps.items()},
        )

    def put(self, idx: Index, other: StackState) -> None:
        """Replace the states ``idx`` by ``other``'s (in order)."""
        for s, a in self.gains.items():
            a[idx] = other.gains[s]
        for s, a in self.biases.items():
            a[idx] = other.biases[s]
        for s, a in self.temps.items():
            a[idx] = other.temps[s]
        self.dip[idx] = other.dip
        self.rotations[idx] = other.rotations


def stack(problems: Sequence[Problem]) -> Stack:
    """Stack problems of one :func:`layout`.

    Parameters
    ----------
    problems : sequence of Problem
        At least one, all of the same layout.

    Returns
    -------
    Stack
    """
    first = problems[0]
    powers = None
    if first.temp_powers is not None:
        powers = np.stack([np.asarray(p.temp_powers) for p in problems])
    return Stack(
        first,
        {s: np.stack([p.linv[s] for p in problems]) for s in first.sensors},
        {s: np.stack([p.means[s] for p in problems]) for s in first.sensors},
        powers,
    )


def stack_states(problems: Sequence[Problem], states: Sequence[State]) -> StackState:
    """Stack each problem's state (temperature coefficients cut or padded to its order).

    Parameters
    ----------
    problems, states : sequences of Problem and State, one state per problem

    Returns
    -------
    StackState
    """
    first = problems[0]
    return StackState(
        {s: np.stack([np.asarray(x.gains[s], dtype=float) for x in states]) for s in first.sensors},
        {
            s: np.stack([np.asarray(x.biases[s], dtype=float) for x in states])
            for s in first.sensors
        },
        np.array([float(x.dip) for x in states]),
        np.stack([np.asarray(x.rotations, dtype=float) for x in states]),
        {
            s: np.stack([x.temp(p, s) for p, x in zip(problems, states, strict=True)])
            for s in first.temp_slice
        },
    )


def unstack_state(st: StackState, b: int) -> State:
    """Problem b's state, laid out as :func:`.pose_model.apply_step` lays it out.

    Parameters
    ----------
    st : StackState
    b : int

    Returns
    -------
    State
    """
    return State(
        {s: a[b].copy() for s, a in st.gains.items()},
        {s: a[b].copy() for s, a in st.biases.items()},
        float(st.dip[b]),
        st.rotations[b].copy(),
        {s: a[b].copy() for s, a in st.temps.items()},
    )


def _fields(sp: Stack, sensor: str, dip: Array) -> Array:
    """(B, 3): :func:`.pose_model.field` of each problem."""
    if sensor == "accel":
        return np.broadcast_to(GRAVITY, (len(dip), 3))
    if sp.first.joint:
        return np.stack([np.cos(dip), np.zeros_like(dip), np.sin(dip)], axis=1)
    return np.broadcast_to(np.array([1.0, 0.0, 0.0]), (len(dip), 3))


def _rotate(rotations: Array, f: Array) -> Array:
    """(B, N, 3): ``R_bi f_b``."""
    out: Array = (rotations @ f[:, None, :, None])[..., 0]
    return out


def residuals(sp: Stack, st: StackState) -> Array:
    """Whitened residuals (B, N, 3·#sensors): :func:`.pose_model.residuals` of each problem.

    Parameters
    ----------
    sp : Stack
    st : StackState

    Returns
    -------
    ndarray
    """
    B, n = st.rotations.shape[:2]
    out = []
    for s in sp.first.sensors:
        v = _rotate(st.rotations, _fields(sp, s, st.dip))
        raw = v @ st.gains[s].transpose(0, 2, 1) + st.biases[s][:, None, :] - sp.means[s]
        order = sp.first.temp_order(s)
        if order and sp.powers is not None:
            raw += sp.powers[:, :, :order] @ st.temps[s]
        w = _whiten(sp.linv[s].reshape(-1, 3, 3), raw.reshape(-1, 3))
        out.append(w.reshape(B, n, 3))
    return out[0] if len(out) == 1 else np.concatenate(out, axis=2)


def rotation_bases(sp: Stack, st: StackState) -> Array | None:
    """(B, N, 3, 2) tangent bases of one-sensor problems (:func:`.pose_model.rotation_basis`),
    None for joint ones."""
    if sp.first.joint:
        return None
    B, n = st.rotations.shape[:2]
    v = _rotate(st.rotations, _fields(sp, sp.first.sensors[0], st.dip)).reshape(-1, 3)
    helper = np.eye(3)[np.argmin(np.abs(v), axis=1)]
    b1 = np.cross(v, helper)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    b2 = np.cross(v, b1)
    out: Array = np.stack([b1, b2], axis=-1).reshape(B, n, 3, 2)
    return out


def jacobians(sp: Stack, st: StackState, basis: Array | None) -> tuple[Array, Array]:
    """:func:`.pose_model.jacobians` of each problem: (B, N, m, 3 or 2) and (B, N, m, G).

    Parameters
    ----------
    sp : Stack
    st : StackState
    basis : ndarray or None
        From :func:`rotation_bases`.

    Returns
    -------
    tuple of ndarray
    """
    J = jacobian(sp, st, basis)
    P = J.shape[-1] - sp.first.n_global - 1
    return J[..., :P], J[..., P:-1]


def jacobian(sp: Stack, st: StackState, basis: Array | None) -> Array:
    """:func:`.pose_model.jacobian` of each problem, (B, N, m, P + G + 1), by the same
    :func:`.pose_model.fill_constant` and :func:`.pose_model.fill_jacobian` on the B·N poses."""
    p = sp.first
    B, n = st.rotations.shape[:2]
    bn = B * n
    linv = np.stack([sp.linv[s].reshape(bn, 3, 3) for s in p.sensors])
    Kw = np.stack([(sp.linv[s] @ st.gains[s][:, None]).reshape(bn, 3, 3) for s in p.sensors])
    flat_basis = None if basis is None else basis.reshape(bn, 3, 2)
    P = 3 if basis is None else 2
    J = np.zeros((bn, 3 * len(p.sensors), P + p.n_global + 1))
    flat_linv = {s: linv[k] for k, s in enumerate(p.sensors)}
    fill_constant(p, J, flat_linv, None if sp.powers is None else sp.powers.reshape(bn, -1))
    if p.joint:
        dip = st.dip
        F = np.stack(
            [
                _fields(sp, "accel", dip),
                _fields(sp, "mag", dip),
                np.stack([-np.sin(dip), np.zeros_like(dip), np.cos(dip)], axis=1),
            ],
            axis=2,
        )
        VV = (st.rotations @ F[:, None]).reshape(bn, 3, 3)
        fill_jacobian(p, J, linv, Kw, VV[:, :, :2].transpose(2, 0, 1), VV[:, :, 2], flat_basis)
    else:
        f = _fields(sp, p.sensors[0], st.dip)
        v = _rotate(st.rotations, f).reshape(1, bn, 3)
        fill_jacobian(p, J, linv, Kw, v, None, flat_basis)
    return J.reshape(B, n, *J.shape[1:])


def apply_steps(sp: Stack, st: StackState, dg: Array, dp: Array, basis: Array | None) -> StackState:
    """:func:`.pose_model.apply_step` of each problem: globals added, ``exp(ω^) R_i``.

    Parameters
    ----------
    sp : Stack
    st : StackState
    dg : ndarray
        (B, G) steps of the globals.
    dp : ndarray
        (B, N, 3 or 2) steps of the rotations.
    basis : ndarray or None
        From :func:`rotation_bases`.

    Returns
    -------
    StackState
    """
    p = sp.first
    B, n = st.rotations.shape[:2]
    gains, biases, temps = {}, {}, {}
    for s in p.sensors:
        d = dg[:, p.gain_slice[s]]
        sym = p.symmetric(s)
        dK = d[:, SYM_INDEX].reshape(B, 3, 3) if sym else d.reshape(B, 3, 3)
        gains[s] = st.gains[s] + dK
        biases[s] = st.biases[s] + dg[:, p.bias_slice[s]]
        if s in p.temp_slice:
            temps[s] = st.temps[s] + dg[:, p.temp_slice[s]].reshape(B, -1, 3)
    dip = st.dip + dg[:, p.dip_index] if p.dip_index is not None else st.dip + 0.0
    flat = dp.reshape(B * n, -1)
    omega = flat if basis is None else np.einsum("nij,nj->ni", basis.reshape(-1, 3, 2), flat)
    rotations = exp_map(omega).reshape(B, n, 3, 3) @ st.rotations
    return StackState(gains, biases, dip, rotations, temps)
