"""Choose n of N candidate poses by the expected information: a greedy start, then exchanges (DETMAX-like).

Information in the fit's prior-normalised unknowns z: M(S) = I + M_0 + sum_{k in S} G_k^T G_k (G_k: (r, P) whitened
Jacobian rows of candidate k, M_0: what every plan of n poses gets, the repeated views, `wolfcal.plan.information`),
covariance C = M^-1. The criterion looks at the
covariance of the observable chain unknowns, C_obs = B^T C_cc B (B: (c, k) basis without the directions no pose can
inform, nuisance unknowns such as an external camera's pose marginalised): D = log det C_obs, A = trace
C_obs, E = largest eigenvalue of C_obs; smaller is better. I (I-optimal, "deliverable") is A on the basis of what
the calibration delivers (`plan.deliverable.deliverable_basis`: B B^T = D^T D / m), so trace C_obs is the average
predicted variance of the delivered poses. Adding candidate k is a rank-r update, evaluated for all
candidates at once: with S_k = I + G_k C G_k^T and V_k = G_k C_cB,
C_obs' = C_obs - V_k^T S_k^-1 V_k, log det C_obs' = log det C_obs + log det(S_k - V_k C_obs^-1 V_k^T) - log det S_k.
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError

CRITERIA = ("D", "A", "E", "I")
MAX_SWEEPS = 20
TOLERANCE = 1e-9  # relative improvement an exchange must bring


def check_criterion(criterion: str) -> str:
    """The --criterion in upper case; a clear error for one not in CRITERIA."""
    if criterion.upper() not in CRITERIA:
        raise WolfcalError(f"--criterion {criterion!r} must be one of {', '.join(CRITERIA)}")
    return criterion.upper()


def criterion_value(M: np.ndarray, basis: np.ndarray, criterion: str) -> float:
    """The criterion of information matrix M (P, P) (smaller is better)."""
    c = basis.shape[0]
    C_obs = basis.T @ np.linalg.inv(M)[:c, :c] @ basis
    if criterion == "D":
        return float(np.linalg.slogdet(C_obs)[1])
    if criterion in ("A", "I"):
        return float(np.trace(C_obs))
    return float(np.linalg.eigvalsh(C_obs)[-1])


def values_after_adding(M: np.ndarray, G: np.ndarray, basis: np.ndarray, criterion: str) -> np.ndarray:
    """(N,) criterion of M + G_k^T G_k for every candidate k (G: (N, r, P), zero rows padding at the end, as
    `wolfcal.plan.information.factors` packs them), by rank-r updates: candidates with as many rows up to their last
    nonzero one are evaluated together, with one matrix product over all their rows for each quadratic form."""
    c = basis.shape[0]
    C = np.linalg.inv(M)
    C = 0.5 * (C + C.T)
    Y = C[:, :c] @ basis  # (P, k): C_zB
    C_obs = basis.T @ C[:c, :c] @ basis
    base = criterion_value(M, basis, criterion)
    # D: S_k - V_k C_obs^-1 V_k^T = I + G_k (C - Y C_obs^-1 Y^T) G_k^T
    D = C - Y @ np.linalg.solve(C_obs, Y.T) if criterion == "D" else None
    nonzero = np.any(G != 0.0, axis=2)  # (N, r)
    rows_used = np.where(nonzero.any(axis=1), G.shape[1] - np.argmax(nonzero[:, ::-1], axis=1), 0)  # to the last
    out = np.full(len(G), base)
    for r in np.unique(rows_used[rows_used > 0]):
        which = np.flatnonzero(rows_used == r)
        Gr = G[which, :r]
        flat, Gt = Gr.reshape(-1, Gr.shape[2]), np.swapaxes(Gr, 1, 2)
        S = np.eye(r) + (flat @ C).reshape(Gr.shape) @ Gt  # (n, r, r)
        if D is not None:
            inner = np.eye(r) + (flat @ D).reshape(Gr.shape) @ Gt
            out[which] = base + np.linalg.slogdet(inner)[1] - np.linalg.slogdet(S)[1]
            continue
        V = (flat @ Y).reshape(len(which), r, -1)  # (n, r, k)
        SinvV = np.linalg.solve(S, V)
        if criterion in ("A", "I"):
            out[which] = base - np.einsum("nrk,nrk->n", V, SinvV)
        else:
            out[which] = np.linalg.eigvalsh(C_obs - np.swapaxes(V, 1, 2) @ SinvV)[:, -1]
    return out


def information(G: np.ndarray, chosen, M0: np.ndarray | None = None) -> np.ndarray:
    """M = I + M0 + sum of the chosen candidates' information (P, P)."""
    chosen = np.asarray(list(chosen), dtype=int)
    M = np.eye(G.shape[2]) + np.einsum("nri,nrj->ij", G[chosen], G[chosen])
    return M if M0 is None else M + M0


