"""The product search against brute force: every short lasso run with every dwell duration on the tick grid.

Small random WTSs (3 regions, integer weights) and random formulas over the whole grammar (next, eventually,
always, until, open/closed/unbounded intervals, nesting). The planner's run must satisfy the formula under the
exact reference semantics, and whenever brute force finds a satisfying lasso, the planner must find one too
(the exact search with one-tick delays loses nothing against every grid dwell duration), and the exact search
alone (without the fast first attempt) reaches the same verdict and cost. Time-optimality against brute force is
checked on chain-shaped WTSs in ``property_tests/test_semantics.py``, on windows in ``test_search.py``.

Three modes: observed dwells (each dwell a position; brute force over dwell positions of 1..6 half-ticks), silent
waits (no position; brute force over every wait of 0..6 half-ticks before every departure, including the first,
and over runs that end by staying in their last region forever), and no waiting.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest

from tubempc.errors import NoAcceptingRunError
from tubempc.mitl import Always, And, Atom, Eventually, Formula, Implies, Interval, Next, Not, Or, Until
from tubempc.planning import LassoRun, find_run, holds, make_wts

HALF = Fraction(1, 2)


def random_interval(rng: np.random.Generator) -> Interval:
    lo = int(rng.integers(0, 3))
    if rng.random() < 0.3:
        return Interval(Fraction(lo), None, lo_closed=bool(rng.random() < 0.7))
    hi = lo + int(rng.integers(0, 3))
    lc, hc = bool(rng.random() < 0.7), bool(rng.random() < 0.7)
    if hi == lo:
        lc = hc = True
    return Interval(Fraction(lo), Fraction(hi), lo_closed=lc, hi_closed=hc)


def random_formula(rng: np.random.Generator, depth: int) -> Formula:
    if depth == 0 or rng.random() < 0.25:
        a = Atom(str(rng.choice(["p", "q"])))
        return Not(a) if rng.random() < 0.3 else a
    op = int(rng.integers(0, 8))
    sub = random_formula(rng, depth - 1)
    if op == 0:
        return Eventually(random_interval(rng), sub)
    if op == 1:
        return Always(random_interval(rng), sub)
    if op == 2:
        return Until(random_interval(rng), sub, random_formula(rng, depth - 1))
    if op == 3:
        return Next(random_interval(rng), sub)
    if op == 4:
        return And((sub, random_formula(rng, depth - 1)))
    if op == 5:
        return Or((sub, random_formula(rng, depth - 1)))
    if op == 6:
        return Implies(sub, random_formula(rng, depth - 1))
    return Not(sub)


def random_wts(rng: np.random.Generator):  # type: ignore[no-untyped-def]
    labels = {"A": ("p",), "B": ("q",), "C": ()}
    if rng.random() < 0.5:
        labels["C"] = ("p", "q")
    weights = {}
    for a, b in itertools.permutations(labels, 2):
        if rng.random() < 0.8:
            weights[(a, b)] = int(rng.integers(1, 4))
    return make_wts(labels, weights, initial="A"), labels, weights


def brute_force(labels, weights, formula: Formula, *, wait: bool, max_pos: int = 4,  # type: ignore[no-untyped-def]
                max_dwell: int = 6) -> Fraction | None:
    """Earliest loop entry time over all lassos with at most ``max_pos`` positions (dwells: 1..max_dwell ticks)."""
    dwells = [HALF * k for k in range(1, max_dwell + 1)] if wait else []

    def steps(region: str) -> list[tuple[str, Fraction]]:
        out = [(b, Fraction(w)) for (a, b), w in weights.items() if a == region]
        out.extend((region, d) for d in dwells)
        return out

    best: Fraction | None = None
    stack: list[tuple[tuple[str, ...], tuple[Fraction, ...]]] = [(("A",), (Fraction(0),))]
    while stack:
        regions, times = stack.pop()
        for loop in range(len(regions)):
            if best is not None and times[loop] >= best:
                continue
            for nxt, d in steps(regions[-1]):
                if nxt != regions[loop]:
                    continue
                period = times[-1] - times[loop] + d
                run = LassoRun(regions, times, loop_start=loop, period=period)
                if holds(formula, run, labels):
                    best = times[loop]
        if len(regions) < max_pos:
            for nxt, d in steps(regions[-1]):
                stack.append(((*regions, nxt), (*times, times[-1] + d)))
    return best


def brute_force_lasso_silent(labels, weights, formula: Formula, *, max_pos: int,  # type: ignore[no-untyped-def]
                             max_wait: int = 6) -> Fraction | None:
    """Earliest loop entry (or end) over all runs, lassos included (``brute_force_silent`` of the package: finite
    runs only), of at most ``max_pos`` arrivals (the start included), with a
    silent wait of 0..max_wait half-ticks before every move (the closing move of a lasso included); a finite run
    stays in its last region forever without a further position."""
    waits = [HALF * k for k in range(max_wait + 1)]

    def steps(region: str) -> list[tuple[str, Fraction]]:
        return [(b, Fraction(w) + d) for (a, b), w in weights.items() if a == region for d in waits]

    best: Fraction | None = None
    stack: list[tuple[tuple[str, ...], tuple[Fraction, ...]]] = [(("A",), (Fraction(0),))]
    while stack:
        regions, times = stack.pop()
        if (best is None or times[-1] < best) and holds(formula, LassoRun(regions, times), labels):
            best = times[-1]
        for loop in range(len(regions)):
            if best is not None and times[loop] >= best:
                continue
            for nxt, d in steps(regions[-1]):
                if nxt == regions[loop]:
                    run = LassoRun(regions, times, loop_start=loop, period=times[-1] - times[loop] + d)
                    if holds(formula, run, labels):
                        best = times[loop]
                        break
        if len(regions) < max_pos:
            for nxt, d in steps(regions[-1]):
                stack.append(((*regions, nxt), (*times, times[-1] + d)))
    return best


def _check(seed: int, *, wait: bool, dwell: str = "observed", max_pos: int = 4) -> None:
    rng = np.random.default_rng(seed)
    wts, labels, weights = random_wts(rng)
    formula = random_formula(rng, 2)
    try:
        found = find_run(wts, formula, wait=wait, dwell=dwell)
    except NoAcceptingRunError:
        found = None
    if wait:
        # the exact search alone (no first attempt) reaches the same verdict and the same cost
        try:
            alone = find_run(wts, formula, wait=wait, dwell=dwell, first_attempt=False, diagnose=False)
        except NoAcceptingRunError:
            alone = None
        assert (alone is None) == (found is None), (seed, str(formula))
        if alone is not None and found is not None:
            assert holds(formula, alone.run, labels), (formula, alone.run)
            assert _cost(alone.run) == _cost(found.run), (seed, str(formula), alone.run, found.run)
    if found is not None:
        assert holds(formula, found.run, labels), (formula, found.run)
        if wait and dwell == "silent":
            assert set(found.kinds) <= {"start", "move"}, found.kinds  # a silent wait is never a position
    if wait and dwell == "silent":
        bf = brute_force_lasso_silent(labels, weights, formula, max_pos=max_pos)
    else:
        bf = brute_force(labels, weights, formula, wait=wait, max_pos=max_pos)
    if bf is not None:
        assert found is not None, f"seed {seed}: planner found no run for {formula}, brute force entered at {bf}"


def _cost(run: LassoRun) -> Fraction:
    return run.times[run.loop_start if run.loop_start is not None else run.size - 1]


@pytest.mark.parametrize("seed", range(40))
def test_against_brute_force_with_waits(seed: int) -> None:
    _check(seed, wait=True)


@pytest.mark.parametrize("seed", range(40))
def test_against_brute_force_silent_waits(seed: int) -> None:
    _check(2000 + seed, wait=True, dwell="silent", max_pos=3)


def test_silent_wait_aimed_two_moves_ahead() -> None:
    # A -2-> B -3-> C only: q (at C) in [10,12] and every p (at B) answered by q within 5 s. Waiting at B would
    # leave B at 2 and C past 7; the wait must be taken in A before the first departure (B at 7, C at 10).
    labels = {"A": ("r",), "B": ("p",), "C": ("q",)}
    weights = {("A", "B"): 2, ("B", "C"): 3}
    formula = And((Eventually(Interval(Fraction(10), Fraction(12)), Atom("q")),
                   Always(Interval(Fraction(0), None), Implies(Atom("p"), Eventually(Interval(Fraction(0),
                                                                                               Fraction(5)),
                                                                                      Atom("q"))))))
    found = find_run(make_wts(labels, weights, initial="A"), formula, dwell="silent")
    assert found.run.regions == ("A", "B", "C") and found.run.times == (0, 7, 10)
    assert found.waits_s == (0, 5, 0) and found.run.loop_start is None
    assert brute_force_lasso_silent(labels, weights, formula, max_pos=3, max_wait=10) == 10


@pytest.mark.parametrize("seed", range(40))
def test_against_brute_force_without_waits(seed: int) -> None:
    _check(1000 + seed, wait=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(40, 400))
def test_against_brute_force_many(seed: int) -> None:
    _check(seed, wait=bool(seed % 2))


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(40, 240))
def test_against_brute_force_silent_many(seed: int) -> None:
    _check(2000 + seed, wait=True, dwell="silent", max_pos=3)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(30))
def test_against_brute_force_silent_four_positions(seed: int) -> None:
    _check(3000 + seed, wait=True, dwell="silent", max_pos=4)
