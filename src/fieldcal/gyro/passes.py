"""One pass over the motion's intervals at a point of the gyroscope's fit: each segment's
integrated turn and, as asked, its integration noise and the sums its Jacobian is made of —
a chunk of whole segments at a time, by component (linear in the intervals, a few MB of work
arrays whatever the length of the log), the last few passes kept (``docs/methods/gyro.md``,
*The likelihood*).

Over segment ``k`` with intervals ``j`` (length ``dt_j``, corrected raw rate
``u_j = raw_j − b(t_j)``, rate ``ω_j = M u_j``, step ``φ_j = −ω_j dt_j``) and ``P_{j−1}`` the
rotation from the segment's start to the interval's:

- the turn ``ΔR̂_k``, the ordered product of the steps (:mod:`.integrate`);
- the integration noise ``Σ_j dt_j P_{j−1}ᵀ (M Q Mᵀ) P_{j−1}``;
- with ``D_j = dt_j P_{j−1}ᵀ J_r(φ_j)`` (the change of the segment's rotation with the
  interval's rate, :func:`step_right_jacobian`): ``Σ_j D_j ⊗ u_j`` (the gain's part),
  ``Σ_j D_j (1 − λ_j)`` and ``Σ_j D_j λ_j`` (the biases of the poses before and after).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .data import Segments
from .integrate import SCAN_BLOCK, block_scan, matrix_columns, multiply_columns, runs, step_parts

Array = NDArray[np.float64]

#: Intervals integrated at a time: whole segments, about this many intervals (the rotations'
#: scan), in parts of about :data:`PART` (the per-interval matrices).
CHUNK, PART = 1 << 16, 1 << 12

#: What a pass computes: the turns only, with the integration noise, with the Jacobian's sums.
TURNS, NOISE, JACOBIAN = 0, 1, 2

#: Rows of a pass's per-segment sums at each level: the integration noise (9), then
#: ``Σ D_j ⊗ u_j`` (27), ``Σ D_j (1 − λ_j)`` and ``Σ D_j λ_j`` (9 each).
SUM_ROWS = {TURNS: 0, NOISE: 9, JACOBIAN: 54}

#: Passes kept (the solver comes back to a point: the fit's start, a step's end).
KEEP = 4


@dataclass
class Chunk:
    """Consecutive whole segments and their intervals, the per-interval data by component."""

    segments: slice  # the segments
    raw: Array  # (3, J_c) the intervals' raw rates, one row per axis
    dt: Array  # (J_c,)
    lam: Array  # (J_c,) interpolation weight of the later pose's bias
    pose: NDArray[np.int64]  # (J_c,) the pose before each interval's segment
    first: NDArray[np.int64]  # (M_c,) first interval of each segment, within the chunk
    last: NDArray[np.int64]  # (M_c,) last interval of each segment, within the chunk
    seg: NDArray[np.int64]  # (J_c,) each interval's segment, within the chunk
    parts: list[slice]  # the chunk's segments in runs of about PART intervals
    # the scan's block of the rotation before each interval (:func:`.integrate.block_scan`)
    # and the (block, segment) pairs the intervals fall in: one product per pair carries the
    # blocks before it and the segment's start, and no pass over the intervals does
    block: int  # the scan's block length
    pair: NDArray[np.int64]  # (J_c,) each interval's pair
    pair_block: NDArray[np.int64]  # (pairs,)
    pair_seg: NDArray[np.int64]  # (pairs,)


@dataclass
class Pass:
    """A pass's results per segment: ``level`` (:data:`TURNS`, :data:`NOISE`,
    :data:`JACOBIAN`), the turns (M, 3, 3) and the sums (:data:`SUM_ROWS` rows, M columns)."""

    level: int
    total: Array
    sums: Array

    def pick(self, rows: NDArray[np.int64]) -> Pass:
        """The pass of some of the segments."""
        return Pass(self.level, self.total[rows], self.sums[:, rows])


def chunks_of(
    data: Segments, size: int = CHUNK, part: int = PART, block: int = SCAN_BLOCK
) -> list[Chunk]:
    """The segments in runs of about ``size`` intervals (at least one segment each), scanned
    in blocks of ``block`` steps."""
    out: list[Chunk] = []
    for run in runs(data.first, data.last, size):
        j0, j1 = int(data.first[run][0]), int(data.last[run][-1]) + 1
        first, last = data.first[run] - j0, data.last[run] - j0
        seg = data.seg[j0:j1]
        # the block of the rotation before interval j: that of step j − 1 (the identity, in
        # block 0, before the first)
        within = np.maximum(np.arange(j1 - j0) - 1, 0) // block
        new = np.ones(j1 - j0, dtype=bool)
        new[1:] = (within[1:] != within[:-1]) | (seg[1:] != seg[:-1])
        starts = np.flatnonzero(new)
        out.append(
            Chunk(
                run,
                np.ascontiguousarray(data.raw[j0:j1].T),
                data.dt[j0:j1],
                data.lam[j0:j1],
                data.before[seg],
                first,
                last,
                seg - run.start,
                runs(first, last, part),
                block,
                np.cumsum(new) - 1,
                within[starts],
                seg[starts] - run.start,
            )
        )
    return out


def right_jacobian_columns(phi: Array) -> Array:
    """``J_r(φ)`` (3, 3, J) of rotation vectors (3, J) by component
    (:func:`.model.right_jacobian`), as ``(1 − b θ²) I − a [φ]× + b φ φᵀ``
    (``[φ]×² = φ φᵀ − θ² I``)."""
    t2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    t = np.sqrt(t2)
    small = t < 1e-3
    s = np.where(small, 1.0, t)
    a = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(s)) / (s * s))
    b = np.where(small, 1.0 / 6.0 - t2 / 120.0, (s - np.sin(s)) / (s * s * s))
    return _right_jacobian(phi, t2, a, b)


def step_right_jacobian(h: Array, theta2: Array, half_sinc: Array, cos_half: Array) -> Array:
    """``J_r(−h)`` (3, 3, J) of the steps' rotation vectors ``h = ω dt`` (3, J), as
    :func:`right_jacobian_columns` of ``−h`` but from the sines and cosines of the half
    angles the step quaternions already hold: ``1 − cos θ = 2 sin²(θ/2)`` and
    ``sin θ = 2 sin(θ/2) cos(θ/2)``, so ``a = 2 (sin(θ/2)/θ)²`` (no cancellation at any
    angle) and ``b = (1 − 2 (sin(θ/2)/θ) cos(θ/2)) / θ²`` (its series below 10⁻³):
    ``(1 − b θ²) I + a [h]× + b h hᵀ``."""
    small = theta2 < 1e-6
    a = 2.0 * half_sinc * half_sinc
    b = np.where(
        small,
        1.0 / 6.0 - theta2 / 120.0,
        (1.0 - 2.0 * half_sinc * cos_half) / np.where(small, 1.0, theta2),
    )
    # J_r(−h) is the same expression of −h (the negations are exact: the same numbers)
    return _right_jacobian(-h, theta2, a, b)


def _right_jacobian(phi: Array, t2: Array, a: Array, b: Array) -> Array:
    """``(1 − b θ²) I − a [φ]× + b φ φᵀ`` (3, 3, J) by component."""
    out: Array = (b * phi)[:, None, :] * phi[None, :, :]
    diag = 1.0 - b * t2
    ax, ay, az = a * phi[0], a * phi[1], a * phi[2]
    out[0, 0] += diag
    out[1, 1] += diag
    out[2, 2] += diag
    out[0, 1] += az
    out[0, 2] -= ay
    out[1, 0] -= az
    out[1, 2] += ax
    out[2, 0] += ay
    out[2, 1] -= ax
    return out


@dataclass
class Steps:
    """A chunk's intervals at one point: corrected raw rates ``u`` and ``h = ω dt`` (3, J_c),
    the step quaternions ``q`` (4, J_c) with their ``θ²`` and ``sin(θ/2)/θ`` (J_c,), and the
    rotations' scan from the chunk's start in its two factors (:func:`.integrate.block_scan`:
    ``inner`` (4, J_c), ``before`` (4, blocks))."""

    u: Array
    h: Array
    q: Array
    theta2: Array
    half_sinc: Array
    inner: Array
    before: Array


def steps_at(x: Array, c: Chunk) -> Steps:
    """The chunk's rates, steps and scan at ``x``."""
    u, h = _rates(x, c)
    q, theta2, half_sinc = step_parts(h)
    return Steps(u, h, q, theta2, half_sinc, *block_scan(q, c.block))


