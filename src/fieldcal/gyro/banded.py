"""Symmetric positive definite "arrow" systems: block tridiagonal over the poses with a dense
border of a few global unknowns, factored, solved and partly inverted in time linear in the
number of poses (banded Cholesky, LAPACK's ``pbtrf``/``pbtrs``, then the border's Schur
complement)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve_banded, cholesky_banded

Array = NDArray[np.float64]


class Arrow:
    """``K = [[T, B], [Bᵀ, Z]]``: ``T`` block tridiagonal with ``diag`` (N, q, q) and ``lower``
    (N−1, q, q) (``lower[i] = T[i+1, i]``), ``B`` the border (N, q, g), ``Z`` the corner (g, g).

    ``T = L Lᵀ`` by banded Cholesky (``T`` stored as a band of ``2q`` diagonals, L block lower
    bidiagonal); the border's Schur complement ``W = Z − Bᵀ T⁻¹ B`` is dense (g, g)."""

    def __init__(self, diag: Array, lower: Array, border: Array, corner: Array) -> None:
        n, q, _ = diag.shape
        band = np.zeros((2 * q, n * q))  # band[d, j] = T[j + d, j]
        for r in range(q):
            for c in range(r + 1):
                band[r - c, c::q] = diag[:, r, c]
            for c in range(q):
                band[q + r - c, c : (n - 1) * q : q] = lower[:, r, c]
        self.factor = cholesky_banded(band, lower=True, check_finite=False)
        self.n, self.q = n, q
        self.border = border
        self.Y = self.solve_tridiagonal(border)  # T⁻¹ B (N, q, g)
        W = corner - np.einsum("nqa,nqb->ab", border, self.Y)
        self.W = 0.5 * (W + W.T)
        self.W_inv: Array = np.linalg.inv(self.W) if len(W) else np.zeros((0, 0))

    def solve_tridiagonal(self, R: Array) -> Array:
        """``T⁻¹ R`` for ``R`` (N, q, c): LAPACK's banded forward and backward sweeps."""
        if R.shape[2] == 0:
            return np.zeros_like(R)
        flat = cho_solve_banded(
            (self.factor, True), R.reshape(self.n * self.q, -1), check_finite=False
        )
        out: Array = flat.reshape(R.shape)
        return out

    def _blocks(self) -> tuple[Array, Array]:
        """``L_ii⁻¹`` (N, q, q) and ``L_{i+1,i}`` (N−1, q, q) of the factor."""
        n, q, L = self.n, self.q, self.factor
        diag = np.zeros((n, q, q))
        off = np.zeros((max(n - 1, 0), q, q))
        for r in range(q):
            for c in range(r + 1):
                diag[:, r, c] = L[r - c, c::q]
            for c in range(q):
                off[:, r, c] = L[q + r - c, c : (n - 1) * q : q]
        inv: Array = np.asarray(np.linalg.inv(diag), dtype=float)
        return inv, off

    def solve(self, local: Array, glob: Array) -> tuple[Array, Array]:
        """``K⁻¹ [local; glob]``, ``local`` (N, q, c) and ``glob`` (g, c)."""
        u = self.solve_tridiagonal(local)
        v = self.W_inv @ (glob - np.einsum("nqg,nqc->gc", self.border, u))
        return u - np.einsum("nqg,gc->nqc", self.Y, v), v

    def band_inverse(self) -> tuple[Array, Array, Array]:
        """Blocks ``(T⁻¹)_{i,i}``, ``(T⁻¹)_{i,i+1}`` and ``(T⁻¹)_{i,i+2}`` (each (N, q, q), zero
        past the end), from ``Lᵀ X = L⁻¹`` swept backwards."""
        n, q = self.n, self.q
        inv, off = self._blocks()
        own = np.transpose(inv, (0, 2, 1)) @ inv  # L_ii⁻ᵀ L_ii⁻¹
        A = np.transpose(inv[:-1], (0, 2, 1)) @ np.transpose(off, (0, 2, 1))  # L_ii⁻ᵀ L_{i+1,i}ᵀ
        # (T⁻¹)_{i,i} = L_ii⁻ᵀ L_ii⁻¹ + a_i (T⁻¹)_{i+1,i+1} a_iᵀ: the one sequential sweep, on
        # plain lists of (q, q) blocks (numpy's indexing kept out of it)
        a, at, own_list = list(A), list(np.transpose(A, (0, 2, 1))), list(own)
        s0 = own_list[n - 1]
        diagonal = [s0] * n
        for i in range(n - 2, -1, -1):
            s0 = own_list[i] + a[i] @ s0 @ at[i]
            diagonal[i] = s0
        x0 = np.array(diagonal).reshape(n, q, q)
        # the blocks off the diagonal from it, all at once
        x1 = np.zeros((n, q, q))
        x2 = np.zeros((n, q, q))
        x1[:-1] = -A @ x0[1:]
        x2[:-2] = -A[:-1] @ x1[1:-1]
        return x0, x1, x2
