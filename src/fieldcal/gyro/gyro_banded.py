"""Symmetric positive definite "arrow" systems: block tridiagonal over the poses with a dense
border of a few global unknowns, factored, solved and partly inverted in time linear in the
number of poses (block Cholesky, then the border's Schur complement)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


class Arrow:
    """``K = [[T, B], [Bᵀ, Z]]``: ``T`` block tridiagonal with ``diag`` (N, q, q) and ``lower``
    (N−1, q, q) (``lower[i] = T[i+1, i]``), ``B`` the border (N, q, g), ``Z`` the corner (g, g).

    ``T = L Lᵀ`` by block Cholesky (L block lower bidiagonal); the border's Schur complement
    ``W = Z − Bᵀ T⁻¹ B`` is dense (g, g)."""

    def __init__(self, diag: Array, lower: Array, border: Array, corner: Array) -> None:
        n = len(diag)
        inv = np.empty_like(diag)  # L_ii⁻¹
        off = np.empty_like(lower)  # L_{i+1,i}
        block = diag[0]
        for i in range(n):
            inv[i] = np.linalg.inv(np.linalg.cholesky(block))
            if i + 1 < n:
                off[i] = lower[i] @ inv[i].T
                block = diag[i + 1] - off[i] @ off[i].T
        self.inv = inv
        self.off = off
        self.border = border
        self.Y = self.solve_tridiagonal(border)  # T⁻¹ B (N, q, g)
        W = corner - np.einsum("nqa,nqb->ab", border, self.Y)
        self.W = 0.5 * (W + W.T)
        self.W_inv: Array = np.linalg.inv(self.W) if len(W) else np.zeros((0, 0))

    def solve_tridiagonal(self, R: Array) -> Array:
        """``T⁻¹ R`` for ``R`` (N, q, c): a forward and a backward sweep over the poses."""
        n = len(self.inv)
        y = np.empty_like(R)
        y[0] = self.inv[0] @ R[0]
        for i in range(1, n):
            y[i] = self.inv[i] @ (R[i] - self.off[i - 1] @ y[i - 1])
        x = np.empty_like(R)
        x[-1] = self.inv[-1].T @ y[-1]
        for i in range(n - 2, -1, -1):
            x[i] = self.inv[i].T @ (y[i] - self.off[i].T @ x[i + 1])
        return x

    def solve(self, local: Array, glob: Array) -> tuple[Array, Array]:
        """``K⁻¹ [local; glob]``, ``local`` (N, q, c) and ``glob`` (g, c)."""
        u = self.solve_tridiagonal(local)
        v = self.W_inv @ (glob - np.einsum("nqg,nqc->gc", self.border, u))
        return u - np.einsum("nqg,gc->nqc", self.Y, v), v

    def band_inverse(self) -> tuple[Array, Array, Array]:
        """Blocks ``(T⁻¹)_{i,i}``, ``(T⁻¹)_{i,i+1}`` and ``(T⁻¹)_{i,i+2}`` (each (N, q, q), zero
        past the end), from ``Lᵀ X = L⁻¹`` swept backwards."""
        n, q, _ = self.inv.shape
        x0 = np.zeros((n, q, q))
        x1 = np.zeros((n, q, q))
        x2 = np.zeros((n, q, q))
        x0[-1] = self.inv[-1].T @ self.inv[-1]
        for i in range(n - 2, -1, -1):
            a = self.inv[i].T @ self.off[i].T  # L_ii⁻ᵀ L_{i+1,i}ᵀ
            x1[i] = -a @ x0[i + 1]
            if i + 2 < n:
                x2[i] = -a @ x1[i + 1]
            x0[i] = self.inv[i].T @ self.inv[i] - a @ x1[i].T
        return x0, x1, x2
