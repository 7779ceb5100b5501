"""The gyroscope's normal equations at one point, in time linear in the number of poses: the
cost, its gradient, the diagonal of the information (Levenberg-Marquardt's damping), the
damped step, the gain's information with the biases eliminated and the covariance of linear
functions of the parameters — each equal to the dense ``Jᵀ Σ⁻¹ J`` computation, never forming
it (``x = (gain coordinates, b_0, …, b_{N−1})``; the poses' errors are latent unknowns,
:mod:`.noise`)."""

from __future__ import annotations

import numpy as np

from .banded import Arrow
from .model import Array, Evaluation
from .noise import SegmentNoise


def _tt(X: Array, Y: Array) -> Array:
    """``X_kᵀ Y_k`` for stacks of matrices."""
    out: Array = np.transpose(X, (0, 2, 1)) @ Y
    return out


def _pad(X: Array) -> Array:
    """``X`` with a block of zeros before and after (the neighbours past the ends)."""
    return np.concatenate([np.zeros_like(X[:1]), X, np.zeros_like(X[:1])])


class NormalSystem:
    """``Jᵀ Σ⁻¹ J`` (plus the biases' priors) at ``x`` for the whitening ``noise``; ``gain_map``
    (9, r) the gain directions moved along (``None``: all nine)."""

    def __init__(
        self,
        noise: SegmentNoise,
        ev: Evaluation,
        x: Array,
        p: Array,
        prior_inv: Array,
        gain_map: Array | None = None,
    ) -> None:
        self.noise = noise
        W, n = noise.W, noise.model.n
        self.a = noise.a
        self.r = W @ ev.r[:, :, None]  # (M, d, 1)
        JM = W @ ev.J_gain
        self.JM = JM if gain_map is None else JM @ gain_map
        self.Ja = W @ ev.J_before
        self.Jb = W @ ev.J_after
        self.prior_inv = prior_inv
        self.prior_res = x[9:].reshape(n, 3) - p
        self.n_gain = self.JM.shape[2]

    def _by_pose(self, before: Array, after: Array) -> Array:
        """Sum per pose of per-segment terms of the pose before and the pose after."""
        out = np.zeros((self.noise.model.n, *before.shape[1:]))
        out[self.a] += before
        out[self.a + 1] += after
        return out

    def gradient(self) -> Array:
        """``Jᵀ Σ⁻¹ r`` plus the priors' part, in ``x``'s order."""
        e = self.noise.project(self.r)
        g_b = self._by_pose(_tt(self.Ja, e), _tt(self.Jb, e))[:, :, 0]
        g_b += np.einsum("nij,nj->ni", self.prior_inv, self.prior_res)
        return np.concatenate([np.einsum("mdg,md->g", self.JM, e[:, :, 0]), g_b.ravel()])

    def diagonal(self) -> Array:
        """The diagonal of ``Jᵀ Σ⁻¹ J`` plus the priors', in ``x``'s order: the latent poses'
        errors eliminated through the selected blocks of their inverse (each bias meets the
        latent unknowns of its own pose and its two neighbours, and the shared ones)."""
        noise, a, n = self.noise, self.a, self.noise.model.n
        Ja, Jb, Ua, Ub, Uz = self.Ja, self.Jb, noise.Ua, noise.Ub, noise.Uz
        gain = np.einsum("mdg,mdg->g", self.JM, noise.project(self.JM))
        own = np.einsum("nii->ni", self._by_pose(_tt(Ja, Ja), _tt(Jb, Jb)) + self.prior_inv)
        # K[latent, b_i] from the latent unknowns of poses i−1, i, i+1 and the shared ones
        before = np.zeros((n, 3, 3))  # from the latent unknowns of pose i − 1
        before[a + 1] += _tt(Ua, Jb)
        after = np.zeros((n, 3, 3))  # of pose i + 1
        after[a] += _tt(Ub, Ja)
        V = [before, self._by_pose(_tt(Ua, Ja), _tt(Ub, Jb)), after]
        Vz = self._by_pose(_tt(Uz, Ja), _tt(Uz, Jb))  # (N, G, 3)
        lat = noise.latent
        x0, x1, x2 = lat.band_inverse()
        x0p, x1p, x2p, Yp = _pad(x0), _pad(x1), _pad(x2), _pad(lat.Y)
        i = np.arange(n) + 1  # positions in the padded arrays
        # (T⁻¹) blocks between the latent unknowns of poses i − 1 + s and i − 1 + t, s ≤ t
        upper = {
            (0, 0): x0p[i - 1],
            (0, 1): x1p[i - 1],
            (0, 2): x2p[i - 1],
            (1, 1): x0p[i],
            (1, 2): x1p[i],
            (2, 2): x0p[i + 1],
        }
        quad = np.zeros((n, 3))
        for s in range(3):
            for t in range(3):
                X = upper[s, t] if s <= t else np.transpose(upper[t, s], (0, 2, 1))
                quad += np.einsum("nai,nab,nbi->ni", V[s], X, V[t])
        Yv = _tt(Yp[i - 1], V[0]) + _tt(Yp[i], V[1]) + _tt(Yp[i + 1], V[2]) - Vz  # (N, G, 3)
        quad += np.einsum("ngi,gh,nhi->ni", Yv, lat.W_inv, Yv)
        return np.concatenate([gain, (own - quad).ravel()])

    def _system(self, damping: Array) -> Arrow:
        """The normal matrix of (biases, ξ per pose; gain, ζ) with ``damping`` added to the
        diagonal of ``x``'s unknowns."""
        noise, a, n = self.noise, self.a, self.noise.model.n
        Ra = np.concatenate([self.Ja, noise.Ua], axis=2)  # (M, d, 6)
        Rb = np.concatenate([self.Jb, noise.Ub], axis=2)
        Rg = np.concatenate([self.JM, noise.Uz], axis=2)  # (M, d, r + G)
        diag = self._by_pose(_tt(Ra, Ra), _tt(Rb, Rb))
        diag[:, :3, :3] += self.prior_inv
        diag[:, 3:, 3:] += np.eye(3)
        diag[:, np.arange(3), np.arange(3)] += damping[self.n_gain :].reshape(n, 3)
        lower = np.zeros((max(n - 1, 0), 6, 6))
        lower[a] += _tt(Rb, Ra)
        border = self._by_pose(_tt(Ra, Rg), _tt(Rb, Rg))
        corner = np.einsum("mdg,mdh->gh", Rg, Rg)
        g = self.n_gain
        corner[np.arange(g), np.arange(g)] += damping[:g]
        corner[g:, g:] += np.eye(corner.shape[0] - g)
        return Arrow(diag, lower, border, corner)

    def step(self, damping: Array) -> Array:
        """``−(Jᵀ Σ⁻¹ J + P + diag(damping))⁻¹ g`` (``P`` the priors'), in ``x``'s order."""
        n, r = self.noise.model.n, self.r
        local = self._by_pose(
            np.concatenate([_tt(self.Ja, r), _tt(self.noise.Ua, r)], axis=1),
            np.concatenate([_tt(self.Jb, r), _tt(self.noise.Ub, r)], axis=1),
        )
        local[:, :3, 0] += np.einsum("nij,nj->ni", self.prior_inv, self.prior_res)
        glob = np.concatenate(
            [np.einsum("mdg,mdc->gc", self.JM, r), np.einsum("mdg,mdc->gc", self.noise.Uz, r)]
        )
        u, v = self._system(damping).solve(-local, -glob)
        return np.concatenate([v[: self.n_gain, 0], u[:, :3, 0].reshape(3 * n)])

    def gain_information(self) -> Array:
        """The gain's information with the biases (and the poses' errors) eliminated."""
        Wg = self._system(np.zeros(self.n_gain + 3 * self.noise.model.n)).W
        g = self.n_gain
        out: Array = Wg[:g, :g] - Wg[:g, g:] @ np.linalg.solve(Wg[g:, g:], Wg[g:, :g])
        return 0.5 * (out + out.T)

    def covariance_of(self, L: Array) -> Array:
        """``L (Jᵀ Σ⁻¹ J + P)⁻¹ Lᵀ`` for ``L`` (k, r + 3N) in ``x``'s order."""
        n, g = self.noise.model.n, self.n_gain
        k = L.shape[0]
        local = np.zeros((n, 6, k))
        local[:, :3, :] = np.transpose(L[:, g:].reshape(k, n, 3), (1, 2, 0))
        glob = np.zeros((g + self.noise.n_shared, k))
        glob[:g] = L[:, :g].T
        u, v = self._system(np.zeros(g + 3 * n)).solve(local, glob)
        out: Array = L[:, :g] @ v[:g] + L[:, g:] @ np.transpose(u[:, :3, :], (0, 1, 2)).reshape(
            3 * n, k
        )
        return 0.5 * (out + out.T)
