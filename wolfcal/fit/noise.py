"""The noise model of one measurement block: independent noise per measured number plus the errors that groups of
measurements share.

Residual rows of one group (e.g. every corner seen at one still pose: they share its encoder quantisation) have
covariance C_g = sigma^2 I + U_g U_g^T. U_g is thin (n rows, k columns, k does not grow with n): sigma_q * A for the
rows of each joint reading in the group (A = d(rows)/d(joint readings)) and tau per repeating detection error
(`SharedErrors`). Its thin SVD U_g = Q_g diag(s_g) V_g^T gives the symmetric whitening

    C_g^-1/2 = I / sigma + Q_g diag(1 / sqrt(sigma^2 + s_g^2) - 1 / sigma) Q_g^T,

applied as an operator: no n x n matrix is ever formed, so memory and time grow linearly with a group's length (a
still pose held for hundreds of frames). Each whitened number belongs to one measured row. The SVD is done once per
linearisation, so trying another sigma (the noise-level search) costs one division; groups of equal size are
decomposed in one batched call. Rows may have their own noise level, sigma * s_i (`row_scale` s, e.g. one per
motion-capture marker): with D = diag(s), C_g = D (sigma^2 I + D^-1 U_g U_g^T D^-1) D, so the same whitening of the
factors D^-1 U_g whitens D^-1 r.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from wolfcal.fit.columns import ColumnMatrix, is_sparse, scipy_sparse

# Half-width over which `weighted_median` spreads each value's weight, in the values' unit: for standardised residuals
# (median 0.67 when the noise model fits) it shifts the median of a normal sample by about 1e-4 of itself, and it
# spans several neighbouring values around the median of a block of 100 rows or more.
MEDIAN_WIDTH = 0.05
RANK_TOLERANCE = 1e-12  # singular values below this fraction of a group's largest are dropped (no shared error)
# The same from the eigenvalues of U U^T, which rounding blurs by ~1e-15 of the largest: a singular value below 1e-6
# of the group's largest adds less than 1e-12 of its share to the covariance
GRAM_RANK_TOLERANCE = 1e-12
EIGEN_TOLERANCE = 1e-9  # squared singular values closer than this fraction of a group's largest are one eigenvalue
# Entries of the shared-error matrices U_g decomposed in one batched call (a long recording's groups in batches: a
# few MB at a time)
DECOMPOSE_ENTRIES = 1 << 18


def row_groups(labels: np.ndarray, dim: int, keep: np.ndarray | None = None) -> np.ndarray:
    """(U * dim,) group of each row: unit u (label labels[u]) owns rows u*dim .. u*dim+dim-1; groups numbered
    0, 1, ... in ascending label order; rows of units with keep False are in no group (-1)."""
    units = np.arange(len(labels)) if keep is None else np.flatnonzero(keep)
    group = np.full(len(labels), -1)
    group[units] = np.unique(labels[units], return_inverse=True)[1].ravel()
    return np.repeat(group, dim)


def _left_factors(U: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Left singular vectors Q (G, n, r) and squared singular values (G, r), largest first, of a batch of factors
    U (G, n, k), and which are kept (G, r): those above the rank tolerance of each group's largest. A group with no
    more rows than columns (a view's or a pose's few corners against the joints) from the eigenvectors of U U^T (half
    the time of an SVD; orthonormal to rounding, the squares to rounding of the largest: kept above
    GRAM_RANK_TOLERANCE of it), else by SVD (a long still pose: never an n x n matrix)."""
    n, k = U.shape[1:]
    if n <= k:
        s2, Q = np.linalg.eigh(U @ np.swapaxes(U, 1, 2))
        s2, Q = np.maximum(s2[:, ::-1], 0.0), Q[:, :, ::-1]
        return Q, s2, s2 > GRAM_RANK_TOLERANCE * s2[:, :1]
    Q, s, _ = np.linalg.svd(U, full_matrices=False)
    return Q, s**2, s > RANK_TOLERANCE * s[:, :1]


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


