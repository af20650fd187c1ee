"""Window reductions on a regular grid of samples and the gaps between them: which samples and gaps a time window
covers (``window_range``), and min/max over them for every query position at once (``reduce_window``, built on
``sliding_clipped``: a blocked sparse-table doubling for narrow windows, van Herk/Gil-Werman for wide ones).

input: per-sample and per-gap values (float arrays), window offsets in samples, ``np.minimum`` or ``np.maximum`` and
its identity -> output: one value per query position. min and max are exact, so every evaluation order gives the
same values (``verify.monitor.grid`` relies on this for bit-identical results with the general engine).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["WindowRange", "reduce_window", "sliding_clipped", "window_range"]

FloatArray = npt.NDArray[np.float64]


def _ceil_div(a: int, b: int) -> int:
    return -((-a) // b)


@dataclass(frozen=True, slots=True)
class WindowRange:
    """Offsets ``[a, b]`` (inclusive, relative to the query index) of the samples and of the gaps in a window;
    ``b`` None: to the end; empty when ``b < a``."""

    pa: int
    pb: int | None
    ga: int
    gb: int | None


def window_range(a_rel: int, b_rel: int | None, dt: int, gap_query: bool, empty: bool) -> WindowRange:
    """Positions overlapping ``[t_i + a_rel, t_i + b_rel]`` and not before the query position (``t_i`` its sample
    time). A sample k is in it iff ``a_rel <= (k - i) dt <= b_rel``; a gap k (``[t_k + 1, t_k + dt - 1]``) iff
    ``t_k + dt - 1 >= t_i + a_rel`` and ``t_k + 1 <= t_i + b_rel``."""
    if empty:
        return WindowRange(1, 0, 1, 0)
    pa = max(_ceil_div(a_rel, dt), 1 if gap_query else 0)
    ga = max(_ceil_div(a_rel - dt + 1, dt), 0)
    if b_rel is None:
        return WindowRange(pa, None, ga, None)
    return WindowRange(pa, b_rel // dt, ga, (b_rel - 1) // dt)


#: widths up to this use the blocked doubling (log2(width) cache-resident passes), wider ones van Herk/Gil-Werman
_DOUBLING_MAX_WIDTH = 1 << 13
#: query positions per block of the doubling (plus width - 1 of overlap); the block's two buffers stay in cache
_DOUBLING_BLOCK = 1 << 15


def sliding_clipped(x: FloatArray, width: int, op: np.ufunc, identity: float, *, block: int = 0) -> FloatArray:
    """``out[k] = op(x[k : k + width])`` for every k < len(x) (windows clipped at the end; ``op`` is min or max,
    exact, so every evaluation order gives the same values). ``block`` > 0 forces the doubling with that block
    size (tests)."""
    n = x.shape[0]
    if width <= 1 or n == 0:
        return x
    width = min(width, n)  # every window is clipped at the end: a wider one is x[k:], so memory follows the log
    if block > 0 or width <= _DOUBLING_MAX_WIDTH:
        return _sliding_doubling(x, width, op, block or max(_DOUBLING_BLOCK, 4 * width))
    m = -(-(n + width - 1) // width)
    xp = np.empty(m * width)
    xp[:n] = x
    xp[n:] = identity
    prefix = op.accumulate(xp.reshape(m, width), axis=1).ravel()
    suffix = op.accumulate(xp[::-1].reshape(m, width), axis=1).ravel()[::-1]
    return op(suffix[:n], prefix[width - 1 : width - 1 + n])  # type: ignore[no-any-return]


def _sliding_doubling(x: FloatArray, width: int, op: np.ufunc, block: int) -> FloatArray:
    """Sparse-table sliding reduction, block by block: after the pass with shift s, ``c[k] = op(x[k : k + 2s])``
    (clipped at the end of the loaded part, which reaches ``width - 1`` past the block or to the end of ``x``);
    the last step combines two overlapping windows of the largest power of two <= width."""
    n = x.shape[0]
    out = np.empty(n)
    cur = np.empty(min(n, block + width - 1))
    nxt = np.empty_like(cur)
    for s0 in range(0, n, block):
        e0 = min(n, s0 + block)
        m = min(n, e0 + width - 1) - s0
        c, t = cur[:m], nxt[:m]
        c[:] = x[s0 : s0 + m]
        s = 1
        while 2 * s <= width:
            k = max(m - s, 0)
            op(c[:k], c[s : s + k], out=t[:k])
            t[k:] = c[k:]
            c, t = t, c
            s *= 2
        q = e0 - s0
        if s < width:
            sh = width - s
            k = max(min(q, m - sh), 0)
            op(c[:k], c[sh : sh + k], out=out[s0 : s0 + k])
            out[s0 + k : e0] = c[k:q]
        else:
            out[s0:e0] = c[:q]
    return out


def _window_reduce(x: FloatArray, a: int, b: int | None, *, nq: int, op: np.ufunc, identity: float) -> FloatArray:
    """``out[i] = op(x[i + a : i + b + 1])`` clipped to ``x`` (``identity`` when empty), for ``i < nq``."""
    size = x.shape[0]
    valid = max(0, min(nq, size - a))
    if (b is not None and b < a) or valid == 0:
        return np.full(nq, identity)
    reduced = op.accumulate(x[::-1])[::-1] if b is None else sliding_clipped(x, b - a + 1, op, identity)
    if a == 0 and valid == nq:
        return reduced[:nq]
    out = np.empty(nq)
    out[:valid] = reduced[a : a + valid]
    out[valid:] = identity
    return out


def _shifted(x: FloatArray, offset: int, nq: int, identity: float) -> FloatArray:
    """``out[i] = x[i + offset]`` (``identity`` past the end), ``offset >= 0``."""
    out = np.full(nq, identity)
    valid = max(0, min(nq, x.shape[0] - offset))
    out[:valid] = x[offset : offset + valid]
    return out


def reduce_window(p: FloatArray, g: FloatArray, r: WindowRange, *, nq: int, op: np.ufunc,
                  identity: float) -> FloatArray:
    """``op`` over the samples ``p[i + r.pa .. i + r.pb]`` and the gaps ``g[i + r.ga .. i + r.gb]``.

    When the two ranges differ by at most one position at each end (always the case on a grid unless a range is
    empty), sample k and gap k (the one after it) are merged into one cell first, so that one sliding reduction
    covers both, plus at most one extra sample or gap at the ends."""
    left = r.ga in (r.pa, r.pa - 1)
    right = r.gb is None if r.pb is None else (r.gb is not None and r.gb in (r.pb, r.pb - 1))
    nonempty = (r.pb is None or r.pa <= r.pb) and (r.gb is None or r.ga <= r.gb)
    if not (left and right and nonempty):
        return op(_window_reduce(p, r.pa, r.pb, nq=nq, op=op, identity=identity),  # type: ignore[no-any-return]
                  _window_reduce(g, r.ga, r.gb, nq=nq, op=op, identity=identity))
    cells = np.empty(p.shape[0])
    op(p[:-1], g, out=cells[:-1])
    cells[-1] = p[-1]
    c1 = None if r.pb is None or r.gb is None else min(r.pb, r.gb)
    out = _window_reduce(cells, r.pa, c1, nq=nq, op=op, identity=identity)
    if r.ga == r.pa - 1:
        out = op(out, _shifted(g, r.ga, nq, identity))
    if r.pb is not None and r.gb == r.pb - 1:
        out = op(out, _shifted(p, r.pb, nq, identity))
    return out
