"""Re-timing: a found run skeleton -> the same regions with wait durations that maximise the timing margin.

input: the search's ``LassoRun`` with the kind of each position (``move`` durations are fixed WTS weights, plus a
free silent wait before the departure in silent mode; observed ``dwell`` durations are free), the formula and the
labels -> output: a ``Retimed`` run (times rounded to the millisecond, re-checked exactly) and its margin: the
smallest distance, in seconds, between a time difference the verdict depends on and the interval endpoint it must
stay on the right side of.

Which differences matter is read off the exact truth table of the skeleton: for an existential operator
(``F``, ``U``, ``!G``) that holds at an anchor, one witness (the one with the most slack) must stay inside its
window; when it does not hold, every candidate must stay outside; ``X`` keeps the membership of its successor.
The children are kept where these choices use them, recursively. Keeping those memberships keeps the truth of every
sub-formula that the verdict uses, so the re-timed run satisfies the formula (and it is re-checked exactly).
Three linear programs (cvxpy): maximise the smallest slack (the margin); at that margin, maximise the sum of the
slacks of the two-sided windows (each capped at its half width: witnesses move towards the window centres); at
both optima, minimise the total duration. Durations of the repeating part stay fixed (the suffix is periodic).
Objective ``time`` (default) adds one constraint: the run's cost (its last position, or its repeating part's first)
stays at or before the search's, so the re-timing never gives up time-optimality for margin; ``margin`` drops it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from tubempc.mitl import Always, And, Eventually, Formula, Implies, Interval, Next, Not, Or, Until, subformulas
from tubempc.planning.reference_semantics import LassoRun, holds, truth_table

__all__ = ["OBJECTIVES", "Retimed", "retime"]

OBJECTIVES = ("time", "margin")

_MARGIN_CAP_S = 1e4  # bounds the LP when nothing limits the margin
_ROUND = Fraction(1, 1000)  # re-timed dwells are rounded to the millisecond


@dataclass(frozen=True, slots=True)
class Retimed:
    """``margin_s`` is ``inf`` when no time difference matters to the verdict."""

    run: LassoRun
    margin_s: float
    retimed: bool


@dataclass(frozen=True, slots=True)
class _Keep:
    """Keep ``t_j - t_i`` inside (``inside=True``) or on its current side outside of ``interval``."""

    i: int
    j: int
    interval: Interval
    inside: bool


def _max_constant(formula: Formula) -> Fraction:
    out = Fraction(0)
    for f in subformulas(formula):
        if isinstance(f, Next | Eventually | Always | Until):
            out = max(out, f.interval.lo if f.interval.hi is None else f.interval.hi)
    return out


def _slack(d: Fraction | float, keep: _Keep, original: Fraction) -> float:
    iv = keep.interval
    if keep.inside:
        s = float(d - iv.lo)
        return s if iv.hi is None else min(s, float(iv.hi - d))
    if original < iv.lo:
        return float(iv.lo - d)
    if iv.hi is None:
        raise ValueError("a difference outside an unbounded window must lie below it")
    return float(d - iv.hi)


def _keeps(formula: Formula, run: LassoRun, labels: Mapping[str, Sequence[str]], horizon: int) -> list[_Keep]:
    table = truth_table(formula, run, labels)
    loop = run.loop_start if run.loop_start is not None else run.size
    keeps: list[_Keep] = []
    seen: set[tuple[Formula, int]] = set()
    todo: list[tuple[Formula, int]] = [(formula, 0)]

    def val(f: Formula, k: int) -> bool:
        return table[f][run.canon(k)]

    while todo:
        f, i = todo.pop()
        if (f, i) in seen or i >= loop or i >= horizon:
            continue  # anchors in the repeating part only look at fixed differences
        seen.add((f, i))
        if isinstance(f, Not):
            todo.append((f.arg, i))
        elif isinstance(f, And | Or):
            todo.extend((a, i) for a in f.args)
        elif isinstance(f, Implies):
            todo.extend(((f.left, i), (f.right, i)))
        elif isinstance(f, Next):
            j = i + 1
            if run.exists(j):
                todo.append((f.arg, j))
                if val(f.arg, j):
                    keeps.append(_Keep(i, j, f.interval, f.interval.contains(run.time(j) - run.time(i))))
        elif isinstance(f, Eventually | Always | Until):
            found, used = _window_keeps(f, i, run, val, horizon=horizon, loop=loop)
            keeps.extend(found)
            todo.extend(used)
    return keeps


def _window_keeps(f: Eventually | Always | Until, i: int, run: LassoRun, val: Callable[[Formula, int], bool], *,
                  horizon: int, loop: int) -> tuple[list[_Keep], list[tuple[Formula, int]]]:
    """A window operator anchored at ``i``: the memberships its truth depends on (one witness inside when it holds,
    every candidate outside when it does not) and the (sub-formula, position) pairs whose truth those choices use."""
    if isinstance(f, Until):
        left: Formula | None = f.left
        right, want = f.right, True
    else:
        left, right, want = None, f.arg, isinstance(f, Eventually)
    iv = f.interval
    t0 = run.time(i)
    holds_now = val(f, i) if isinstance(f, Eventually | Until) else not val(f, i)
    cands: list[int] = []
    for k in range(i, horizon):
        if val(right, k) == want:
            cands.append(k)
        if left is not None and not val(left, k):
            break
    used: list[tuple[Formula, int]] = []
    if not holds_now:
        for k in range(i, horizon):
            used.append((right, k))
            if left is not None:
                used.append((left, k))
        return [_Keep(i, k, iv, False) for k in cands], used
    inside = [k for k in cands if iv.contains(run.time(k) - t0)]
    if not inside:
        return [], []  # the witness lies beyond the horizon: differences there are fixed
    # prefer a witness before the repeating part: its time is the plan's, not a far copy's
    pool = [k for k in inside if k <= loop] or inside
    best = max(pool, key=lambda k: _slack(run.time(k) - t0, _Keep(i, k, iv, True), run.time(k) - t0))
    used.append((right, best))
    if left is not None:
        used.extend((left, k) for k in range(i, best))
    return [_Keep(i, best, iv, True)], used


def retime(run: LassoRun, kinds: Sequence[str], formula: Formula, labels: Mapping[str, Sequence[str]], *,
           min_dwell_s: Fraction, waits_s: Sequence[Fraction] | None = None, objective: str = "time") -> Retimed:
    """Maximise the margin over the free durations of the prefix of ``run`` (see the module docstring).

    Observed dwells (``kinds[p] == "dwell"``) last at least ``min_dwell_s``. With ``waits_s`` (silent mode: the
    wait before the move into each position), every prefix move is free: it lasts at least its WTS weight
    (``times[p] - times[p - 1] - waits_s[p]``), the excess being the silent wait before its departure.
    ``objective="time"`` (default): the run's cost (its last position, or its repeating part's first one) stays
    at or before the search's, so a time-optimal run stays time-optimal; ``"margin"``: the margin alone counts
    (the cost may grow)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective={objective!r} must be one of {OBJECTIVES}")
    loop = run.loop_start if run.loop_start is not None else run.size - 1
    span = _max_constant(formula) + (run.period or 0) + 1
    horizon = 0
    while run.exists(horizon) and run.time(horizon) <= run.time(loop) + span:
        horizon += 1
    keeps = _keeps(formula, run, labels, horizon)
    if not keeps:
        return Retimed(run, math.inf, False)
    originals = [run.time(k.j) - run.time(k.i) for k in keeps]
    margin0 = min(_slack(d, k, d) for d, k in zip(originals, keeps, strict=True))
    free = _free_steps(run, kinds, loop=loop, min_dwell_s=min_dwell_s, waits_s=waits_s)
    if not free:
        return Retimed(run, margin0, False)
    new = _solve(run, keeps, originals, free, loop=loop, keep_cost=objective == "time")
    if new is None:
        return Retimed(run, margin0, False)
    durations = _rounded(run, free, new, keep_cost=objective == "time")
    times = [Fraction(0)]
    for p in range(1, run.size):
        step = durations.get(p, run.times[p] - run.times[p - 1])
        times.append(times[-1] + step)
    candidate = LassoRun(run.regions, tuple(times), run.loop_start, run.period)
    if objective == "time" and candidate.times[loop] > run.times[loop]:
        return Retimed(run, margin0, False)  # rounding moved the cost past the optimum
    if not holds(formula, candidate, labels):
        return Retimed(run, margin0, False)
    margin = min(_slack(candidate.time(k.j) - candidate.time(k.i), k, d) for d, k in zip(originals, keeps, strict=True))
    if margin < margin0:
        return Retimed(run, margin0, False)
    return Retimed(candidate, margin, True)


