"""The estimation problem: one parameter vector, a list of measurement blocks, Gaussian priors.

Unknowns are prior-normalised, z = (value - reference) / prior_sigma, so a prior residual is z itself. The first
`n_chain` unknowns change the robot model (shared by every block); each block's own unknowns follow. Data residuals
of a block are whitened by its noise model (`GroupedWhitening`, rebuilt per solver round at the current estimate)
and passed through a Huber-shaped function, so a misdetected view cannot drag the solution while priors stay
quadratic. Residuals and the Jacobian come from one linearisation per parameter vector (analytic derivatives);
the Jacobian is sparse when the blocks bring many unknowns (e.g. one camera pose per sample).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from wolfcal.fit.blocks import Block, Linearization
from wolfcal.fit.columns import is_sparse, scipy_sparse
from wolfcal.fit.noise import GroupedWhitening, SharedErrors, row_groups
from wolfcal.fit.uncertainty import triangular_factor
from wolfcal.graph import connected_components
from wolfcal.robot.parameters import ParameterSet

if TYPE_CHECKING:
    import scipy.sparse

DENSE_LIMIT = 300  # unknowns up to which the Jacobian is a dense matrix
MAD_TO_SIGMA = 1.4826  # standard deviation of a normal distribution per median absolute deviation
# Measured rows whitened at a time in the normal equations (whole noise groups): a few hundred KB per chunk of
# Jacobian, and large enough that numpy's per-call overhead stays small.
CHUNK_ROWS = 4096


def huber_sqrt(r: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Residual transform whose square is the Huber loss (r for |r| <= k, sign(r) sqrt(2k|r| - k^2) beyond), and
    its derivative."""
    a = np.abs(r)
    inside = a <= k
    root = np.sqrt(np.maximum(2.0 * k * a - k * k, 1e-300))
    return np.where(inside, r, np.sign(r) * root), np.where(inside, 1.0, k / root)


