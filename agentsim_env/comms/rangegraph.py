"""The range graph of a step: overlay links (an adjacency by slot) and every slot's nearest neighbour.

Both come from the slots indexed in the step's neighbour grid (the online ones), 3D distance, same world:

- **links**: the overlay's edges, ``dist <= min(range_i, range_j)`` between two online slots, stored as rows
  ``indices[start[s]:end[s]]`` per slot. The ranges are the overlay's current ones, which may exceed the
  configured range the graph was built for: the grid scan reaches ``max(max_dist, largest range)``. The pairs
  of ``set_pairs`` only reach ``max_dist``, so links from them refuse larger ranges;
- **nearest**: the closest other slot within ``nearest_range`` and ``max_dist`` (ties: the lower slot), or -1.

Two sources give identical results. ``set_pairs`` takes the pairs ``(i, j, d)`` of
``core.spatial.neighbor_pairs`` (``i < j``, each once) and builds the rows by a counting sort (lazily: only what
is asked for). ``set_grid`` takes the grid itself and scans each slot's window once, with the window's
coordinates gathered in grid order so candidates are read sequentially; it needs no pair list and computes
links and nearest in the same pass. Its rows list a slot's neighbours in the order the pairs path produces
(the pairs' order, in which a slot's row holds first the lower slots found before it in grid order, then its
own higher neighbours, then the lower slots found after it). That order matters: the overlay reads neighbours
in row order, which orders a step's deliveries and so decides which messages an inbox of M rows keeps.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from agentsim_env.core.spatial import Grid, cell_of
from agentsim_env.core.threads import RowThreads


@nb.njit(cache=True)
def _nearest_from_pairs(i, j, d, n_slots, max_d):  # type: ignore[no-untyped-def]
    # Nearest neighbour of every slot over the pairs (ties: the lower slot); -1 when none within max_d.
    best = np.full(n_slots, np.inf)
    out = np.full(n_slots, -1, dtype=np.int64)
    for k in range(i.shape[0]):
        if d[k] > max_d:
            continue
        a, b = i[k], j[k]
        if d[k] < best[a] or (d[k] == best[a] and b < out[a]):
            best[a], out[a] = d[k], b
        if d[k] < best[b] or (d[k] == best[b] and a < out[b]):
            best[b], out[b] = d[k], a
    return out


@nb.njit(cache=True)
def _links_from_pairs(pi, pj, pos, online, world, rng, n):  # type: ignore[no-untyped-def]
    # Counting sort of the kept pairs by endpoint, both directions: O(S + E).
    e = pi.shape[0]
    keep = np.zeros(e, dtype=np.bool_)
    indptr = np.zeros(n + 1, dtype=np.int64)
    for q in range(e):
        i = pi[q]
        j = pj[q]
        if i == j or not online[i] or not online[j] or world[i] != world[j]:
            continue
        r = min(rng[i], rng[j])
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        if dx * dx + dy * dy + dz * dz <= r * r:
            keep[q] = True
            indptr[i + 1] += 1
            indptr[j + 1] += 1
    for s in range(n):
        indptr[s + 1] += indptr[s]
    fill = indptr[:-1].copy()
    indices = np.empty(indptr[n], dtype=np.int64)
    for q in range(e):
        if keep[q]:
            i = pi[q]
            j = pj[q]
            indices[fill[i]] = j
            fill[i] += 1
            indices[fill[j]] = i
            fill[j] += 1
    return indptr, indices


@nb.njit(cache=True)
def _grown(a, need, keep):  # type: ignore[no-untyped-def]
    b = np.empty(max(need, 2 * a.shape[0], 64), dtype=a.dtype)
    b[:keep] = a[:keep]
    return b


@nb.njit(cache=True, nogil=True)
def _graph_prep(pos, online, items, rng, links, start, end, near, sp, ok_link):  # type: ignore[no-untyped-def]
    # Coordinates, range and link eligibility in grid order (a window's candidates are then read sequentially);
    # every row empty and every nearest -1 until the row kernel fills the indexed slots'.
    for q in range(items.shape[0]):
        s = items[q]
        sp[q, 0], sp[q, 1], sp[q, 2], sp[q, 3] = pos[s, 0], pos[s, 1], pos[s, 2], rng[s]
        ok_link[q] = links and online[s]
    start[:] = 0
    end[:] = 0
    near[:] = -1


@nb.njit(cache=True, nogil=True)
def _graph_shift(items, lo, hi, start, end, base, src, n, dst):  # type: ignore[no-untyped-def]
    # Rows of the grid positions [lo, hi) were written at 0.. of ``src`` (n entries): move them to ``base``..
    # of ``dst`` (each range's own part of the one output, so ranges copy on their own threads).
    for i in range(n):
        dst[base + i] = src[i]
    for q in range(lo, hi):
        u = items[q]
        start[u] += base
        end[u] += base


_W = 6  # entries copied unconditionally per window column and per row list (see _graph_rows)


@nb.njit(cache=True, inline="always")
def _append(dst, n, src, s0, cnt):  # type: ignore[no-untyped-def]
    # dst[n:n + cnt] = src[s0:s0 + cnt], the first _W entries copied whatever cnt (branch free for short lists;
    # the caller keeps room for them); the new length
    for t in range(_W):
        dst[n + t] = src[s0 + t]
    for t in range(_W, cnt):
        dst[n + t] = src[s0 + t]
    return n + cnt


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _graph_rows(
    lo,
    hi,
    world,
    cell_start,
    items,
    ox,
    oy,
    cell,
    nx,
    ny,
    reach,
    pair_d,
    near_r,  # type: ignore[no-untyped-def]  # noqa: E501
    start,
    end,
    near,
    indices,
    cand,
    d2c,
    sp,
    ok_link,
):
    # One window scan per indexed slot u at grid positions [lo, hi) (every pair is seen from both ends), in two
    # phases. Phase 1 lists the window's grid positions column by column, then keeps those within reach. Both
    # are branch free where the data decide: a column holds 0 to a few candidates (at 10,000 agents ~2), so a
    # loop over each column's candidates mispredicts its exit once a column; instead each column writes its
    # first _W positions unconditionally and advances by how many are real (a longer column finishes in a loop
    # that is rarely entered). Phase 2 walks the candidates in range: the nearest (one running minimum and the
    # second smallest: the careful tie rule below runs only when they lie within 1e-9 of each other), then the
    # links in the order of the pairs path: lower slots found before u in grid order (A), every higher slot
    # (B), then lower slots found after u (C), each in grid order; B and C are copied behind A the same way as
    # the columns. The window's cells come in grid order whatever its size, so a longer reach adds candidates
    # but never reorders a row. A nearest neighbour must also lie within pair_d (<= reach), as with the pairs
    # path: it does not depend on how far the links reach. The rows go to ``indices`` from 0 in grid order
    # (start / end relative to it); a row depends only on its own window, so ranges may run on different
    # threads, each with its own buffers.
    m = items.shape[0]
    r2 = reach * reach
    pair_d2 = pair_d * pair_d
    # sqrt is monotone and correctly rounded: d2 above (1 + 1e-9) times a bound cannot round to within it
    near_hi = near_r * near_r * (1.0 + 1e-9)
    # the window's corners are clamped to just outside the map before cell_of clamps them to the border
    # cells (the same cells): a reach far beyond the map must not overflow the integer cell index
    lo_x, lo_y = ox - cell, oy - cell
    hi_x, hi_y = ox + (nx + 1) * cell, oy + (ny + 1) * cell
    # cand: the kept candidates [0, k), the B and C lists [k + _W, 3 (k + _W)), the window's positions after
    # 3 (m + _W); any window holds <= m candidates
    need = 4 * (m + _W) + 8
    if cand.shape[0] < need:
        cand = _grown(cand, need, 0)
    if d2c.shape[0] < m + 1:  # squared distance of each kept candidate
        d2c = np.empty(m + 1)
    qs = cand[3 * (m + _W) + 4 :]
    n = 0
    for idx in range(lo, hi):
        u = items[idx]
        xu, yu, zu, ru = sp[idx, 0], sp[idx, 1], sp[idx, 2], sp[idx, 3]
        x0, y0 = cell_of(max(xu - reach, lo_x), max(yu - reach, lo_y), ox, oy, cell, nx, ny)
        x1, y1 = cell_of(min(xu + reach, hi_x), min(yu + reach, hi_y), ox, oy, cell, nx, ny)
        base0 = world[u] * nx
        nq = 0
        for a in range(x0, x1 + 1):
            base = (base0 + a) * ny
            s0 = cell_start[base + y0]
            e0 = cell_start[base + y1 + 1]
            for t in range(_W):
                qs[nq + t] = s0 + t
            nq += min(e0 - s0, _W)
            for q in range(s0 + _W, e0):
                qs[nq] = q
                nq += 1
        k = 0
        for c in range(nq):
            q = qs[c]
            dx = sp[q, 0] - xu
            dy = sp[q, 1] - yu
            dz = sp[q, 2] - zu
            d2 = dx * dx + dy * dy + dz * dz
            cand[k] = q
            d2c[k] = d2
            k += d2 <= r2
        # phase 2 over the k candidates in range (u itself among them, at q == idx); A goes straight to the
        # row, B and C to their lists
        if n + k + _W > indices.shape[0]:
            indices = _grown(indices, n + k + _W, n)
        lu = ok_link[idx]
        m2 = np.inf  # smallest squared distance to another slot, its slot, and the second smallest
        bv = -1
        s2 = np.inf
        row0 = n
        kb = k + _W
        kc = 2 * (k + _W)
        nb_ = kb
        nc = kc
        for c in range(k):
            q = cand[c]
            v = items[q]
            d2 = d2c[c]
            other = q != idx
            dd = d2 if other else np.inf
            s2 = min(s2, max(m2, dd))
            bv = v if dd < m2 else bv
            m2 = min(m2, dd)
            r = min(ru, sp[q, 3])
            link = other & lu & ok_link[q] & (d2 <= r * r)
            higher = v > u
            indices[n] = v
            cand[nb_] = v
            cand[nc] = v
            n += link & ~higher & (q < idx)
            nb_ += link & higher
            nc += link & ~higher & (q > idx)
        # nearest: the pairs path's rule (smallest sqrt distance, then lowest slot); only candidates whose d2 is
        # within 1e-9 of the minimum can round to the same distance (sqrt is monotone and correctly rounded),
        # so with the second smallest beyond that the minimum's slot is the answer
        bslot = -1
        if m2 <= near_hi:
            lim = min(m2 * (1.0 + 1e-9), pair_d2)
            if s2 > m2 * (1.0 + 1e-9):
                if m2 <= pair_d2 and np.sqrt(m2) <= near_r:
                    bslot = bv
            else:
                best = np.inf
                for c in range(k):
                    if d2c[c] <= lim and cand[c] != idx:
                        v = items[cand[c]]
                        d = np.sqrt(d2c[c])
                        if d <= near_r and (d < best or (d == best and v < bslot)):
                            best = d
                            bslot = v
        n = _append(indices, n, cand, kb, nb_ - kb)
        n = _append(indices, n, cand, kc, nc - kc)
        start[u] = row0
        near[u] = bslot
        end[u] = n
    return indices, cand, d2c, n


class RangeGraph:
    """Links and nearest neighbours of the current positions (see the module docstring).

    Args:
        n_slots: Slots S.
        max_dist: Pair radius in metres: the radius of the pairs given to ``set_pairs``, the farthest a nearest
            neighbour may be, and the least distance the grid scan reaches (its links reach as far as the
            largest link range, see ``links``).
        nearest_range: Largest distance of a nearest neighbour in metres (<= ``max_dist`` to matter).
    """

    __slots__ = (
        "n_slots",
        "max_dist",
        "nearest_range",
        "_grid",
        "_pairs",
        "_pos",
        "_online",
        "_world",
        "_near",
        "_near_ok",
        "_links",
        "_links_ok",
        "_buf",
        "_parts",
        "threads",
    )

    def __init__(self, n_slots: int, max_dist: float, nearest_range: float) -> None:
        self.n_slots = int(n_slots)
        self.max_dist, self.nearest_range = float(max_dist), float(nearest_range)
        empty = np.zeros(0, dtype=np.int64)
        self._grid: Grid | None = None
        self._pairs: tuple[np.ndarray, ...] = (empty, empty, np.zeros(0))
        self._pos, self._online, self._world = np.zeros((0, 3)), np.zeros(0, dtype=bool), empty
        self._near = np.full(self.n_slots, -1, dtype=np.int64)
        self._links = (np.zeros(self.n_slots, dtype=np.int64), np.zeros(self.n_slots, dtype=np.int64), empty)
        # grid scan buffers, reused: row starts, row ends, nearest, links, and the grid-ordered copies of
        # (x, y, z, range) and of the link eligibility; per range of rows (a thread each): its rows, the two
        # row scratch lists and the candidates' squared distances
        s = self.n_slots
        self._buf = (
            np.zeros(s, dtype=np.int64),
            np.zeros(s, dtype=np.int64),
            np.full(s, -1, dtype=np.int64),
            empty,
            np.zeros((s, 4)),
            np.zeros(s, dtype=bool),
        )
        self._parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._near_ok = self._links_ok = False
        self.threads = RowThreads(1)
        """Threads for the grid scan's rows (``World.set_num_threads`` sets them); results do not change."""

    @property
    def pairs(self) -> tuple[np.ndarray, ...]:
        """The pairs given to the latest ``set_pairs`` (empty after ``set_grid``)."""
        return self._pairs

    def set_pairs(self, pairs: tuple[np.ndarray, ...], pos: np.ndarray, online: np.ndarray, world: np.ndarray) -> None:
        """Use the pairs ``(i, j, d)`` of ``neighbor_pairs(..., max_dist)``; links and nearest follow lazily."""
        empty = np.zeros(0, dtype=np.int64)
        self._grid = None
        self._pairs = tuple(pairs) if len(pairs) == 3 else (empty, empty, np.zeros(0))
        self._pos, self._online, self._world = pos, online, world
        self._near_ok = self._links_ok = False

    def set_grid(
        self,
        grid: Grid,
        pos: np.ndarray,
        online: np.ndarray,
        world: np.ndarray,
        link_range: np.ndarray,
        links: bool,
    ) -> None:
        """Scan the step's grid (built from ``pos`` over the online slots): nearest now, links if ``links``.

        The links follow ``link_range`` whatever ``max_dist`` is: the scan reaches the largest link range when
        that is farther (the grid's cells may be smaller than the reach; a query scans every cell it covers).
        """
        empty = np.zeros(0, dtype=np.int64)
        self._grid, self._pairs = grid, (empty, empty, np.zeros(0))
        self._pos, self._online, self._world = pos, online, world
        self._links_ok = False  # links of earlier positions must not answer a later links() call
        self._scan(link_range, links)

    def _scan(self, link_range: np.ndarray, links: bool) -> None:
        g = self._grid
        assert g is not None
        sp = g.spec
        top = float(link_range.max()) if link_range.shape[0] else 0.0  # a reduction, no allocation
        reach = max(self.max_dist, top) if links else self.max_dist
        pos = np.ascontiguousarray(self._pos, dtype=np.float64)
        online = np.ascontiguousarray(self._online, dtype=np.bool_)
        world = np.ascontiguousarray(self._world, dtype=np.int64)
        start, end, near, indices, sp4, ok_link = self._buf
        items = g.items
        _graph_prep(pos, online, items, link_range, links, start, end, near, sp4, ok_link)
        m = items.shape[0]
        ranges = self.threads.ranges(m)  # the ranges ``threads.run(rows, m)`` calls ``rows`` with
        parts = self._parts
        while len(parts) < len(ranges):
            parts.append((np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)))
        parts[0] = (indices, *parts[0][1:])  # the first range writes where the one output begins

        def rows(lo: int, hi: int, part: int) -> int:
            out, cand, d2c = parts[part]
            out, cand, d2c, n = _graph_rows(
                lo,
                hi,
                world,
                g.cell_start,
                items,
                sp.origin_x,
                sp.origin_y,
                sp.cell,
                sp.nx,
                sp.ny,
                reach,
                self.max_dist,
                self.nearest_range,
                start,
                end,
                near,
                out,
                cand,
                d2c,
                sp4,
                ok_link,
            )
            parts[part] = (out, cand, d2c)
            return int(n)

        if len(ranges) == 1:
            rows(0, m, 0)
            indices = parts[0][0]
        else:  # each range's rows into a buffer of its own, then the later ranges' moved behind the first's
            counts = self.threads.run(rows, m)
            base = np.cumsum([0, *counts])
            indices = parts[0][0]
            if indices.shape[0] < base[-1]:
                indices = _grown(indices, int(base[-1]), counts[0])
                parts[0] = (indices, *parts[0][1:])

            def move(lo: int, hi: int, _: int) -> None:
                for p in range(1 + lo, 1 + hi):
                    _graph_shift(
                        items,
                        ranges[p][0],
                        ranges[p][1],
                        start,
                        end,
                        int(base[p]),
                        parts[p][0],
                        counts[p],
                        indices,
                    )

            self.threads.run(move, len(ranges) - 1, 1)
        self._buf = (start, end, near, indices, sp4, ok_link)
        self._near, self._near_ok = near, True
        if links:
            self._links, self._links_ok = (start, end, indices), True

    def nearest(self) -> np.ndarray:
        """``(S,)`` int64: each slot's nearest neighbour within ``nearest_range``, or -1 (an internal buffer)."""
        if not self._near_ok:
            i, j, d = self._pairs
            self._near = _nearest_from_pairs(i, j, d, self.n_slots, self.nearest_range)
            self._near_ok = True
        return self._near

    def links(self, link_range: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(start, end, indices)``: slot ``s`` links to ``indices[start[s]:end[s]]`` (internal buffers).

        Args:
            link_range: ``(S,)`` per-slot transmission range (a link needs ``dist <= min`` of both ends'), such
                as the overlay's current ``link_range``. From the grid any range works; from the pairs of
                ``set_pairs``, which reach ``max_dist``, a larger range would lose links.

        Raises:
            ValueError: From pairs, if a range exceeds ``max_dist``.
        """
        if not self._links_ok:
            if self._grid is not None:
                self._scan(link_range, True)
            else:
                if self._pos.shape[0] != self.n_slots:
                    raise ValueError("links need the positions of the pairs: pass them with set_pairs")
                top = float(link_range.max()) if link_range.shape[0] else 0.0
                if top > self.max_dist:
                    raise ValueError(
                        f"comm_range must be <= {self.max_dist:g} m (max_dist, the radius of the pairs given to "
                        f"set_pairs), got {top:g} m: build the pairs with a larger max_dist or pass the grid"
                    )
                indptr, indices = _links_from_pairs(
                    np.ascontiguousarray(self._pairs[0], dtype=np.int64),
                    np.ascontiguousarray(self._pairs[1], dtype=np.int64),
                    np.ascontiguousarray(self._pos),
                    np.ascontiguousarray(self._online, dtype=np.bool_),
                    np.ascontiguousarray(self._world, dtype=np.int64),
                    link_range,
                    self.n_slots,
                )
                self._links, self._links_ok = (indptr[:-1], indptr[1:], indices), True
        return self._links
