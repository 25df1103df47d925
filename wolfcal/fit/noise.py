"""The noise model of one measurement block: independent noise per measured number plus the errors that groups of
measurements share.

Residual rows of one group (e.g. every corner seen at one still pose: they share its encoder quantisation) have
covariance C_g = sigma^2 I + S_g, S_g = sigma_q^2 A_g A_g^T (A_g = d(rows)/d(joint readings)) plus any repeating
detection error (`SharedErrors`). With S_g = U diag(l) U^T, W_g = diag(1 / sqrt(sigma^2 + l)) U^T whitens them
(W_g^T W_g = C_g^-1). The eigen-decomposition is
done once per linearisation, so trying another sigma (the noise-level search) costs one division. Groups of equal
size are decomposed in one batched call. Rows may have their own noise level, sigma * s_i (`row_scale` s, e.g. one per
motion-capture marker): with D = diag(s), C_g = D (sigma^2 I + D^-1 S_g D^-1) D, so the same decomposition of
D^-1 S_g D^-1 whitens r / s.
"""

from __future__ import annotations

from dataclasses import dataclass

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


@dataclass
class SharedErrors:
    """Errors that rows share besides their own noise: the joint readings of a still pose (rows with the same
    `reading` share sigma_q^2 A A^T; with a reading group per joint, rows with the same group of joint j share
    sigma_q^2 A_j A_j^T: legs that held still while the head moved) and a detection error that repeats (rows with
    the same `label` >= 0 and the same `axis` share tau^2: a tag that a fixed camera sees in the same place in every
    frame)."""

    A: np.ndarray  # (R, J) d(row)/d(joint readings)
    sigma_q: float  # joint reading noise [rad]
    reading: np.ndarray  # (R,) reading group of each row, or (R, J) of each row's reading of each joint
    label: np.ndarray  # (R,) shared detection error of each row, -1 for none
    axis: np.ndarray  # (R,) measured axis of each row (u, v, ...)
    tau: float = 0.0  # shared detection error per axis [the block's unit]

    def covariance(self, rows: np.ndarray) -> np.ndarray:
        """(G, n, n) shared part of the covariance of groups of rows (G, n)."""
        A, reading = self.A[rows], self.reading[rows]
        if self.reading.ndim == 2:
            C = np.zeros(rows.shape + rows.shape[-1:])
            for j in range(A.shape[-1]):
                same = reading[:, :, None, j] == reading[:, None, :, j]
                C += self.sigma_q**2 * (A[:, :, j, None] * A[:, None, :, j]) * same
        else:
            C = self.sigma_q**2 * (A @ np.swapaxes(A, 1, 2)) * (reading[:, :, None] == reading[:, None, :])
        if self.tau > 0:
            label, axis = self.label[rows], self.axis[rows]
            shared = (label[:, :, None] == label[:, None, :]) & (label[:, :, None] >= 0)
            shared &= axis[:, :, None] == axis[:, None, :]
            C = C + self.tau**2 * shared
        return C


class GroupedWhitening:
    """Whitening of residual rows split into groups (list of row-index arrays) with covariance
    sigma^2 I + (shared part), the shared part from `SharedErrors`; rows of different groups are independent."""

    def __init__(self, groups: list[np.ndarray], shared: SharedErrors, row_scale: np.ndarray | None = None) -> None:
        self.groups, self.shared = groups, shared
        self.n_rows = len(shared.A)
        self.row_scale = np.ones(self.n_rows) if row_scale is None else np.asarray(row_scale, dtype=float)
        sizes = np.array([len(g) for g in groups], dtype=int)
        self._classes = []  # (rows (G, n), eigenvalues (G, n), eigenvectors (G, n, n))
        for n in np.unique(sizes):
            if n == 0:
                continue
            rows = np.stack([groups[i] for i in np.flatnonzero(sizes == n)])
            s = self.row_scale[rows]
            lam, U = np.linalg.eigh(shared.covariance(rows) / (s[:, :, None] * s[:, None, :]))
            self._classes.append((rows, np.clip(lam, 0.0, None), U))
        self.group_of_row = np.full(self.n_rows, -1)
        for k, g in enumerate(groups):
            self.group_of_row[g] = k
        self.n_groups = len(groups)

    def with_shared(self, shared: SharedErrors) -> GroupedWhitening:
        """The same groups under another shared part (e.g. another size of the shared detection error)."""
        return GroupedWhitening(self.groups, shared, self.row_scale)

    def rotate(self, r: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per size class: U^T r of each group (G, n) and its eigenvalues (G, n)."""
        scaled = r / self.row_scale
        return [np.einsum("gji,gj->gi", U, scaled[rows]) for rows, _, U in self._classes], [c[1] for c in self._classes]

    def whitened(self, r: np.ndarray, sigma: float) -> np.ndarray:
        """Whitened residuals of the grouped rows, flat, in no particular order (for scale estimates)."""
        y, lam = self.rotate(r)
        if not y:
            return np.zeros(0)
        return np.concatenate([(yc / np.sqrt(sigma**2 + lc)).ravel() for yc, lc in zip(y, lam)])

    def group_norms(self, r: np.ndarray, sigma: float) -> np.ndarray:
        """(n_groups,) squared whitened norm of each group's residuals, in the order of `groups`."""
        out = np.zeros(self.n_groups)
        y, lam = self.rotate(r)
        for (rows, _, _), yc, lc in zip(self._classes, y, lam):
            out[self.group_of_row[rows[:, 0]]] = np.sum(yc**2 / (sigma**2 + lc), axis=1)
        return out

    def matrix(self, sigma: float) -> scipy.sparse.csr_matrix:
        """W (R, R), block diagonal over the groups; rows in no group get zero weight."""
        data, rr, cc = [], [], []
        for rows, lam, U in self._classes:
            n = rows.shape[1]
            W = np.swapaxes(U, 1, 2) / np.sqrt(sigma**2 + lam)[:, :, None] / self.row_scale[rows][:, None, :]
            data.append(W.ravel())
            rr.append(np.repeat(rows, n, axis=1).ravel())
            cc.append(np.tile(rows, (1, n)).ravel())
        if not data:
            return scipy.sparse.csr_matrix((self.n_rows, self.n_rows))
        return scipy.sparse.csr_matrix(
            (np.concatenate(data), (np.concatenate(rr), np.concatenate(cc))), shape=(self.n_rows, self.n_rows)
        )