class BlockState:
    """A block's place in the problem and its current noise model and outlier set."""

    def __init__(self, block: Block, start: int, sigma: float, sigma_q: float) -> None:
        self.block, self.start, self.sigma, self.sigma_q = block, start, sigma, sigma_q
        # A detection error that repeats (the same tag seen from the same place) cannot show in the residuals: the
        # tag mount and the camera pose absorb it. Its size is the configured detection noise (priors.pixel_noise),
        # or the estimated noise level when that is larger (`shared_size`).
        self.shared_floor = sigma
        self.excluded = np.zeros(block.n_views, dtype=bool)  # (V,) views left out
        self.excluded_units = np.zeros(block.n_units, dtype=bool)  # (U,) single units left out (`Block.unit_rule`)
        self.groups = block.joint_reading_groups()  # (U, J) fixed: derived once
        self.labels = block.shared_labels()  # (U,) fixed: derived once
        self.classes = block.noise_classes()  # (U,) fixed: derived once
        self.unit_scale = np.ones(block.n_units)  # (U,) each unit's noise level relative to sigma (its class's)
        self.frames = block.unit_frames()  # (U,) frames averaged into each unit, None: one each
        self.scatter = block.unit_scatter()  # (U, dim) their squared deviations about the unit's mean
        self.whitening: GroupedWhitening | None = None

    def shared_size(self, sigma: float) -> float:
        """Size of a repeating detection error per axis [the block's unit] at the noise level `sigma`."""
        return max(sigma, self.shared_floor)

    @property
    def row_scale(self) -> np.ndarray:
        """(R,) each residual row's noise level relative to sigma: its class's, over sqrt(frames) of a mean."""
        scale = self.unit_scale if self.frames is None else self.unit_scale / np.sqrt(self.frames)
        return np.repeat(scale, self.block.dim)

    def frame_scatter(self) -> tuple[float, float]:
        """(sum of squared deviations [unit^2], degrees of freedom) of the frames averaged into the inlier units
        about their means (`Block.unit_scatter`); (0, 0) when the units are single measurements."""
        if self.frames is None or self.scatter is None:
            return 0.0, 0.0
        inlier = self.inlier_units
        return float(np.sum(self.scatter[inlier])), float(np.sum(self.frames[inlier] - 1) * self.block.dim)

    @property
    def inlier_units(self) -> np.ndarray:
        return ~self.excluded[self.block.view_of_unit] & ~self.excluded_units

    def shared_errors(self, lin: Linearization) -> SharedErrors:
        """The errors the block's rows share at this linearisation (see `SharedErrors`); a repeating detection
        error counts only where at least two inlier units share it (size: see `shared_floor`)."""
        block, d = self.block, self.block.dim
        A = lin.joint_sensitivity.reshape(-1, lin.joint_sensitivity.shape[-1])
        # Units the joint readings do not move (a tag fixed to the base seen by an external camera) share no
        # reading error: each is its own reading group, so only a shared detection error links them.
        moved = np.any(lin.joint_sensitivity != 0, axis=(1, 2))
        alone = self.groups.max(initial=0) + 1 + np.arange(block.n_units)
        reading = np.where(moved[:, None], self.groups, alone[:, None])  # (U, J)
        # one group per unit when every joint's groups agree (a still pose), else the unit of the joint's groups
        self.reading_of_unit = _one_group(reading)
        per_joint = np.any(reading != reading[:, :1], axis=1).any()
        label = np.where(self.inlier_units, self.labels, -1)
        # shared by at least two measurements: units, or the frames averaged into them
        weights = None if self.frames is None else self.frames[label >= 0]
        counts = np.bincount(label[label >= 0], weights) if np.any(label >= 0) else np.zeros(0, int)
        label = np.where((label >= 0) & (counts[np.maximum(label, 0)] >= 2) if len(counts) else False, label, -1)
        return SharedErrors(
            A=A,
            sigma_q=self.sigma_q,
            reading=np.repeat(reading, d, axis=0) if per_joint else np.repeat(self.reading_of_unit, d),
            label=np.repeat(label, d),
            axis=np.tile(np.arange(d), block.n_units),
            tau=self.shared_size(self.sigma),
        )

    def rebuild(self, lin: Linearization) -> None:
        """Noise groups over the inlier units at this linearisation (left-out views are in no group): units that
        share a joint reading or a repeating detection error are in one group."""
        self.whitening = None  # the old factors go before the new ones are built
        shared = self.shared_errors(lin)
        reading = self.reading_of_unit
        group_of_unit = reading
        label = shared.label[:: self.block.dim]
        if np.any(label >= 0):  # join reading groups linked by a shared detection error
            n_read = int(reading.max()) + 1
            linked = label >= 0
            n_nodes = n_read + int(label.max()) + 1
            group_of_unit = connected_components(n_nodes, reading[linked], n_read + label[linked])[reading]
        self.whitening = GroupedWhitening(
            row_groups(group_of_unit, self.block.dim, self.inlier_units), shared, self.row_scale
        )
        self.set_sigma(self.sigma)

    def set_sigma(self, sigma: float) -> bool:
        """Set the noise level per measured number [the block's unit]. The shared detection error's size follows
        it (`shared_size`); when that size changes the groups are decomposed again, so the next solve and the
        reported uncertainty use one noise model. Returns whether they were."""
        tau = self.shared_size(sigma)
        shared = self.noise_model.shared
        again = shared.tau != tau and np.any(shared.label >= 0)
        self.sigma = sigma
        if again:
            groups, row_scale = self.noise_model.group_of_row, self.noise_model.row_scale
            self.whitening = None  # the old factors go before the new ones are built
            self.whitening = GroupedWhitening(groups, replace(shared, tau=tau), row_scale)
        return bool(again)

    def whiten(self, M, split: bool = True):
        """The block's rows (R,) or (R, P) whitened at its noise level: `GroupedWhitening.split` (R + K rows, what
        the robust loss acts on) or, with split False, `GroupedWhitening.apply` (R rows, each on its measured row)."""
        return self.noise_model.split(M, self.sigma) if split else self.noise_model.apply(M, self.sigma)

    @property
    def noise_model(self) -> GroupedWhitening:
        """The whitening of the last `rebuild` (Problem builds one for every block before any use)."""
        if self.whitening is None:
            raise RuntimeError(f"{self.block.name}: noise model used before it was built (call rebuild first)")
        return self.whitening