def _slots(group: np.ndarray, key: np.ndarray, on: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Index of each row's key among the distinct keys of its group (-1 where `on` is False), and the number of
    distinct keys per group."""
    slot = np.full(len(group), -1)
    if not on.any():
        return slot, np.zeros(n_groups, dtype=int)
    pairs, inverse = np.unique(group[on] * (int(key[on].max()) + 1) + key[on], return_inverse=True)
    pair_group = pairs // (int(key[on].max()) + 1)
    slot[on] = (np.arange(len(pairs)) - np.searchsorted(pair_group, pair_group))[inverse.ravel()]
    return slot, np.bincount(pair_group, minlength=n_groups)


class GroupedWhitening:
    """Whitening of residual rows split into groups (`group_of_row`: (R,) group 0, 1, ... of each row, -1 for none)
    with covariance sigma^2 I + (shared part), the shared part from `SharedErrors`; rows of different groups are
    independent, rows in no group get zero weight."""

    def __init__(
        self,
        group_of_row: np.ndarray,
        shared: SharedErrors,
        row_scale: np.ndarray | None = None,
        factors: tuple[ColumnMatrix, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """`factors`: (Q, s^2, group of each column) when already decomposed (`chunks`)."""
        self.group_of_row, self.shared = group_of_row, shared
        self.row_scale = np.ones(len(group_of_row)) if row_scale is None else np.asarray(row_scale, dtype=float)
        self.at_level = bool(np.all(self.row_scale == 1.0))  # every row at the block's level: D = I
        self.in_group = group_of_row >= 0
        self.n_rows, self.n_groups = len(group_of_row), int(group_of_row.max()) + 1 if self.in_group.any() else 0
        grouped = np.flatnonzero(self.in_group)
        self.rows = grouped[np.argsort(group_of_row[grouped], kind="stable")]  # grouped rows, group by group
        sizes = np.bincount(group_of_row[grouped], minlength=self.n_groups)
        self.Q, self.s2, self.group_of_column = self._thin_factors(sizes) if factors is None else factors
        self._chunks: tuple[int, list[tuple[np.ndarray, GroupedWhitening]]] | None = None

    def chunks(self, max_rows: int) -> list[tuple[np.ndarray, GroupedWhitening]]:
        """The grouped rows a few whole groups at a time (consecutive groups up to `max_rows` rows; a larger group
        alone): each chunk's rows (R_c,) and the whitening of those rows alone, numerically the same as this one's
        on them (rows in no group carry no weight and are in no chunk). For sums over rows (normal equations)
        without whitening every row at once. Made once per `max_rows` and kept (a solve sums the normal equations
        at every step under one noise model: splitting the factors anew took 5 % of a 1000-sample fit's CPU)."""
        if self._chunks is None or self._chunks[0] != max_rows:
            self._chunks = (max_rows, list(self._split_chunks(max_rows)))
        return self._chunks[1]

    def _split_chunks(self, max_rows: int) -> Iterator[tuple[np.ndarray, GroupedWhitening]]:
        """`chunks`, made."""
        sizes = np.bincount(self.group_of_row[self.rows], minlength=self.n_groups)
        ends = np.concatenate([[0], np.cumsum(sizes)])  # in `rows`, of groups 0 .. n_groups
        position = np.zeros(self.n_rows, dtype=np.int64)
        position[self.rows] = np.arange(len(self.rows))
        first = 0
        while first < self.n_groups:
            end = max(int(np.searchsorted(ends, ends[first] + max_rows, side="right")) - 1, first + 1)
            rows = self.rows[ends[first] : ends[end]]
            columns = np.flatnonzero((self.group_of_column >= first) & (self.group_of_column < end))
            Q = self.Q.select(columns, position - ends[first], len(rows))
            # the part's factors are given: its rows' joint sensitivities are not copied (A without columns)
            shared = self.shared
            part = SharedErrors(np.empty((len(rows), 0)), shared.sigma_q, shared.reading[rows], shared.label[rows],
                                shared.axis[rows], shared.tau)  # fmt: skip
            factors = (Q, self.s2[columns], self.group_of_column[columns] - first)
            yield rows, GroupedWhitening(self.group_of_row[rows] - first, part, self.row_scale[rows], factors)
            first = end

    @staticmethod
    def _batches(sizes: np.ndarray, counts: list[np.ndarray], labels: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
        """Groups decomposed in one batched call: of one size n, in order, about DECOMPOSE_ENTRIES entries of their
        factors at a time (groups without shared errors are left out)."""
        widths = np.sum(counts, axis=0) + labels if counts else labels  # columns of each group (before rank)
        for n in np.unique(sizes[sizes > 0]):
            members = np.flatnonzero((sizes == n) & (widths > 0))
            if not len(members):
                continue
            per_batch = max(1, DECOMPOSE_ENTRIES // (n * int(widths[members].max())))
            for first in range(0, len(members), per_batch):
                yield int(n), members[first : first + per_batch]

    @property
    def QT(self):
        """Q^T: a view of Q's arrays (no copy)."""
        return self.Q.T

    def _thin_factors(self, sizes: np.ndarray) -> tuple[ColumnMatrix, np.ndarray, np.ndarray]:
        """Q (R, K) block diagonal over the groups (each group's left singular vectors of U_g), s^2 (K,) and the
        group of each column. Q is stored by columns (each column: its group's rows, ascending), built in place
        from the decompositions (a copy through (row, column) pairs would hold several times its size)."""
        shared, rows = self.shared, self.rows
        nonzero = shared.A != 0
        moving = np.flatnonzero(np.any(nonzero, axis=0))  # joints that move no row are left out
        nonzero = nonzero[:, moving]
        reading = shared.reading[:, None] if shared.reading.ndim == 1 else shared.reading[:, moving]
        group = self.group_of_row[rows]
        if reading.shape[1] == 1:  # one reading per row: all its joints' columns follow that reading's slot
            slot, count = _slots(group, reading[rows, 0], np.any(nonzero[rows], axis=1), self.n_groups)
            slots, counts = [slot] * len(moving), [count] * len(moving)
        else:
            pairs = [_slots(group, reading[rows, j], nonzero[rows, j], self.n_groups) for j in range(len(moving))]
            slots, counts = [p[0] for p in pairs], [p[1] for p in pairs]
        del nonzero
        n_axes = int(shared.axis.max()) + 1 if len(shared.axis) else 1
        labelled = (shared.label[rows] >= 0) & (shared.tau > 0)
        label_slot, labels = _slots(group, shared.label[rows] * n_axes + shared.axis[rows], labelled, self.n_groups)
        starts = np.concatenate([[0], np.cumsum(sizes)])
        data: list[np.ndarray] = []
        row_idx: list[np.ndarray] = []
        col_len: list[np.ndarray] = []
        s2: list[np.ndarray] = []
        group_of_column: list[np.ndarray] = []
        for n, members in self._batches(sizes, counts, labels):
            widths = [int(c[members].max(initial=0)) for c in counts]  # columns per joint: its distinct readings
            k_reading = int(np.sum(widths))
            k = k_reading + int(labels[members].max())
            at = (starts[members][:, None] + np.arange(n)).ravel()  # positions in `rows`, (G * n,)
            U = np.zeros((len(members) * n, k))
            firsts = np.cumsum([0, *widths[:-1]])
            if slots and all(slot is slots[0] for slot in slots):  # one reading per row: each joint at its slot
                has = np.flatnonzero(slots[0][at] >= 0)
                unit = rows[at][has]
                U[has[:, None], firsts + slots[0][at][has][:, None]] = (
                    shared.sigma_q * shared.A[unit][:, moving] / self.row_scale[unit][:, None]
                )
            else:
                for j, (slot, first) in enumerate(zip(slots, firsts)):
                    has = np.flatnonzero(slot[at] >= 0)
                    unit = rows[at][has]
                    U[has, first + slot[at][has]] = shared.sigma_q * shared.A[unit, moving[j]] / self.row_scale[unit]
            has = np.flatnonzero(label_slot[at] >= 0)
            U[has, k_reading + label_slot[at][has]] = shared.tau / self.row_scale[rows[at][has]]
            Q, s_squared, kept = _left_factors(U.reshape(len(members), n, k))
            g, c = np.nonzero(kept)
            data.append(Q[g, :, c].ravel())
            row_idx.append(rows[at].reshape(len(members), n)[g].ravel().astype(np.int32))
            col_len.append(np.full(len(g), n))
            s2.append(s_squared[g, c])
            group_of_column.append(members[g])
        if not data:
            return ColumnMatrix.empty(self.n_rows), np.zeros(0), np.zeros(0, dtype=int)
        indptr = np.concatenate([[0], np.cumsum(np.concatenate(col_len))])
        factor = ColumnMatrix(np.concatenate(data), np.concatenate(row_idx), indptr, self.n_rows)
        return factor, np.concatenate(s2), np.concatenate(group_of_column)

    def apply(self, M, sigma: float):
        """W M: the whitening of rows (R,) or (R, P), dense or sparse (then sparse); rows in no group become 0."""
        d = 1.0 / np.sqrt(sigma**2 + self.s2) - 1.0 / sigma
        keep = self.in_group / sigma
        if is_sparse(M):  # a sparse Jacobian (many unknowns): scipy.sparse is loaded
            sparse = scipy_sparse()
            Q = self.Q.as_scipy
            M = sparse.diags(1.0 / self.row_scale) @ M
            shared = Q @ (sparse.diags(d) @ (Q.T @ M))
            return (sparse.diags(keep) @ M + shared).tocsr()
        M = np.asarray(M, dtype=float)
        if M.ndim == 1:
            M = M / self.row_scale
            return keep * M + self.Q @ (d * (self.QT @ M))
        M = M / self.row_scale[:, None]
        out = self.Q @ (d[:, None] * (self.QT @ M))
        out += keep[:, None] * M
        return out

    def split(self, M, sigma: float):
        """W_s M, (R + K) rows: the whitening that keeps the two kinds of error apart. Rows 0..R-1: each measured
        row's part outside its group's shared errors, (I - Q Q^T) D^-1 M / sigma (a misdetected corner stays in its
        own row); rows R..R+K-1: each shared error's component, Q^T D^-1 M / sqrt(sigma^2 + s^2) (a stale joint
        reading shows in these few numbers). W_s^T W_s = C^-1 like `apply`'s W, and W_s is unique (no choice of
        basis), so a loss applied per number (the robust fit's) does not depend on how a group was decomposed."""
        scale = 1.0 / np.sqrt(sigma**2 + self.s2)
        keep = self.in_group / sigma
        if is_sparse(M):  # a sparse Jacobian (many unknowns): scipy.sparse is loaded
            sparse = scipy_sparse()
            Q = self.Q.as_scipy
            M = sparse.diags(1.0 / self.row_scale) @ M
            t = Q.T @ M
            own = sparse.diags(keep) @ (M - Q @ t)
            return sparse.vstack([own, sparse.diags(scale) @ t]).tocsr()
        M = np.asarray(M, dtype=float)
        M = M / (self.row_scale if M.ndim == 1 else self.row_scale[:, None])
        t = self.QT @ M
        own = M - self.Q @ t
        own *= keep if M.ndim == 1 else keep[:, None]
        return np.concatenate([own, t * (scale if M.ndim == 1 else scale[:, None])])

    def split_normal(
        self, M: np.ndarray, sigma: float, weight: np.ndarray, v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(W_s M)^T diag(weight) W_s M (P, P) and (W_s M)^T v (P,) of dense rows M (R, P) (W_s: `split`; weight
        and v (R + K,): one number per split row), without forming W_s M when every row is in a group (a `chunks`
        part) and few measured rows have a weight other than 1. With N = D^-1 M and T = Q^T N, the measured rows'
        part (I - Q Q^T) N / sigma has the Gram matrix (N^T N - T^T T) / sigma^2 (Q^T Q = I); the rows weighted
        otherwise add (weight - 1) times their own outer product. Equal to the explicit sum to rounding (the
        cancellation in N^T N - T^T T costs ~1e-13 of it where the shared errors dominate); symmetric. Half the CPU
        of forming the split rows (a copy of R + K rows and two sparse products per column)."""
        R = self.n_rows
        odd = np.flatnonzero(weight[:R] != 1.0)
        if not self.in_group.all() or 4 * len(odd) > R:
            J = self.split(M, sigma)
            H = J.T @ (weight[:, None] * J)
            return 0.5 * (H + H.T), J.T @ v
        N = M if self.at_level else M / self.row_scale[:, None]
        T = self.QT @ N
        shared = 1.0 / (sigma**2 + self.s2)
        H = N.T @ N / sigma**2 + T.T @ ((shared * weight[R:] - 1.0 / sigma**2)[:, None] * T)
        if len(odd):
            own = (N[odd] - (self.Q @ T)[odd]) / sigma
            H += own.T @ ((weight[odd] - 1.0)[:, None] * own)
        g = (N.T @ v[:R] - T.T @ (self.QT @ v[:R])) / sigma + T.T @ (np.sqrt(shared) * v[R:])
        return 0.5 * (H + H.T), g

    def standardized(self, r: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """Numbers of the grouped rows that are each N(0, 1) when the model fits, and the degrees of freedom each
        carries (for robust scale estimates, `weighted_median`), independent of how a group's covariance is
        decomposed: per row and per eigenspace of the group's shared part (the span of its shared errors' singular
        vectors of one size, and the rest: the row's own part), the row's projection onto it divided by its standard
        deviation there, weighted by the row's share h of that eigenspace (a row's shares sum to 1, a group's
        weights to its number of rows, as an eigenbasis of its covariance would count them; an eigenspace of one
        vector gives every row the same number, its component). Rows the shared errors explain fully carry no
        information on sigma and are dropped."""
        return self.standardizer(r)(sigma)

    def standardizer(self, r: np.ndarray) -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
        """sigma -> `standardized(r, sigma)`, with everything that does not depend on sigma (projections, shares,
        eigenspaces) done once: a noise-level search evaluates it at many sigma."""
        r = r / self.row_scale
        Q, per_column = self.Q, np.diff(self.Q.indptr)
        tr = self.QT @ r
        own = (r - Q @ tr)[self.rows]
        free = 1.0 - np.bincount(Q.indices, Q.data**2, minlength=self.n_rows)[self.rows]
        informative = free > RANK_TOLERANCE**0.5
        own, root_free, weights = own[informative], np.sqrt(free[informative]), [free[informative]]
        if len(self.s2):
            # one number per (row, eigenspace of its group), ordered by row, then eigenspace: from Q's layout (each
            # column holds its group's rows; a group's eigenspaces are numbered consecutively), no sort
            space, group = self._eigenspaces(), self.group_of_column
            first = np.full(self.n_groups, len(space))
            np.minimum.at(first, group, space)
            n_spaces = np.zeros(self.n_groups, dtype=np.int64)
            np.maximum.at(n_spaces, group, space - first[group] + 1)
            spaces_of_row = np.zeros(self.n_rows, dtype=np.int64)
            spaces_of_row[self.rows] = n_spaces[self.group_of_row[self.rows]]
            offset = np.cumsum(spaces_of_row) - spaces_of_row
            key = np.repeat(space - first[group], per_column)
            key += offset[Q.indices]
            share = np.bincount(key, Q.data**2)
            on = share > RANK_TOLERANCE
            root_share = np.sqrt(share[on])
            weights.append(share[on])
        weight = np.concatenate(weights)

        n_own, n_numbers = len(own), int(np.count_nonzero(on)) if len(self.s2) else 0

        def at(sigma: float) -> tuple[np.ndarray, np.ndarray]:  # written into one array, few temporaries (memory)
            values = np.empty(n_own + n_numbers)
            np.divide(own, sigma, out=values[:n_own])
            values[:n_own] /= root_free
            if n_numbers:
                t = tr / np.sqrt(sigma**2 + self.s2)
                entries = np.repeat(t, per_column)
                entries *= Q.data
                sums = np.bincount(key, entries)  # per (row, eigenspace)
                del entries  # one number per value of Q, not kept beside the sums (as large as Q)
                np.compress(on, sums, out=values[n_own:])  # no copy of the kept sums beside them
                del sums
                values[n_own:] /= root_share
            return values, weight

        return at

    def _eigenspaces(self) -> np.ndarray:
        """(K,) eigenspace of each shared column: columns of one group whose s^2 agree to EIGEN_TOLERANCE of the
        group's largest share one."""
        order = np.lexsort((self.s2, self.group_of_column))
        s2, group = self.s2[order], self.group_of_column[order]
        largest = np.zeros(self.n_groups)
        np.maximum.at(largest, group, s2)
        new = np.ones(len(order), dtype=bool)
        new[1:] = (group[1:] != group[:-1]) | (s2[1:] - s2[:-1] > EIGEN_TOLERANCE * largest[group[1:]])
        space = np.empty(len(order), dtype=np.int64)
        space[order] = np.cumsum(new) - 1
        return space

    def group_norms(self, r: np.ndarray, sigma: float) -> np.ndarray:
        """(n_groups,) squared whitened norm r_g^T C_g^-1 r_g of each group's residuals."""
        r = r / self.row_scale
        t = self.QT @ r
        independent = np.bincount(self.group_of_row[self.rows], r[self.rows] ** 2, self.n_groups) / sigma**2
        shared = np.bincount(self.group_of_column, t**2 * (1.0 / (sigma**2 + self.s2) - 1.0 / sigma**2), self.n_groups)
        return independent + shared


def weighted_median(values: np.ndarray, weights: np.ndarray, width: float = MEDIAN_WIDTH) -> float:
    """The median of the weighted values with each value's weight spread evenly over +- `width` around it: where
    their cumulative weight (piecewise linear) reaches half of the total. Unlike a plain weighted median (an order
    statistic, which jumps from one value to the next as the weights' order changes: 2 % of a noise level from 128
    rows, enough to move a fit's noise model and with it its estimates by a sizable fraction of a standard
    deviation), a continuous function of the values where they lie closer than 2 `width` around the median; NaN
    for no values. Found within a window around the values' plain median that holds it, narrowed by bisection to
    about `width` (a few passes over the values), sorting only the values whose spread reaches into the window
    (usually a small share of them)."""
    if values.size == 0:
        return float("nan")
    half = 0.5 * float(np.sum(weights))
    levels = (half * (1.0 - 1e-9), half * (1.0 + 1e-9))
    center, reach = float(np.median(values)), 4.0 * width
    low, high = float(values.min()) - width, float(values.max()) + width
    while True:  # the window [a, b]: the cumulative weight below both levels at a, above both at b
        a, b = max(center - reach, low), min(center + reach, high)
        below_a = _weight_below(values, weights, a, width)
        if (below_a < levels[0] and _weight_below(values, weights, b, width) > levels[1]) or (a, b) == (low, high):
            break
        reach *= 4.0
    while b - a > width:  # narrowed by bisection: fewer values' spreads reach into it (a pass each, no sort)
        mid = 0.5 * (a + b)
        below_mid = _weight_below(values, weights, mid, width)
        if below_mid < levels[0]:
            a, below_a = mid, below_mid
        elif below_mid > levels[1]:
            b = mid
        else:
            break
    near = (values > a - width) & (values < b + width)  # the values whose spread reaches into the window
    spread = np.concatenate([values[near] - width, values[near] + width])
    step = np.concatenate([weights[near], -weights[near]]) / (2.0 * width)  # the slope's change at each edge
    inside = (spread > a) & (spread < b)
    order = np.argsort(spread[inside])
    edges = np.concatenate([[a], spread[inside][order], [b]])
    slope = np.concatenate([[float(np.sum(step[spread <= a]))], step[inside][order], [0.0]])
    np.cumsum(slope, out=slope)  # the cumulative weight's slope after each edge
    cumulative = below_a + np.concatenate([[0.0], np.cumsum(slope[:-1] * np.diff(edges))])  # at each edge

    def at(level: float) -> float:  # where the cumulative weight reaches `level`
        k = min(int(np.searchsorted(cumulative, level)), len(edges) - 1)  # first edge at or above it
        if k == 0 or slope[k - 1] <= 0.0:
            return float(edges[k])
        return float(edges[k - 1] + (level - cumulative[k - 1]) / slope[k - 1])

    # a stretch without values at exactly half (values further apart than 2 width): its middle, not the end that
    # rounding picks
    return 0.5 * (at(levels[0]) + at(levels[1]))


def _weight_below(values: np.ndarray, weights: np.ndarray, x: float, width: float) -> float:
    """The cumulative weight of `weighted_median` at x: each value's weight spread over +- width, the part below x."""
    share = np.subtract(x, values)  # one temporary, worked in place (the values of a long fit: 390k)
    share *= 1.0 / (2.0 * width)
    share += 0.5
    return float(np.clip(share, 0.0, 1.0, out=share) @ weights)


def weighted_median_above(
    values: np.ndarray, weights: np.ndarray, threshold: float, width: float = MEDIAN_WIDTH
) -> bool:
    """Whether `weighted_median(values, weights, width)` exceeds `threshold`, without sorting (one pass over the
    values: a noise-level search asks this many times): less than half of the weight lies below it."""
    if values.size == 0:
        return False
    return _weight_below(values, weights, threshold, width) <= 0.5 * float(np.sum(weights))
