"""Exact pointwise MITL semantics on lasso timed runs (the planner's own reference evaluator).

input: a ``Formula``, a ``LassoRun`` (regions and exact ``Fraction`` times; a prefix and a repeating suffix) and the
region labels -> output: the truth of every sub-formula at every canonical position (``truth_table``) and the verdict
at position 0 (``holds``).

Semantics (the same as the certifier's timed-run monitor): ``p`` holds at ``i`` iff ``p`` labels ``r(i)``;
``a U_I b`` at ``i`` iff some ``j >= i`` with ``t_j - t_i in I`` has ``b`` and ``a`` holds at every ``k`` in
``[i, j)``; ``F_I a = true U_I a``; ``G_I a = !F_I !a``; ``X_I a`` at ``i`` iff ``t_{i+1} - t_i in I`` and ``a`` holds
at ``i + 1``. Positions of the repeating part have identical futures in every copy, so one copy carries their truth.
Used to cross-check the product search (brute-force tests) and to validate re-timed plans; ``brute_force_silent``
enumerates every finite run with silent waits on a time grid (the planner's independent reference for tests).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Next, Not, Or, Until, subformulas

__all__ = ["LassoRun", "brute_force_silent", "holds", "truth_table"]


@dataclass(frozen=True, slots=True)
class LassoRun:
    """``regions[i]`` entered (or dwelt in) at ``times[i]``; positions ``loop_start..n-1`` repeat forever, the copy
    of position ``loop_start`` coming ``period`` after it. ``loop_start is None``: a finite run (no repetition)."""

    regions: tuple[str, ...]
    times: tuple[Fraction, ...]
    loop_start: int | None = None
    period: Fraction | None = None

    def __post_init__(self) -> None:
        n = len(self.regions)
        if n == 0 or len(self.times) != n:
            raise ValueError(f"regions ({n}) and times ({len(self.times)}) must be non-empty and of equal length")
        if self.times[0] != 0:
            raise ValueError(f"times[0]={self.times[0]} must be 0")
        for i in range(1, n):
            if not self.times[i] > self.times[i - 1]:
                raise ValueError(f"times must increase strictly: times[{i}]={self.times[i]} <= {self.times[i - 1]}")
        if self.loop_start is not None:
            if not 0 <= self.loop_start < n:
                raise ValueError(f"loop_start={self.loop_start} is not a position of the run (n={n})")
            if self.period is None or self.period <= self.times[-1] - self.times[self.loop_start]:
                raise ValueError(f"period={self.period} must exceed the span of the repeating part")
        elif self.period is not None:
            raise ValueError("a period needs a loop_start")

    @property
    def size(self) -> int:
        return len(self.regions)

    def canon(self, k: int) -> int:
        """Canonical position of unrolled index ``k``."""
        n = len(self.regions)
        if k < n or self.loop_start is None:
            return k
        length = n - self.loop_start
        return self.loop_start + (k - self.loop_start) % length

    def time(self, k: int) -> Fraction:
        """Time of unrolled index ``k`` (``k < size`` when the run is finite)."""
        n = len(self.regions)
        if k < n:
            return self.times[k]
        if self.loop_start is None or self.period is None:
            raise IndexError(f"position {k} is past the end of a finite run of {n} positions")
        length = n - self.loop_start
        copies, rem = divmod(k - self.loop_start, length)
        return self.times[self.loop_start + rem] + copies * self.period

    def exists(self, k: int) -> bool:
        return self.loop_start is not None or k < len(self.regions)

    def unrolled(self, until_s: Fraction) -> list[tuple[str, Fraction]]:
        """Positions in time order up to (and including) ``until_s``."""
        out: list[tuple[str, Fraction]] = []
        k = 0
        while self.exists(k) and self.time(k) <= until_s:
            out.append((self.regions[self.canon(k)], self.time(k)))
            k += 1
        return out


def _window_end(run: LassoRun, i: int, lo: Fraction, hi: Fraction | None) -> int:
    """First unrolled index past every position that can matter for a window [lo, hi] anchored at ``i``."""
    t0 = run.time(i)
    k = i
    if hi is not None:
        while run.exists(k) and run.time(k) - t0 <= hi:
            k += 1
        return k
    # unbounded: past the lower end, plus one full repetition (later witnesses repeat earlier ones)
    while run.exists(k) and run.time(k) - t0 < lo:
        k += 1
    if run.loop_start is not None:
        k = max(k, run.loop_start) + (run.size - run.loop_start) + 1
    return k if run.loop_start is not None else min(k + run.size, run.size)


def truth_table(formula: Formula, run: LassoRun, labels: Mapping[str, Sequence[str]]) -> dict[Formula, list[bool]]:
    """Truth of every sub-formula at canonical positions ``0..size-1``."""
    n = run.size
    table: dict[Formula, list[bool]] = {}
    for f in subformulas(formula):
        if f in table:
            continue
        table[f] = _values(f, run, labels, table, n)
    return table


def _values(f: Formula, run: LassoRun, labels: Mapping[str, Sequence[str]], table: dict[Formula, list[bool]],
            n: int) -> list[bool]:
    if isinstance(f, Const):
        return [f.value] * n
    if isinstance(f, Atom):
        return [f.name in labels.get(run.regions[i], ()) for i in range(n)]
    if isinstance(f, Not):
        return [not v for v in table[f.arg]]
    if isinstance(f, And):
        return [all(table[a][i] for a in f.args) for i in range(n)]
    if isinstance(f, Or):
        return [any(table[a][i] for a in f.args) for i in range(n)]
    if isinstance(f, Implies):
        return [(not table[f.left][i]) or table[f.right][i] for i in range(n)]
    if isinstance(f, Next):
        out = []
        for i in range(n):
            j = i + 1
            ok = run.exists(j) and f.interval.contains(run.time(j) - run.time(i)) and table[f.arg][run.canon(j)]
            out.append(bool(ok))
        return out
    if isinstance(f, Eventually | Always | Until):
        iv = f.interval
        if isinstance(f, Until):
            left, right = table[f.left], table[f.right]
        elif isinstance(f, Eventually):
            left, right = [True] * n, table[f.arg]
        else:
            left, right = [True] * n, [not v for v in table[f.arg]]
        out = []
        for i in range(n):
            t0 = run.time(i)
            end = _window_end(run, i, iv.lo, iv.hi)
            found = False
            for k in range(i, end):
                c = run.canon(k)
                if right[c] and iv.contains(run.time(k) - t0):
                    found = True
                    break
                if not left[c]:
                    break
            out.append(found if not isinstance(f, Always) else not found)
        return out
    raise TypeError(f"formula={f!r} is not an MITL formula")


def holds(formula: Formula, run: LassoRun, labels: Mapping[str, Sequence[str]]) -> bool:
    """Whether the run satisfies ``formula`` at position 0."""
    return truth_table(formula, run, labels)[formula][0]


def brute_force_silent(labels: Mapping[str, Sequence[str]], weights: Mapping[tuple[str, str], Fraction | int],
                       formula: Formula, *, initial: str, grid_s: Fraction, max_moves: int,
                       until_s: Fraction, dead: Callable[[LassoRun], bool] | None = None) -> LassoRun | None:
    """The earliest-ending satisfying finite run, by brute force: every run of at most ``max_moves`` moves along
    ``weights`` (``(a, b) -> seconds``) from ``initial``, with every silent wait on the ``grid_s`` grid before every
    departure (the first included), every position at or before ``until_s``; the robot stays in its last region
    forever without a further position. Ties: fewer positions first. ``None`` when no such run satisfies
    ``formula``. ``dead(run)`` (optional) says that no extension of the finite run by later positions can satisfy
    the formula (the caller vouches for it); such runs are not extended. Exponential: for tests on small WTSs."""
    if grid_s <= 0 or max_moves < 0:
        raise ValueError(f"grid_s={grid_s} must be positive and max_moves={max_moves} non-negative")
    out: dict[str, list[tuple[str, Fraction]]] = {}
    for (a, b), w in weights.items():
        out.setdefault(a, []).append((b, Fraction(w)))
    best: LassoRun | None = None
    stack: list[tuple[tuple[str, ...], tuple[Fraction, ...]]] = [((initial,), (Fraction(0),))]
    while stack:
        regions, times = stack.pop()
        if best is not None and (times[-1], len(times)) >= (best.times[-1], best.size):
            continue  # every extension ends later
        run = LassoRun(regions, times)
        if holds(formula, run, labels):
            best = run
            continue
        if len(regions) > max_moves or (dead is not None and dead(run)):
            continue
        for b, w in out.get(regions[-1], ()):
            t = times[-1] + w
            while t <= until_s:
                stack.append(((*regions, b), (*times, t)))
                t += grid_s
    return best