def _free_steps(run: LassoRun, kinds: Sequence[str], *, loop: int, min_dwell_s: Fraction,
                waits_s: Sequence[Fraction] | None) -> dict[int, Fraction]:
    """Position -> minimum duration of the step into it, for the steps of the prefix the re-timing may change: an
    observed dwell (at least ``min_dwell_s``) and, in silent mode, a move (at least its WTS weight)."""
    free: dict[int, Fraction] = {}
    for p in range(1, loop + 1):
        if kinds[p] == "dwell":
            free[p] = min_dwell_s
        elif waits_s is not None and kinds[p] == "move":
            free[p] = run.times[p] - run.times[p - 1] - waits_s[p]
    return free


def _rounded(run: LassoRun, free: Mapping[int, Fraction], new: Sequence[float], *,
             keep_cost: bool) -> dict[int, Fraction]:
    """The solver's durations rounded to the millisecond (never below their minimum); with ``keep_cost`` the excess
    rounding adds to the cost is taken off the free step with the most room, when one has enough."""
    durations = {p: max(lo, round(Fraction(x) / _ROUND) * _ROUND) for (p, lo), x in zip(free.items(), new,
                                                                                          strict=True)}
    if keep_cost:
        excess = sum(durations.values()) - sum(run.times[p] - run.times[p - 1] for p in free)
        if excess > 0:
            slackest = max(free, key=lambda p: durations[p] - free[p])
            if durations[slackest] - free[slackest] >= excess:
                durations[slackest] -= excess
    return durations