class Integrator:
    """Passes over the intervals of ``data`` (``Q`` the rate noise density) at points
    ``x = (vec M, b_0, …)``; the last :data:`KEEP` passes kept, and the rotations' scan of the
    last turns-only pass (a step's trial point, where the next full pass often comes)."""

    def __init__(self, data: Segments, noise_density: Array) -> None:
        self.data = data
        self.Q = noise_density
        self._chunks: list[Chunk] | None = None
        self._passes: OrderedDict[bytes, Pass] = OrderedDict()
        self._scans: tuple[bytes, list[Steps]] | None = None

    def run(self, x: Array, level: int) -> Pass:
        """The pass at ``x`` of at least ``level``."""
        key = x.tobytes()
        kept = self._passes.get(key)
        if kept is not None and kept.level >= level:
            self._passes.move_to_end(key)
            return kept
        if self._chunks is None:
            self._chunks = chunks_of(self.data)
        m = len(self.data.first)
        total = np.empty((m, 3, 3))
        sums = np.empty((SUM_ROWS[level], m))
        scans = self._scans[1] if self._scans is not None and self._scans[0] == key else None
        kept_scans = []
        M = x[:9].reshape(3, 3)
        density = M @ self.Q @ M.T
        for i, chunk in enumerate(self._chunks):
            steps = scans[i] if scans is not None else steps_at(x, chunk)
            total[chunk.segments], sums[:, chunk.segments] = _chunk_pass(
                chunk, steps, density, level
            )
            kept_scans.append(steps)
        # the last pass's steps: a trial point's serve the solver's next full pass, which is
        # likely there, and a full pass's the path lengths at that point
        self._scans = (key, kept_scans)
        done = Pass(level, total, sums)
        self._passes[key] = done
        while len(self._passes) > KEEP:
            self._passes.popitem(last=False)
        return done

    def path_length(self, x: Array) -> Array:
        """The angle (rad) each segment turns through at ``x``, ``Σ_j |ω_j| dt_j``: the steps'
        angles summed (those of the last pass when it was at ``x``)."""
        if self._chunks is None:
            self._chunks = chunks_of(self.data)
        key = x.tobytes()
        kept = self._scans[1] if self._scans is not None and self._scans[0] == key else None
        out = np.empty(len(self.data.first))
        for i, chunk in enumerate(self._chunks):
            if kept is not None:
                theta2 = kept[i].theta2
            else:
                h = _rates(x, chunk)[1]
                theta2 = h[0] * h[0] + h[1] * h[1] + h[2] * h[2]
            out[chunk.segments] = np.add.reduceat(np.sqrt(theta2), chunk.first)
        return out


