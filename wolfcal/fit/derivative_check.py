"""The derivative check every measurement block's test calls: a block's analytic Jacobians (`Block.linearize`)
against central differences of its residuals.

Checked: d(residual)/d(chain parameter values) (`jac_chain`), d(residual)/d(the block's own unknowns) (`jac_local`
scattered to the block's nuisance columns by `local_cols`) and d(residual)/d(joint readings) (`joint_sensitivity`,
one common change of every sample's reading of a joint at a time: each unit depends only on its own sample's
readings). Each Jacobian must match to `rtol` of its largest entry (plus `atol` [unit / SI]).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wolfcal.fit.blocks import Block, Linearization
from wolfcal.robot.parameters import ParameterSet

STEP = 1e-6  # central-difference step [SI: rad, m, rad of a joint reading]


def central_differences(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, step: float = STEP) -> np.ndarray:
    """(..., N) central differences of f at x (N,)."""
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = step
        cols.append((f(x + e) - f(x - e)) / (2.0 * step))
    return np.stack(cols, axis=-1) if cols else np.zeros((*f(x).shape, 0))


def dense_local(block: Block, lin: Linearization) -> np.ndarray:
    """(U, dim, L_block) d(residual)/d(the block's own unknowns), `jac_local` scattered by `local_cols`."""
    out = np.zeros((block.n_units, block.dim, len(block.nuisance)))
    if lin.jac_local is None or lin.local_cols is None:
        return out
    for u in range(block.n_units):
        for k, col in enumerate(lin.local_cols[u]):
            out[u, :, col] += lin.jac_local[u, :, k]
    return out


def _check(name: str, analytic: np.ndarray, numeric: np.ndarray, rtol: float, atol: float) -> None:
    scale = float(np.abs(numeric).max(initial=0.0))
    error = float(np.abs(analytic - numeric).max(initial=0.0))
    assert error <= rtol * scale + atol, (
        f"{name}: analytic and central-difference derivatives differ by {error:.3g} (largest entry {scale:.3g}, "
        f"allowed {rtol * scale + atol:.3g})"
    )


def assert_block_derivatives(
    block: Block,
    chain: ParameterSet,
    chain_values: np.ndarray,
    local_values: np.ndarray | None = None,
    rtol: float = 1e-5,
    atol: float = 1e-9,
    step: float = STEP,
) -> Linearization:
    """AssertionError naming the Jacobian (chain, local or joint readings) where the block's analytic derivatives
    at (chain_values (Pc,), local_values (L,), default the nuisance references) differ from central differences;
    returns the linearisation checked. The residuals must be finite there."""
    local = block.nuisance.references.copy() if local_values is None else np.asarray(local_values, dtype=float)
    values = np.asarray(chain_values, dtype=float)
    lin = block.linearize(values, local, chain)
    assert lin.residual.shape == (block.n_units, block.dim), (
        f"{block.name}: residual shape {lin.residual.shape}, expected (units, dim) = ({block.n_units}, {block.dim})"
    )
    assert np.all(np.isfinite(lin.residual)), f"{block.name}: residuals not finite at the point checked"
    _check(
        f"{block.name} chain",
        lin.jac_chain,
        central_differences(lambda v: block.linearize(v, local, chain).residual, values, step),
        rtol,
        atol,
    )
    if len(block.nuisance):
        _check(
            f"{block.name} local",
            dense_local(block, lin),
            central_differences(lambda x: block.linearize(values, x, chain).residual, local, step),
            rtol,
            atol,
        )
    q0 = block.q_measured.copy()

    def at_readings(dq: np.ndarray) -> np.ndarray:
        block.q_measured = q0 + dq
        try:
            return block.linearize(values, local, chain).residual
        finally:
            block.q_measured = q0

    numeric = central_differences(lambda dq: at_readings(np.broadcast_to(dq, q0.shape)), np.zeros(q0.shape[1]), step)
    _check(f"{block.name} joint readings", lin.joint_sensitivity, numeric, rtol, atol)
    return lin