class Problem:
    """See the module docstring. `chain` holds the robot-model parameters; blocks bring their own."""

    def __init__(
        self, chain: ParameterSet, blocks: Sequence[Block], sigmas: list[float], sigma_q: float, huber_k: float = 3.0
    ) -> None:
        self.chain, self.blocks, self.huber_k, self.sigma_q = chain, blocks, huber_k, sigma_q
        self.n_chain = len(chain)
        params, self.states, start = chain, [], len(chain)
        for block, sigma in zip(blocks, sigmas):
            self.states.append(BlockState(block, start, sigma, sigma_q))
            params = params + block.nuisance
            start += len(block.nuisance)
        self.params = params
        self._cache: tuple[bytes, list[Linearization]] | None = None
        self.start = self._start()
        for state, lin in zip(self.states, self.evaluate(self.start)):
            # Start each block's noise level at the spread of its residuals where the solve starts (at least
            # the configured value), so the first solve is least squares rather than a long walk along the
            # Huber loss's linear arms; the rounds then estimate it.
            r = lin.residual[np.all(np.abs(lin.residual) < 1e3, axis=1)]
            spread = MAD_TO_SIGMA * float(np.median(np.abs(r - np.median(r, axis=0)))) if r.size else 0.0
            state.sigma = max(state.sigma, spread)
        self.linearize(self.start)

    def _start(self) -> np.ndarray:
        """(P,) where the solve starts, prior-normalised: every unknown at its reference (z = 0), but the chain
        parameters that the first block's `Block.chain_start` holds at its values (the robot model the block was
        solved at alone: a fit that starts degrees off may settle on other lines for its points)."""
        z = np.zeros(len(self.params))
        start = next((b.chain_start for b in self.blocks if b.chain_start is not None), None)
        if start is not None:
            held = self.chain.held_by(start)
            moved = (self.chain.values_from(start) - self.chain.references) / self.chain.prior_sigmas
            z[: self.n_chain] = np.where(held, moved, 0.0)
        return z

    def values(self, z: np.ndarray) -> np.ndarray:
        return self.params.values(z)

    def local_values(self, values: np.ndarray, state: BlockState) -> np.ndarray:
        return values[state.start : state.start + len(state.block.nuisance)]

    def evaluate(self, z: np.ndarray) -> list[Linearization]:
        """Each block's linearisation at z (the last one is cached)."""
        key = np.asarray(z, dtype=float).tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = None  # dropped before the next one is built: only one linearisation in memory
            values = self.values(z)
            chain_values = values[: self.n_chain]
            lins = [s.block.linearize(chain_values, self.local_values(values, s), self.chain) for s in self.states]
            self._cache = (key, lins)
        return self._cache[1]

    def forget_linearization(self) -> None:
        """Drop the cached linearisation (`evaluate` builds the next one afresh)."""
        self._cache = None

    def linearize(self, z: np.ndarray) -> None:
        """Rebuild every block's noise model at z (joint sensitivities and inlier groups)."""
        for state, lin in zip(self.states, self.evaluate(z)):
            state.rebuild(lin)

    def raw_residuals(self, z: np.ndarray) -> list[np.ndarray]:
        """Per block: (U, dim) predicted minus measured [the block's unit]."""
        return [lin.residual for lin in self.evaluate(z)]

    def _whitened(self, z: np.ndarray) -> list[np.ndarray]:
        return [s.whiten(lin.residual.ravel()) for s, lin in zip(self.states, self.evaluate(z))]

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Robust whitened data residuals of every block (zero for left-out views), then the priors z."""
        parts = [huber_sqrt(w, self.huber_k)[0] for w in self._whitened(z)]
        return np.concatenate(parts + [np.asarray(z, dtype=float)])

    def data_jacobian(self, z: np.ndarray, robust: bool = True) -> np.ndarray | scipy.sparse.csr_matrix:
        """d(whitened data residuals)/dz, sparse above DENSE_LIMIT unknowns: of the robust residuals (R + K, P) or,
        with robust False, of the plainly whitened rows (R, P), row i of the block's measured row i (the same
        information J^T J either way)."""
        parts = []
        for state, lin, w in zip(self.states, self.evaluate(z), self._whitened(z)):
            J = state.whiten(self._rows_jacobian(state, lin, np.arange(lin.residual.size)), split=robust)
            if robust:
                scale = huber_sqrt(w, self.huber_k)[1]
                J = scipy_sparse().diags(scale) @ J if is_sparse(J) else np.multiply(J, scale[:, None], out=J)
            parts.append(J)
        if len(self.params) > DENSE_LIMIT:
            return scipy_sparse().vstack(parts).tocsr()
        return parts[0] if len(parts) == 1 else np.vstack(parts)

    def information(
        self, z: np.ndarray, triangular: bool = False, curvature: bool = False
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """J^T J (P, P) and J^T r (P,) of the robust whitened data residuals at z (J: `data_jacobian`, r: their
        part of `residuals`), summed over a few whole noise groups at a time (CHUNK_ROWS): the whole whitened
        Jacobian of a long recording is never in memory. With `triangular` (dense J only), also J's triangular
        factor R (J = Q R, (P, P)), updated chunk by chunk, else None. With `curvature`, the first is instead the
        Huber loss's own second derivative (the whitened rows' J^T J over the rows within huber_k: the loss is
        linear beyond), what a Newton step needs: J^T J of the square-root residuals counts a far row as if its
        loss curved, and steps along such rows then fall far short, converging by a few percent per step."""
        n = len(self.params)
        H, g, R = np.zeros((n, n)), np.zeros(n), np.zeros((0, n)) if triangular and n <= DENSE_LIMIT else None
        for state, lin in zip(self.states, self.evaluate(z)):
            residual = lin.residual.ravel()
            for rows, part in state.noise_model.chunks(CHUNK_ROWS):
                whitened = part.split(residual[rows], state.sigma)
                robust, slope = huber_sqrt(whitened, self.huber_k)
                M = self._rows_jacobian(state, lin, rows)
                if R is None and not is_sparse(M):  # summed without the whitened rows (most weigh 1)
                    weight = (np.abs(whitened) <= self.huber_k).astype(float) if curvature else slope**2
                    H_part, g_part = part.split_normal(M, state.sigma, weight, slope * robust)
                    H += H_part
                    g += g_part
                    continue
                J = part.split(M, state.sigma)
                if curvature:
                    g += J.T @ (slope * robust)  # the Huber loss's derivative, clip(w, -k, k)
                    inside = (np.abs(whitened) <= self.huber_k).astype(float)
                    J = scipy_sparse().diags(inside) @ J if is_sparse(J) else J * inside[:, None]
                    H += (J.T @ J).toarray() if is_sparse(J) else J.T @ J
                    continue
                if is_sparse(J):
                    J = scipy_sparse().diags(slope) @ J
                    H += (J.T @ J).toarray()
                else:
                    J *= slope[:, None]
                    H += J.T @ J
                    if R is not None:
                        R = triangular_factor(np.vstack([R, J]))
                g += J.T @ robust
        return H, g, R

    def normal_equations(self, z: np.ndarray, curvature: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """J^T J and J^T r of every residual (`residuals`: the data's, `information` (with `curvature`: the Huber
        loss's own second derivative), then the priors z)."""
        H, g, _ = self.information(z, curvature=curvature)
        H[np.diag_indices_from(H)] += 1.0
        return H, g + np.asarray(z, dtype=float)

    def _rows_jacobian(self, state: BlockState, lin: Linearization, rows: np.ndarray):
        """d(raw residual rows)/dz (len(rows), P) of a block's rows (indices into its raw rows), dense or, above
        DENSE_LIMIT unknowns, sparse."""
        n, sig = len(self.params), self.params.prior_sigmas
        J_chain = lin.jac_chain.reshape(lin.residual.size, self.n_chain)[rows] * sig[: self.n_chain]
        if n == self.n_chain:  # no block brings unknowns: the chain's columns are all
            return J_chain if n <= DENSE_LIMIT else scipy_sparse().csr_matrix(J_chain)
        dense = np.zeros((len(rows), n)) if n <= DENSE_LIMIT else None
        if dense is not None:
            dense[:, : self.n_chain] = J_chain
        local = None
        if lin.jac_local is not None and lin.local_cols is not None:
            L = lin.jac_local.shape[-1]
            cols = state.start + lin.local_cols[rows // state.block.dim]  # (len(rows), L)
            vals = lin.jac_local.reshape(-1, L)[rows] * sig[cols]
            if dense is not None:
                np.add.at(dense, (np.arange(len(rows))[:, None], cols), vals)
            else:
                local = scipy_sparse().csr_matrix((vals.ravel(), (np.repeat(np.arange(len(rows)), L), cols.ravel())),
                                                shape=(len(rows), n))  # fmt: skip
        if dense is not None:
            return dense
        empty = scipy_sparse().csr_matrix((len(rows), n - self.n_chain))
        J = scipy_sparse().hstack([scipy_sparse().csr_matrix(J_chain), empty]).tocsr()
        return J if local is None else (J + local).tocsr()


def _one_group(reading: np.ndarray) -> np.ndarray:
    """(U,) units linked by any shared joint reading (U, J) into one group (connected components)."""
    if not np.any(reading != reading[:, :1]):
        return reading[:, 0].copy() if reading.size else np.zeros(len(reading), dtype=int)  # not a view of (U, J)
    n_units, n_joints = reading.shape
    low = int(reading.min())
    key = np.arange(n_joints) * (int(reading.max()) - low + 1) + (reading - low)  # (U, J) one number per (joint, group)
    _, node = np.unique(key.ravel(), return_inverse=True)
    node = node.ravel() + n_units
    unit = np.repeat(np.arange(n_units), n_joints)
    n = int(node.max()) + 1
    return connected_components(n, unit, node)[:n_units]
