"""The noise groups' thin factors Q (`wolfcal.fit.noise`) as a numpy matrix stored by columns, and its products.

Q (R, K) is block diagonal over the noise groups: a group's columns (its shared errors' left singular vectors)
hold its rows and no others. Stored by columns in scipy's csc layout (column c: values data[indptr[c]:indptr[c+1]]
in rows indices[...], a group's columns consecutive, each listing the group's rows in one order), so no R x K
matrix is formed. Products with dense matrices run group by group: groups of the same shape in one batched
matrix product (a group's rows gathered once, not once per column). Why not scipy.sparse: the dense fit path
then does not import it (its array-API layer loads numpy.f2py and numpy.testing), an import that costs about as
much as the rest of a fit from cached detections (docs/performance.md); a sparse Jacobian (more than DENSE_LIMIT
unknowns) still uses scipy.sparse, through `as_scipy`.
"""

from __future__ import annotations

import sys
from functools import cached_property
from types import ModuleType
from typing import Any

import numpy as np


def scipy_sparse() -> ModuleType:
    """scipy.sparse, imported when first needed: by a sparse Jacobian (more than DENSE_LIMIT unknowns) only."""
    import scipy.sparse

    return scipy.sparse


def is_sparse(M: Any) -> bool:
    """Whether M is a scipy.sparse matrix, without importing scipy.sparse (no sparse matrix exists before it is)."""
    sparse = sys.modules.get("scipy.sparse")
    return sparse is not None and bool(sparse.issparse(M))


