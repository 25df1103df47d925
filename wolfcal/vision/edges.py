"""Sub-pixel tag corners from the two black-square edges next to each corner, vectorised over the edges of
all the tags given (of one image or several).

For each corner, sub-pixel points of the two edges next to it (area method on intensity profiles across the
edge, unbiased for pixel-integrated and symmetrically blurred steps), a parabola per edge fitted near the
corner (lens distortion bends whole edges, so only a local fit is exact), and the tangents intersected. All
8 edges of a tag are sampled with one `cv2.remap` and fitted with batched normal equations (no per-edge
Python loop; with every profile on its own and two iterations it gives the corners of the per-edge loop it
replaced to ~1e-6 px, tests/vision/test_edge_refinement.py compares the two). A call's cost is mostly numpy's
per operation, whatever the number of tags, so `refine_tags` takes the tags of several images at once. The edges
of large cells have 100-200 profiles: they are averaged in bins (PROFILES), and a tag that has settled after one
iteration is not iterated again (SETTLED). Only the profiles used are sampled and measured (P rows, edge by
edge), window sums and bins are sums of their own (`np.add.reduceat`), the fits closed-form 3x3 solves.

Arrays: E edges (corner k, towards corner k+1 then k-1: edge 2k + j) of a grid of M points along an edge at
distances `d` [px] from the corner (padded to the longest edge), S samples across it at offsets `t` [px]
(positive out of the tag); P profiles (the grid's points used: inside the image, not padding), edge by edge.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.outliers import EDGE_POINT_PX
from wolfcal.vision.outline import mean_side

MIN_POINTS = 4  # edge points needed for a tangent
MIN_CONTRAST = 10.0  # grey levels between the 10th and 90th percentile of an edge's profiles
# Tags refined in one pass at most (detection gathers consecutive images' tags up to this many, `vision.batch`)
TAGS_PER_PASS = 16
# Kept profiles per edge from which they are averaged in bins of k = n // PROFILES (PROFILES to 2 PROFILES - 1 bins):
# a large cell's edge has 100-200 profiles 0.5 px apart. Binned, the corners move by ~0.01 px (median and 95th
# percentile error on rendered views within 0.001 px; 12 bins were worse at the 95th percentile). The fine
# step along the edge stays: profiles 1-2 px apart alias with the pixel grid (+0.003-0.03 px median error).
PROFILES = 24
# A tag whose corners all moved less than this share of its cell in an iteration has settled: no further iteration
SETTLED = 0.03


def edge_offsets(
    profiles: np.ndarray,
    t: np.ndarray,
    dark: np.ndarray,
    light: np.ndarray,
    window: float | np.ndarray,
    length: np.ndarray | None = None,
) -> np.ndarray:
    """Edge position along t [px] of each dark -> light profile (..., S) sampled at t; NaN if it has no edge.

    `t`: (S,) offsets shared by all profiles, or one row per profile, broadcast to (..., S) (e.g. (E, 1, S) for
    profiles (E, M, S): no copy per profile); `length` (...): how many samples of each row are the profile (the
    rest is padding; default all S). `dark`, `light`, `window`: (...) or scalar. Area method: within `window` px
    (less near the profile's ends, at least 0.75 px) of the mid-grey crossing nearest the profile centre, the edge
    lies where the dark area ends: edge = t_start + sum((light - I) / (light - dark)) * dt.
    """
    lead, S = profiles.shape[:-1], profiles.shape[-1]
    t = np.broadcast_to(t, (*lead, S))
    n = np.asarray(S if length is None else length)  # broadcast against lead only where needed: small arrays
    dark, light = np.asarray(dark), np.asarray(light)
    t0, step = t[..., 0], t[..., 1] - t[..., 0]  # t rises evenly along each row
    gaps = np.arange(S - 1)
    above = profiles >= (0.5 * (dark + light))[..., None]
    change = above[..., 1:] > above[..., :-1]  # dark -> light between k and k + 1
    change &= gaps < n[..., None] - 1
    # the crossing nearest the profile centre (length - 1) / 2, by twice its distance |2 k + 2 - length| in small
    # integers (exact; the first of equals)
    small = np.min_scalar_type(-2 * S - 2)  # holds -2 S .. 2 S (int8 for the refinement's S <= 49)
    twice = np.abs((2 * gaps + 2).astype(small) - n.astype(small)[..., None])
    k = np.argmin(np.where(change, twice, small.type(2 * S)), axis=-1)
    row = np.arange(0, change.size, S - 1).reshape(k.shape)  # each profile's first gap in change's flat order
    ok = change.reshape(-1)[row + k]
    cross = t0 + k * step + step / 2
    reach = np.minimum(window, np.minimum(cross - t0, t0 + (n - 1) * step - cross) - step)  # inside the profile
    ok &= reach >= 0.75
    # the window |t - cross| <= reach: samples lo..hi (1 <= lo, hi <= length - 2 where ok)
    lo = np.clip(np.ceil((cross - reach - t0) / step - 1e-9), 1, S - 1).astype(np.intp)
    hi = np.clip(np.floor((cross + reach - t0) / step + 1e-9), 1, S - 1).astype(np.intp)
    share = np.subtract(light[..., None], profiles, dtype=np.float32)  # the dark share of each sample
    share *= (1.0 / (light - dark))[..., None].astype(np.float32)
    np.clip(share, -0.5, 1.5, out=share)
    # the window's sum, one segment [lo, hi] of the flat shares per profile (ends past the array only where not ok)
    first = np.arange(0, share.size, S).reshape(lo.shape)
    bounds = np.stack([first + lo, np.minimum(first + hi + 1, share.size - 1)], axis=-1)
    inside = np.add.reduceat(share.reshape(-1), bounds.reshape(-1))[::2].reshape(lo.shape)
    edge = t0 + (lo - 0.5) * step + inside * step
    return np.where(ok, edge, np.nan)


def _dark_light(profiles: np.ndarray, keep: np.ndarray, n_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(E,) 10th and 90th percentile grey level of each edge's samples in `profiles` (P, S) (those where `keep`
    (E, M), edge by edge; the first n_t (E,) samples of each), as np.percentile (linear interpolation) gives them;
    NaN for an edge without samples. One sort for both."""
    E, S = len(keep), profiles.shape[1]
    edge = np.nonzero(keep)[0]
    count = np.count_nonzero(keep, axis=1) * n_t
    values = profiles[np.arange(S) < n_t[edge][:, None]]  # edge by edge
    ordered = np.full((E, max(int(count.max()), 1)), np.inf, np.float32)
    ordered[np.arange(ordered.shape[1]) < count[:, None]] = values
    ordered.sort(axis=1)
    last = np.maximum(count - 1, 0)
    seen = count > 0
    pos = np.array([[0.10], [0.90]]) * last  # (2, E)
    lo = np.floor(pos).astype(np.intp)
    rows = np.arange(0, ordered.size, ordered.shape[1])
    flat = ordered.reshape(-1)
    a, b = flat[rows + lo], flat[rows + np.minimum(lo + 1, last)]
    with np.errstate(invalid="ignore"):
        dark, light = np.where(seen, a + (b - a) * (pos - lo), np.nan)
    return dark, light


def _masked_median(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per row of (E, M) `values`, the median of values[mask] (NaN for empty rows)."""
    ordered = np.sort(np.where(mask, values, np.inf), axis=1)
    n = mask.sum(axis=1)
    rows = np.arange(len(values))
    lo = ordered[rows, np.maximum(n - 1, 0) // 2]
    hi = ordered[rows, np.minimum(n // 2, values.shape[1] - 1)]
    with np.errstate(invalid="ignore"):
        return np.where(n > 0, 0.5 * (lo + hi), np.nan)


def _fit(d: np.ndarray, off: np.ndarray, weight: np.ndarray, degree: np.ndarray) -> np.ndarray:
    """Least-squares polynomials off(d) of `degree` (E,) (1 or 2) over the points with `weight` 1 -> (E, 3)
    coefficients (constant, linear, quadratic; quadratic 0 for lines). d is scaled per edge for conditioning."""
    scale = np.maximum(np.abs(np.where(weight > 0, d, 0.0)).max(axis=1), 1e-9)[:, None]  # (E, 1)
    x = d / scale
    powers = np.empty((len(d), 5, d.shape[1]))  # w x^k, k = 0..4
    powers[:, 0] = weight
    for k in range(1, 5):
        np.multiply(powers[:, k - 1], x, out=powers[:, k])
    s = powers.sum(axis=2)  # (E, 5) sums of w x^k: the normal matrix [[s0, s1, s2], [s1, s2, s3], [s2, s3, s4]]
    rhs = np.matmul(powers[:, :3], np.where(weight > 0, off, 0.0)[..., None])[..., 0]  # (E, 3) sums of w x^k off
    line = degree != 2  # no quadratic column: its coefficient solves to 0
    a, b, d2 = s[:, 0], s[:, 1], s[:, 2]
    c, e, f = np.where(line, 0.0, s[:, 2]), np.where(line, 0.0, s[:, 3]), np.where(line, 1.0, s[:, 4])
    rhs[line, 2] = 0.0
    # the symmetric 3x3 solve in closed form (adjugate over determinant)
    adjugate = np.stack([d2 * f - e * e, c * e - b * f, b * e - c * d2,
                         c * e - b * f, a * f - c * c, b * c - a * e,
                         b * e - c * d2, b * c - a * e, a * d2 - b * b], axis=1).reshape(-1, 3, 3)  # fmt: skip
    det = a * adjugate[:, 0, 0] + b * adjugate[:, 0, 1] + c * adjugate[:, 0, 2]
    ok = np.abs(det) > 1e-12
    with np.errstate(invalid="ignore", divide="ignore"):
        coeffs = np.matmul(adjugate, rhs[..., None])[..., 0] / np.where(ok, det, np.nan)[:, None]
    return coeffs / np.concatenate([np.ones_like(scale), scale, scale * scale], axis=1)


def _tangents(d: np.ndarray, off: np.ndarray, good: np.ndarray) -> np.ndarray:
    """Offset and slope at d = 0 of each edge (E, 2) from its points (E, M) where `good`.

    A parabola when the points span more than 8 px (it absorbs the bend of the edge under lens distortion,
    which a line would extrapolate into a bias of ~curvature * span^2 / 12), a line otherwise. Points off the
    first fit by more than max(0.3 px, 4 median deviations) (dirt, glare, a wrong crossing) are dropped: the one
    outlier rule, `wolfcal.outliers.EDGE_POINT_PX`.
    """
    span = np.where(good, d, -np.inf).max(axis=1) - np.where(good, d, np.inf).min(axis=1)
    degree = np.where(span > 8.0, 2, 1)
    coeffs = _fit(d, off, good.astype(float), degree)
    fitted = coeffs[:, :1] + coeffs[:, 1:2] * d + coeffs[:, 2:3] * d * d
    residual = np.abs(np.where(good, off, 0.0) - fitted)
    limit = EDGE_POINT_PX.limit(_masked_median(residual, good))
    inlier = good & (residual <= limit[:, None])
    count = inlier.sum(axis=1)
    again = (count > degree + 2) & (count < good.sum(axis=1))
    if again.any():
        coeffs[again] = _fit(d[again], off[again], inlier[again].astype(float), degree[again])
    return coeffs[:, :2]


def _grid(first: np.ndarray, stop: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Per row, np.arange(first, stop, step) padded (continued) to the longest row -> (values (T, N), lengths
    (T,)). The values are computed as np.arange computes them (first + i * ((first + step) - first))."""
    count = np.ceil((stop - first) / step).astype(int)
    delta = (first + step) - first
    return first[:, None] + np.arange(count.max()) * delta[:, None], count


def refine_edges(img: np.ndarray, corners: np.ndarray, cells: int, iterations: int = 2) -> np.ndarray:
    """Refine (4, 2) corners [px] of one tag, or (T, 4, 2) of T tags, in a float32 image by fitting the two
    black-square edges next to each corner, near that corner (see `refine_tags`)."""
    refined = refine_tags([img], np.zeros(len(np.reshape(corners, (-1, 4, 2))), int), corners, cells, iterations)
    return refined[0] if np.ndim(corners) == 2 else refined


def refine_tags(
    images: Sequence[np.ndarray], image_of_tag: np.ndarray, corners: np.ndarray, cells: int, iterations: int = 2
) -> np.ndarray:
    """Refine (T, 4, 2) corners [px] of T tags, tag k seen in the float32 image images[image_of_tag[k]], by fitting
    the two black-square edges next to each corner, near that corner, in at most `iterations` iterations. All
    tags in one pass (one remap per image and iteration): the per-call cost is numpy's, not the pixels', so the
    tags of several images are refined together.

    Edge profiles start max(2 px, 0.3 cell) from the corner (clear of where blur rounds the corner off; at an
    acute corner further, so that their window stays inside the other edge), reach along the edge for 2.5 cells
    and across it for one cell *across that edge* (2-6 px, at most 2 px beyond the window) each way; the edge is
    measured within half that cell
    (1-2.5 px) of it, so it sees the black border and the white quiet zone only. On a strongly foreshortened tag
    (floor tags at 4 m) the cell across the long edges is a fraction of the mean cell: with the mean cell the
    window reached into the data bits and beyond the white margin, and at the sharp corners the profiles crossed
    the other edge, which put corners 0.3-1.6 px off along their edges' normals (1064 edges of rendered floor
    views, 16x16 supersampled, no noise: line offset at the corner 0.35 -> 0.06 px rms). A corner
    whose edges cannot be measured (image border, low contrast) keeps its previous estimate. Tags of other
    sizes get other grids: the grid's rows are padded to the longest, and only the profiles used are sampled.

    Cost: profiles reach at most 2 px beyond the window across the edge (room for the crossing); an edge with
    2 PROFILES or more profiles has them averaged in bins (`_binned`); a tag whose corners all moved less than
    SETTLED cell in an iteration is not iterated again (at 2048x1536 nearly all after the first, at 512x384 few).
    On rendered views the corner errors stay within 0.003 px of every profile on its own and two iterations.
    """
    corners = np.array(corners, dtype=float).reshape(-1, 4, 2)
    if len(corners) > TAGS_PER_PASS:
        return _refine_by_size(images, np.asarray(image_of_tag), corners, cells, iterations)
    image_of_tag = np.asarray(image_of_tag)
    active = np.arange(len(corners))  # tags not settled yet
    for _ in range(iterations):
        edges = _EdgeIndex.of(images, image_of_tag[active], len(active))
        before = corners[active]
        after, cell = _refined_once(images, edges, before, cells)
        corners[active] = after
        active = active[np.linalg.norm(after - before, axis=2).max(axis=1) > SETTLED * cell]
        if not len(active):
            break
    return corners


def _refined_once(
    images: Sequence[np.ndarray], edges: _EdgeIndex, corners: np.ndarray, cells: int
) -> tuple[np.ndarray, np.ndarray]:
    """One iteration of `refine_tags`: corners (T, 4, 2) [px] -> (the intersections of the edges' tangents (T, 4, 2)
    [px], each tag's mean cell (T,) [px] before)."""
    grid = _ProfileGrid.of(corners, edges, cells)
    profiles, keep, d = _binned(*_sample_profiles(images, edges, grid), grid)
    tangent = _edge_tangents(profiles, keep, d, grid)
    point = grid.c + tangent[:, :1] * grid.n  # (E, 2) on the edge at the corner
    direction = grid.e + tangent[:, 1:] * grid.n
    T = len(corners)
    reach = 0.5 * grid.cell[::8] + 1.0  # (T,) how far a corner may move in one iteration [px]
    return _intersect_pairs(corners, point.reshape(T, 8, 2), direction.reshape(T, 8, 2), reach), grid.cell[::8]


def _refine_by_size(
    images: Sequence[np.ndarray], image_of_tag: np.ndarray, corners: np.ndarray, cells: int, iterations: int
) -> np.ndarray:
    """`refine_tags` of more than TAGS_PER_PASS tags (corners (T, 4, 2) [px]), in passes of tags of similar size,
    so that little of the arrays is padding."""
    size = mean_side(corners)
    refined = np.empty_like(corners)
    for part in np.array_split(np.argsort(size), -(-len(corners) // TAGS_PER_PASS)):
        part = part[np.argsort(image_of_tag[part], kind="stable")]  # each image's tags in a row
        refined[part] = refine_tags(images, image_of_tag[part], corners[part], cells, iterations)
    return refined


@dataclass
class _EdgeIndex:
    """The E = 8 T edges of T tags (edge 2k + j starts at corner k and runs towards corner k + 1 (j = 0) or k - 1
    (j = 1)) and the images they are seen in; the same for every iteration of a pass."""

    start: np.ndarray  # (8,) the corner each edge of a tag starts at
    end: np.ndarray  # (8,) the corner it runs towards
    tag: np.ndarray  # (E,) the tag of each edge
    far: np.ndarray  # (E, 2) the last pixel (x, y) [px] of each edge's image
    edges_of_image: list[tuple[int, slice | np.ndarray]]  # (image index, its edges: a slice where they are in a row)

    @staticmethod
    def of(images: Sequence[np.ndarray], image_of_tag: np.ndarray, n_tags: int) -> _EdgeIndex:
        """The edges of `n_tags` tags, tag k seen in images[image_of_tag[k]]."""
        start = np.repeat(np.arange(4), 2)
        end = (start + np.tile([1, -1], 4)) % 4
        tag = np.repeat(np.arange(n_tags), 8)
        image_of_edge = image_of_tag[tag]
        far = np.array([(im.shape[1] - 1, im.shape[0] - 1) for im in images], dtype=float)[image_of_edge]
        edges_of_image: list[tuple[int, slice | np.ndarray]] = []
        if n_tags and (image_of_tag[1:] >= image_of_tag[:-1]).all():  # each image's tags in a row: no copy for remap
            bounds = [0, *(np.flatnonzero(image_of_tag[1:] != image_of_tag[:-1]) + 1), n_tags]
            for first, stop in zip(bounds[:-1], bounds[1:]):
                edges_of_image.append((int(image_of_tag[first]), slice(8 * first, 8 * stop)))
        else:
            for i in np.unique(image_of_edge):
                rows = np.flatnonzero(image_of_edge == i)
                in_a_row = rows[-1] - rows[0] + 1 == len(rows)
                edges_of_image.append((int(i), slice(rows[0], rows[-1] + 1) if in_a_row else rows))
        return _EdgeIndex(start, end, tag, far, edges_of_image)


@dataclass
class _ProfileGrid:
    """Where one iteration samples each edge (E edges, image frame, [px]): from its start corner c along the unit
    direction e, profiles at distances d (E, M) across the outward unit normal n at offsets t (E, S); rows are
    padded to the longest (n_d, n_t: the lengths of the rows)."""

    cell: np.ndarray  # (E,) the tag's mean cell [px]
    c: np.ndarray  # (E, 2) start corner [px]
    e: np.ndarray  # (E, 2) unit direction towards the other corner
    length: np.ndarray  # (E,) the edge's length [px]
    n: np.ndarray  # (E, 2) outward unit normal (out of the tag)
    window: np.ndarray  # (E,) half-width [px] of the window the edge is measured in
    t: np.ndarray  # (E, S) offsets across the edge [px]
    n_t: np.ndarray  # (E,) offsets used of each row
    d: np.ndarray  # (E, M) distances along the edge from the corner [px]
    n_d: np.ndarray  # (E,) distances used of each row

    @staticmethod
    def of(corners: np.ndarray, edges: _EdgeIndex, cells: int) -> _ProfileGrid:
        """The grid of the `edges` of tags with `corners` (T, 4, 2) [px] of `cells` cells across."""
        start, end, tag = edges.start, edges.end, edges.tag
        cell = (mean_side(corners) / cells)[tag]  # (E,)
        c = corners[:, start].reshape(-1, 2)
        e = corners[:, end].reshape(-1, 2) - c
        length = np.linalg.norm(e, axis=1)
        e /= length[:, None]
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        n *= np.where(np.einsum("ei,ei->e", n, c - corners.mean(axis=1)[tag]) >= 0, 1.0, -1.0)[:, None]  # outwards
        across = _border_across(corners, c, n, tag, cells)
        window = np.clip(0.5 * across, 1.0, 2.5)  # keep clear of the data bits and what lies beyond the margin
        half = np.minimum(np.clip(across, 2.0, 6.0), window + 2.0)  # 2 px beyond the window: room for the crossing
        t, n_t = _grid(-half, half + 1e-9, 0.25)
        first = np.maximum(np.maximum(2.0, 0.3 * cell), _clear_of_other_edge(e, window))
        d, n_d = _grid(first, np.maximum(np.maximum(2.5 * cell, 4.0), first + 4.0) + 1e-9, 0.5)
        return _ProfileGrid(cell, c, e, length, n, window, t, n_t, d, n_d)


def _sample_profiles(
    images: Sequence[np.ndarray], edges: _EdgeIndex, grid: _ProfileGrid
) -> tuple[np.ndarray, np.ndarray]:
    """Which profiles (E, M) of `grid` to use (inside the image, within 0.45 of the edge's length from the corner,
    not padding) and their intensities (P, S) (P: those used, edge by edge; one `cv2.remap` per image, bilinear).
    -> (profiles (P, S), keep (E, M))."""
    E, M, S = len(edges.tag), grid.d.shape[1], grid.t.shape[1]
    base = grid.c[:, None] + grid.d[:, :, None] * grid.e[:, None]  # (E, M, 2) on the edge
    t_ends = np.stack([grid.t[:, 0], grid.t[np.arange(E), grid.n_t - 1]], axis=1)  # (E, 2)
    ends = t_ends[:, :, None] * grid.n[:, None]  # (E, 2, 2) profile ends (first, last) from the edge point
    low, high = ends.min(axis=1), ends.max(axis=1)  # (E, 2) per coordinate: the ends' (x, y) are base + these
    inside = (base[..., 0] + low[:, None, 0] >= 0) & (base[..., 1] + low[:, None, 1] >= 0)  # the box is convex
    inside &= base[..., 0] + high[:, None, 0] <= edges.far[:, None, 0]
    inside &= base[..., 1] + high[:, None, 1] <= edges.far[:, None, 1]
    keep = inside & (grid.d < 0.45 * grid.length[:, None]) & (np.arange(M) < grid.n_d[:, None])  # (E, M)
    edge = np.nonzero(keep)[0]  # (P,) the edge of each profile used
    per_edge = np.count_nonzero(keep, axis=1)
    # sample points base + t n (P, S), x and y apart, computed in float64 and stored as float32 for cv2.remap
    maps = [np.add(base[keep][:, a : a + 1], np.repeat(grid.t * grid.n[:, a : a + 1], per_edge, axis=0),
                   out=np.empty((len(edge), S), np.float32), dtype=np.float64, casting="same_kind")
            for a in (0, 1)]  # fmt: skip
    profiles = np.empty((len(edge), S), np.float32)
    for i, rows in edges.edges_of_image:
        if isinstance(rows, slice):  # the image's profiles in a row
            used: slice | np.ndarray = slice(*np.searchsorted(edge, [rows.start, rows.stop]))
        else:
            used = np.isin(edge, rows)
        profiles[used] = cv2.remap(images[i], maps[0][used], maps[1][used], cv2.INTER_LINEAR)
    return profiles, keep


def _binned(profiles: np.ndarray, keep: np.ndarray, grid: _ProfileGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The profiles (P, S) used of the grid's (E, M) (where `keep`) of an edge with k PROFILES or more of them
    averaged in bins of k consecutive profiles of the grid -> (profiles (P', S) of the bins, keep (E, B): bins with a
    profile used, d (E, B): the mean distance [px] of each bin's profiles). The edge position is linear in the
    profile within its window, so a bin's profile gives about the mean of its profiles' offsets, and the bins keep
    their averaging over the pixel grid."""
    E, M = keep.shape
    k = np.maximum(1, keep.sum(axis=1) // PROFILES)  # (E,)
    if (k == 1).all():
        return profiles, keep, grid.d
    bins = int((-(-grid.n_d // k)).max())
    edge, m = np.nonzero(keep)
    of_bin = edge * bins + m // k[edge]  # (P,) the flat (E, B) bin of each profile: non-decreasing
    starts = np.flatnonzero(np.r_[True, of_bin[1:] != of_bin[:-1]])
    count = np.diff(np.r_[starts, len(of_bin)])
    binned = np.add.reduceat(profiles, starts, axis=0) / count[:, None].astype(np.float32)
    full = np.zeros(E * bins, bool)
    full[of_bin[starts]] = True
    d = np.zeros(E * bins)
    d[full] = np.add.reduceat(grid.d[keep], starts) / count
    return binned, full.reshape(E, bins), d.reshape(E, bins)


def _edge_tangents(profiles: np.ndarray, keep: np.ndarray, d: np.ndarray, grid: _ProfileGrid) -> np.ndarray:
    """(E, 2) offset [px] along the outward normal and slope [px/px] at the corner of each edge from its `profiles`
    (P, S) (those where `keep` (E, M), edge by edge); NaN for an edge with fewer than MIN_POINTS measured points or
    less contrast than MIN_CONTRAST."""
    E = len(keep)
    edge = np.nonzero(keep)[0]  # (P,)
    dark, light = _dark_light(profiles, keep, grid.n_t)
    usable = (keep.sum(axis=1) >= MIN_POINTS) & (light - dark >= MIN_CONTRAST)
    dark, light = np.where(usable, dark, 0.0), np.where(usable, light, 255.0)
    off = np.full(keep.shape, np.nan)
    t = np.repeat(grid.t, np.count_nonzero(keep, axis=1), axis=0)  # (P, S) the offsets of each profile's samples
    off[keep] = edge_offsets(profiles, t, dark[edge], light[edge], grid.window[edge], grid.n_t[edge])
    good = keep & np.isfinite(off) & usable[:, None]
    usable &= good.sum(axis=1) >= MIN_POINTS
    tangent = np.full((E, 2), np.nan)
    if usable.any():
        tangent[usable] = _tangents(d[usable], off[usable], good[usable])
    return tangent


def _border_across(corners: np.ndarray, c: np.ndarray, n: np.ndarray, tag: np.ndarray, cells: int) -> np.ndarray:
    """(E,) width [px] of one cell across each edge (start corner c (E, 2), outward normal n (E, 2)) of the tags
    `corners` (T, 4, 2): the tag's extent along -n over `cells`. On a foreshortened tag it is far smaller across the
    long edges than the mean cell: the 1-cell black border and white margin there are only that wide."""
    depth = np.einsum("eki,ei->ek", c[:, None] - corners[tag], n)  # (E, 4) how far inside each corner lies
    return depth.max(axis=1) / cells


def _clear_of_other_edge(e: np.ndarray, window: np.ndarray) -> np.ndarray:
    """(E,) distance [px] from the corner along each edge (unit directions e (E, 2), edges 2k and 2k + 1 meeting
    in corner k) beyond which the inner part of its profiles' window (window + 1 px of blur deep) stays 1 px inside
    the other edge: at an acute corner (a strongly foreshortened tag) profiles nearer the corner cross the other edge
    into the white margin and read the edge too far inward."""
    other = e.reshape(-1, 4, 2, 2)[:, :, ::-1].reshape(-1, 2)
    cos = np.einsum("ei,ei->e", e, other)
    sin = np.sqrt(np.maximum(1.0 - cos * cos, 1e-6))
    return (1.0 + (window + 1.0) * np.maximum(cos, 0.0)) / sin


def _intersect_pairs(corners: np.ndarray, point: np.ndarray, direction: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """New corners (T, 4, 2): intersection of edges 2k and 2k + 1 (points and directions (T, 8, 2)) where both
    are measured, not nearly parallel and within `reach` (T,) px of the old corner; the old corner otherwise."""
    p1, d1, p2, d2 = point[:, 0::2], direction[:, 0::2], point[:, 1::2], direction[:, 1::2]
    det = -d1[..., 0] * d2[..., 1] + d2[..., 0] * d1[..., 1]  # det [d1, -d2]
    rhs = p2 - p1
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (-rhs[..., 0] * d2[..., 1] + d2[..., 0] * rhs[..., 1]) / det  # Cramer's rule for the first unknown
        new = p1 + s[..., None] * d1
        ok = np.isfinite(new).all(axis=2) & (np.abs(det) >= 1e-6)
        ok &= np.linalg.norm(np.where(ok[..., None], new, corners) - corners, axis=2) < reach[:, None]
    return np.where(ok[..., None], new, corners)