def _rates(x: Array, c: Chunk) -> tuple[Array, Array]:
    """The chunk's corrected raw rates ``u = raw − b(t)`` and ``ω dt`` (3, J_c) by component."""
    M = x[:9].reshape(3, 3)
    b = np.ascontiguousarray(x[9:].reshape(-1, 3).T)  # (3, N) the poses' biases by axis
    lam = c.lam
    u = c.raw - ((1.0 - lam) * b.take(c.pose, axis=1) + lam * b.take(c.pose + 1, axis=1))
    return u, (M @ u) * c.dt


def _chunk_pass(c: Chunk, steps: Steps, density: Array, level: int) -> tuple[Array, Array]:
    """One chunk's turns (M_c, 3, 3) and sums (rows, M_c) from its ``steps`` (rates, step
    quaternions and the rotations' scan from the chunk's start)."""
    inner, before, u, h = steps.inner, steps.before, steps.u, steps.h
    # the rotation before each interval is prev[j] ⊗ before[block of j − 1]
    prev = np.empty_like(inner)
    prev[:, 0] = (1.0, 0.0, 0.0, 0.0)
    prev[:, 1:] = inner[:, :-1]
    start = c.pair[c.first]  # the pair of each segment's first interval
    base = multiply_columns(prev[:, c.first], before[:, c.pair_block[start]])
    base[1:] *= -1.0  # conjugate: relative to the segment's start
    end = multiply_columns(inner[:, c.last], before[:, c.last // c.block])
    turn = np.moveaxis(matrix_columns(multiply_columns(end, base)), 2, 0)
    sums = np.empty((SUM_ROWS[level], len(c.first)))
    if level == TURNS:
        return turn, sums
    # P_{j−1} = prev[j] ⊗ (before[block] ⊗ base[segment]): the bracket once per pair
    carry = multiply_columns(before[:, c.pair_block], base[:, c.pair_seg])
    for part in c.parts:
        j = slice(int(c.first[part][0]), int(c.last[part][-1]) + 1)
        # P_{j−1}: products of unit quaternions, unit to round-off (not normalised again)
        P = matrix_columns(multiply_columns(prev[:, j], carry[:, c.pair[j]]), unit=True)
        rows = np.empty((len(sums), j.stop - j.start))
        dt = c.dt[j]
        G = (density @ P.reshape(3, -1)).reshape(P.shape)
        noise = rows[:9].reshape(3, 3, -1)
        np.einsum("iaj,icj->acj", P, G, out=noise)
        noise *= dt  # dt Pᵀ (M Q Mᵀ) P
        if level == JACOBIAN:
            Jr = step_right_jacobian(h[:, j], steps.theta2[j], steps.half_sinc[j], steps.q[0, j])
            D = rows[36:45].reshape(3, 3, -1)  # D_j = dt Pᵀ J_r(φ), then Σ D_j (1 − λ_j)
            np.einsum("iaj,icj->acj", P, Jr, out=D)
            D *= dt
            np.multiply(D[:, :, None, :], u[None, None, :, j], out=rows[9:36].reshape(3, 3, 3, -1))
            np.multiply(D, c.lam[j], out=rows[45:54].reshape(3, 3, -1))
        sums[:, part] = np.add.reduceat(rows, c.first[part] - j.start, axis=1)
    if level == JACOBIAN:
        sums[36:45] -= sums[45:54]  # Σ D_j (1 − λ_j) = Σ D_j − Σ D_j λ_j
    return turn, sums