class ColumnMatrix:
    """A block-diagonal (R, K) matrix stored by columns; `Q @ x` and `Q.T @ M` for dense x (K,) / (K, P) and M (R,)
    / (R, P)."""

    def __init__(self, data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, n_rows: int) -> None:
        self._stored = (np.asarray(data, dtype=float), np.asarray(indices), np.asarray(indptr, dtype=np.int64))
        self.shape = (int(n_rows), len(self._stored[2]) - 1)

    def _entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(data, indices, indptr): the csc layout."""
        return self._stored

    @property
    def data(self) -> np.ndarray:
        """(nnz,) the values, column after column."""
        return self._entries()[0]

    @property
    def indices(self) -> np.ndarray:
        """(nnz,) the row of each value."""
        return self._entries()[1]

    @property
    def indptr(self) -> np.ndarray:
        """(K + 1,) where each column's values begin in `data`, then nnz."""
        return self._entries()[2]

    @classmethod
    def empty(cls, n_rows: int) -> ColumnMatrix:
        return cls(np.zeros(0), np.zeros(0, dtype=np.int32), np.zeros(1, dtype=np.int64), n_rows)

    @property
    def nnz(self) -> int:
        return len(self.data)

    @property
    def T(self) -> _Transposed:
        return _Transposed(self)

    def select(self, columns: np.ndarray, row_map: np.ndarray, n_rows: int) -> ColumnMatrix:
        """The matrix of `columns` (ascending, whole groups: a group's columns all or none), each entry's row r
        moved to row_map[r], with n_rows rows (`_Selection`: its products use this matrix's values, not a copy)."""
        return _Selection(self, columns, row_map, n_rows)

    @cached_property
    def as_scipy(self):
        """The same matrix as scipy.sparse.csc_matrix (for products with sparse matrices: a sparse Jacobian), made
        once (its arrays shared, not copied)."""
        return scipy_sparse().csc_matrix((self.data, self.indices, self.indptr), shape=self.shape)

    @cached_property
    def _groups(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per shape (n rows, k columns): the groups of that shape (G of them) as (rows (G, n), columns (G, k),
        values (G, n, k)). Grouped by exact shape, not padded to a common k: each group's products are then the
        same numbers whichever other groups it is batched with (a fit summed chunk by chunk is the fit in one)."""
        K = self.shape[1]
        if K == 0:
            return []
        length = np.diff(self.indptr)
        first_row = self.indices[self.indptr[:-1]]
        new = np.ones(K, dtype=bool)
        new[1:] = (first_row[1:] != first_row[:-1]) | (length[1:] != length[:-1])  # a group's columns are consecutive
        head = np.flatnonzero(new)  # first column of each group
        width = np.diff(np.append(head, K))  # columns per group
        base = int(width.max()) + 1
        shape_key = length[head] * base + width  # (n, k) as one number
        order = np.argsort(shape_key, kind="stable")  # groups of one shape in column order
        keys, starts = np.unique(shape_key[order], return_index=True)
        out = []
        for key, heads in zip(keys, np.split(head[order], starts[1:])):
            n, k = divmod(int(key), base)
            columns = heads[:, None] + np.arange(k)  # (G, k)
            rows = self.indices[self.indptr[heads][:, None] + np.arange(n)]  # (G, n)
            values = self.data[self.indptr[columns][:, :, None] + np.arange(n)].swapaxes(1, 2)  # (G, n, k)
            out.append((rows, columns, np.ascontiguousarray(values)))
        return out

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        """Q x for dense x (K,) or (K, P): (R,) or (R, P); rows in no group are 0."""
        x = np.asarray(x, dtype=float)
        x2 = x[:, None] if x.ndim == 1 else x
        out = np.zeros((self.shape[0], x2.shape[1]))
        for rows, columns, values in self._groups:
            out[rows] = values @ x2[columns]
        return out[:, 0] if x.ndim == 1 else out

    def rmatmul(self, M: np.ndarray) -> np.ndarray:
        """Q^T M for dense M (R,) or (R, P): (K,) or (K, P)."""
        M = np.asarray(M, dtype=float)
        M2 = M[:, None] if M.ndim == 1 else M
        out = np.zeros((self.shape[1], M2.shape[1]))
        for rows, columns, values in self._groups:
            out[columns] = values.swapaxes(1, 2) @ M2[rows]
        return out[:, 0] if M.ndim == 1 else out


class _Selection(ColumnMatrix):
    """Whole groups of a ColumnMatrix (`ColumnMatrix.select`: a chunk of the noise groups), rows renumbered. Its
    products run on its source's batches (`_groups`) of those groups: the values are views of the source's where a
    shape's groups in the selection are consecutive (a chunk of consecutive groups: always), the rows and columns
    renumbered copies (one number per row or column, not per value), so the same numbers as a copy of the columns
    would give, without holding the chunk's values twice; the csc layout is copied out only when asked for (`data`,
    `indices`, `indptr`: a sparse Jacobian's `as_scipy`)."""

    def __init__(self, source: ColumnMatrix, columns: np.ndarray, row_map: np.ndarray, n_rows: int) -> None:
        self.source, self.columns, self.row_map = source, np.asarray(columns, dtype=np.int64), row_map
        self.shape = (int(n_rows), len(self.columns))

    @cached_property
    def _copied(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        source, columns = self.source, self.columns
        lengths = np.diff(source.indptr)[columns]
        indptr = np.concatenate([[0], np.cumsum(lengths)])
        entry = np.repeat(source.indptr[columns] - indptr[:-1], lengths) + np.arange(indptr[-1])
        return source.data[entry], self.row_map[source.indices[entry]], indptr.astype(np.int64)

    def _entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._copied

    @cached_property
    def _groups(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The source's batches restricted to the selected groups, in the source's order (by shape, then column):
        the order `ColumnMatrix._groups` gives the selection's own columns."""
        position = np.full(self.source.shape[1], -1, dtype=np.int64)
        position[self.columns] = np.arange(len(self.columns))
        out = []
        for rows, columns, values in self.source._groups:
            picked = np.flatnonzero(position[columns[:, 0]] >= 0)
            if not len(picked):
                continue
            if picked[-1] - picked[0] + 1 == len(picked):  # consecutive: views
                picked = slice(int(picked[0]), int(picked[-1]) + 1)  # type: ignore[assignment]
            out.append((self.row_map[rows[picked]], position[columns[picked]], values[picked]))
        return out


class _Transposed:
    """Q^T of a `ColumnMatrix`: `Q.T @ M` for dense M."""

    def __init__(self, matrix: ColumnMatrix) -> None:
        self.matrix = matrix

    def __matmul__(self, M: np.ndarray) -> np.ndarray:
        return self.matrix.rmatmul(M)
