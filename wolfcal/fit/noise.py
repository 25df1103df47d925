"""The noise model of one measurement block: independent noise per measured number plus the joint-reading noise
that a group of measurements shares.

Residual rows of one group (e.g. every corner seen at one still pose: they share its encoder quantisation) have
covariance C_g = sigma^2 I + sigma_q^2 A_g A_g^T, A_g = d(rows)/d(joint readings). With A_g A_g^T = U diag(l) U^T,
W_g = diag(1 / sqrt(sigma^2 + sigma_q^2 l)) U^T whitens them (W_g^T W_g = C_g^-1). The eigen-decomposition is
done once per linearisation, so trying another sigma (the noise-level search) costs one division. Groups of equal
size are decomposed in one batched call.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse


def split_rows(labels: np.ndarray, dim: int, keep: np.ndarray | None = None) -> list[np.ndarray]:
    """Row indices of each group of units: unit u (label labels[u]) owns rows u*dim .. u*dim+dim-1; units with
    keep False are left out; groups in ascending label order, empty groups dropped."""
    units = np.arange(len(labels)) if keep is None else np.flatnonzero(keep)
    order = units[np.argsort(labels[units], kind="stable")]
    bounds = np.flatnonzero(np.diff(labels[order])) + 1
    rows = (order[:, None] * dim + np.arange(dim)).ravel()
    return np.split(rows, bounds * dim) if len(order) else []


class GroupedWhitening:
    """Whitening of residual rows split into groups (list of row-index arrays), at joint sensitivities A (R, J)."""

    def __init__(self, groups: list[np.ndarray], A: np.ndarray, sigma_q: float) -> None:
        self.sigma_q = sigma_q
        self.n_rows = len(A)
        sizes = np.array([len(g) for g in groups], dtype=int)
        self._classes = []  # (rows (G, n), eigenvalues (G, n), eigenvectors (G, n, n))
        for n in np.unique(sizes):
            if n == 0:
                continue
            rows = np.stack([groups[i] for i in np.flatnonzero(sizes == n)])
            A_g = A[rows]  # (G, n, J)
            lam, U = np.linalg.eigh(A_g @ np.swapaxes(A_g, 1, 2))
            self._classes.append((rows, np.clip(lam, 0.0, None), U))
        self.group_of_row = np.full(self.n_rows, -1)
        for k, g in enumerate(groups):
            self.group_of_row[g] = k
        self.n_groups = len(groups)

    def rotate(self, r: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per size class: U^T r of each group (G, n) and its eigenvalues (G, n)."""
        return [np.einsum("gji,gj->gi", U, r[rows]) for rows, _, U in self._classes], [c[1] for c in self._classes]

    def whitened(self, r: np.ndarray, sigma: float) -> np.ndarray:
        """Whitened residuals of the grouped rows, flat, in no particular order (for scale estimates)."""
        y, lam = self.rotate(r)
        if not y:
            return np.zeros(0)
        return np.concatenate([(yc / np.sqrt(sigma**2 + self.sigma_q**2 * lc)).ravel() for yc, lc in zip(y, lam)])

    def group_norms(self, r: np.ndarray, sigma: float) -> np.ndarray:
        """(n_groups,) squared whitened norm of each group's residuals, in the order of `groups`."""
        out = np.zeros(self.n_groups)
        y, lam = self.rotate(r)
        for (rows, _, _), yc, lc in zip(self._classes, y, lam):
            out[self.group_of_row[rows[:, 0]]] = np.sum(yc**2 / (sigma**2 + self.sigma_q**2 * lc), axis=1)
        return out

    def matrix(self, sigma: float) -> scipy.sparse.csr_matrix:
        """W (R, R), block diagonal over the groups; rows in no group get zero weight."""
        data, rr, cc = [], [], []
        for rows, lam, U in self._classes:
            n = rows.shape[1]
            W = np.swapaxes(U, 1, 2) / np.sqrt(sigma**2 + self.sigma_q**2 * lam)[:, :, None]  # (G, n, n)
            data.append(W.ravel())
            rr.append(np.repeat(rows, n, axis=1).ravel())
            cc.append(np.tile(rows, (1, n)).ravel())
        if not data:
            return scipy.sparse.csr_matrix((self.n_rows, self.n_rows))
        return scipy.sparse.csr_matrix(
            (np.concatenate(data), (np.concatenate(rr), np.concatenate(cc))), shape=(self.n_rows, self.n_rows)
        )