@dataclass(frozen=True, slots=True)
class _Rows:
    """The keeps as linear slacks of the free durations ``x``: ``a @ x + b`` (one row per side of a window),
    ``owner[r]`` the keep of row ``r``, ``half[k]`` the half width of keep ``k``'s two-sided window (0: one-sided)."""

    a: np.ndarray
    b: np.ndarray
    owner: list[int]
    half: list[float]


def _rows(keeps: list[_Keep], originals: list[Fraction], positions: list[int], x0: np.ndarray, *,
          loop: int) -> _Rows:
    col = {p: c for c, p in enumerate(positions)}
    rows: list[np.ndarray] = []
    consts: list[float] = []
    owner: list[int] = []
    half: list[float] = []
    for idx, (keep, d0) in enumerate(zip(keeps, originals, strict=True)):
        # d = d0 + sum over free steps between i (exclusive) and j (inclusive, capped at the loop start) of (x - x0)
        coeff = np.zeros(len(positions))
        for p in range(keep.i + 1, min(keep.j, loop) + 1):
            c = col.get(p)
            if c is not None:
                coeff[c] = 1.0
        base = float(d0) - float(coeff @ x0)
        iv = keep.interval
        sides: list[tuple[float, float]] = []  # slack = sign * d + offset
        if keep.inside:
            sides.append((1.0, -float(iv.lo)))
            if iv.hi is not None:
                sides.append((-1.0, float(iv.hi)))
        elif d0 < iv.lo:
            sides.append((-1.0, float(iv.lo)))
        elif iv.hi is not None:
            sides.append((1.0, -float(iv.hi)))
        two_sided = keep.inside and iv.hi is not None and bool(coeff.any())
        half.append(float(iv.hi - iv.lo) / 2 if two_sided and iv.hi is not None else 0.0)
        for sign, offset in sides:
            rows.append(sign * coeff)
            consts.append(sign * base + offset)
            owner.append(idx)
    return _Rows(np.array(rows), np.array(consts), owner, half)


def _solve(run: LassoRun, keeps: list[_Keep], originals: list[Fraction], free: Mapping[int, Fraction], *,
           loop: int, keep_cost: bool) -> list[float] | None:
    import cvxpy as cp

    positions = list(free)
    x0 = np.array([float(run.times[p] - run.times[p - 1]) for p in positions])
    lower = np.array([float(free[p]) for p in positions])
    lin = _rows(keeps, originals, positions, x0, loop=loop)
    a, b, owner, half = lin.a, lin.b, lin.owner, lin.half
    x = cp.Variable(len(positions))
    m = cp.Variable()
    base_cons = [x >= lower, m <= _MARGIN_CAP_S]
    if keep_cost:
        # every free step lies before the loop start (or the last position): their sum fixes the cost
        base_cons.append(cp.sum(x) <= float(x0.sum()))  # type: ignore[attr-defined]
    centred = [k for k, h in enumerate(half) if h > 0]
    try:
        p1 = cp.Problem(cp.Maximize(m), [*base_cons, a @ x + b >= m])
        p1.solve(solver=cp.CLARABEL)  # type: ignore[no-untyped-call]
        if p1.status not in ("optimal", "optimal_inaccurate") or m.value is None:
            return None
        if float(m.value) <= 1e-6:
            if not keep_cost:
                return None
            # the optimum sits on a window end (margin 0): still centre the other witnesses at that cost
            best = 0.0
        else:
            best = float(m.value) * (1 - 1e-6) - 1e-9
        cons = [*base_cons, a @ x + b >= best]
        if centred:
            # each two-sided window's own slack s_k (<= both sides, <= half width), summed: witnesses move to centres
            s = cp.Variable(len(centred))
            pick = {k: n for n, k in enumerate(centred)}
            sel = np.zeros((len(owner), len(centred)))
            for r, k in enumerate(owner):
                if k in pick:
                    sel[r, pick[k]] = 1.0
            mask = sel.any(axis=1)
            link = [a[mask] @ x + b[mask] >= sel[mask] @ s, s <= np.array([half[k] for k in centred])]
            p2 = cp.Problem(cp.Maximize(cp.sum(s)), [*cons, *link])  # type: ignore[attr-defined]
            p2.solve(solver=cp.CLARABEL)  # type: ignore[no-untyped-call]
            if p2.status in ("optimal", "optimal_inaccurate") and p2.value is not None:
                total_s = float(p2.value)
                cons = [*cons, *link, cp.sum(s) >= total_s * (1 - 1e-6) - 1e-9]  # type: ignore[attr-defined]
        p3 = cp.Problem(cp.Minimize(cp.sum(x)), cons)  # type: ignore[attr-defined]
        p3.solve(solver=cp.CLARABEL)  # type: ignore[no-untyped-call]
        if p3.status not in ("optimal", "optimal_inaccurate") or x.value is None:
            return None
        return [float(v) for v in x.value]
    except cp.error.SolverError:
        return None