def select(
    G: np.ndarray, n: int, basis: np.ndarray, criterion: str = "D", M0: np.ndarray | None = None
) -> tuple[list[int], float]:
    """n distinct candidate indices and their criterion value: greedy additions (from I + M0), then sweeps that
    exchange each chosen pose for the best other candidate while that improves the criterion."""
    if n > len(G):
        raise WolfcalError(f"--poses {n}: only {len(G)} candidate poses were found; ask for fewer poses")
    chosen: list[int] = []
    M = information(G, [], M0)
    for _ in range(n):
        values = values_after_adding(M, G, basis, criterion)
        values[chosen] = np.inf
        best = int(np.argmin(values))
        chosen.append(best)
        M += G[best].T @ G[best]
    value = criterion_value(M, basis, criterion)
    for _ in range(MAX_SWEEPS):
        improved = False
        for position in range(n):
            out = chosen[position]
            M_without = M - G[out].T @ G[out]
            values = values_after_adding(M_without, G, basis, criterion)
            values[[k for k in chosen if k != out]] = np.inf
            best = int(np.argmin(values))
            if best != out and values[best] < value - TOLERANCE * max(abs(value), 1.0):
                chosen[position] = best
                M = M_without + G[best].T @ G[best]
                value = criterion_value(M, basis, criterion)
                improved = True
        if not improved:
            break
    return chosen, value


def cover_twice(
    G: np.ndarray,
    chosen: list[int],
    shows: np.ndarray,
    labels: list[str],
    basis: np.ndarray,
    criterion: str = "D",
    M0: np.ndarray | None = None,
) -> list[int]:
    """`chosen` with no column of shows (N, T) bool (a floor tag in view; `labels` name them) shown by exactly one
    chosen pose: the
    fit finds a floor tag's place from its views and refuses a tag seen once. When some is, the one exchange (a
    chosen pose out, a candidate in) that leaves none so and the best criterion is made; a clear error when none
    does."""
    counts = shows[chosen].sum(axis=0)
    if not np.any(counts == 1):
        return chosen
    M = information(G, chosen, M0)
    best: tuple[float, int, int] = (np.inf, -1, -1)
    for position, out in enumerate(chosen):
        values = values_after_adding(M - G[out].T @ G[out], G, basis, criterion)
        values[chosen] = np.inf
        after = (counts - shows[out])[None] + shows  # (N, T) views of each column with candidate k in
        values[np.any(after == 1, axis=1)] = np.inf
        k = int(np.argmin(values))
        if values[k] < best[0]:
            best = (float(values[k]), position, k)
    if best[1] < 0:
        lonely = ", ".join(labels[t] for t in np.flatnonzero(counts == 1))
        raise WolfcalError(f"no exchange of one planned pose leaves every tag in view at least twice ({lonely} seen "
                           "once, and the fit needs two views of a floor tag); ask for more --poses")  # fmt: skip
    chosen = list(chosen)
    chosen[best[1]] = best[2]
    return chosen
