"""The zone search (observed dwells) against the explicit-state searches on random instances.

On small random WTSs (3-4 regions, weights of 1-3 s, labels over ``p``, ``q``) and random formulas (the whole
grammar, depth 2, plus the response shapes whose copies cannot be merged before their window opens:
``G(p -> F[a,b] q) & F[c,d] p``), with observed dwells:

1. the planner with the zone search as its first stage (the default), with the event-driven explicit-state first
   stage (``zones=False``) and the exact search alone (``first_attempt=False``) agree: a run exists for all or
   none, and the runs found have the same cost (no missed run, no later run);
2. every run satisfies the formula under the exact reference semantics;
3. the zone search's own run (``optimal=False``: not re-checked by the exact search) is sound and never earlier
   than the optimum (an earlier one would be a run the exact search missed, or an unsound one).
"""

from __future__ import annotations

import itertools
from fractions import Fraction

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tubempc.errors import NoAcceptingRunError
from tubempc.mitl import Always, And, Atom, Eventually, Formula, Implies, Interval, Next, Not, Or, Until, parse
from tubempc.planning import LassoRun, find_run, holds, make_wts

Labels = dict[str, tuple[str, ...]]
Weights = dict[tuple[str, str], Fraction]


@st.composite
def intervals(draw: st.DrawFn) -> Interval:
    lo = draw(st.integers(0, 3))
    if draw(st.integers(0, 9)) < 2:
        return Interval(Fraction(lo), None, lo_closed=draw(st.booleans()))
    hi = lo + draw(st.integers(0, 3))
    if hi == lo:
        return Interval(Fraction(lo), Fraction(hi), True, True)
    return Interval(Fraction(lo), Fraction(hi), draw(st.booleans()), draw(st.booleans()))


@st.composite
def formulas(draw: st.DrawFn, depth: int = 2) -> Formula:
    if depth == 0 or draw(st.integers(0, 3)) == 0:
        a = Atom(draw(st.sampled_from(("p", "q"))))
        return Not(a) if draw(st.booleans()) else a
    op = draw(st.integers(0, 7))
    sub = draw(formulas(depth - 1))
    if op == 0:
        return Eventually(draw(intervals()), sub)
    if op == 1:
        return Always(draw(intervals()), sub)
    if op == 2:
        return Until(draw(intervals()), sub, draw(formulas(depth - 1)))
    if op == 3:
        return Next(draw(intervals()), sub)
    if op == 4:
        return And((sub, draw(formulas(depth - 1))))
    if op == 5:
        return Or((sub, draw(formulas(depth - 1))))
    if op == 6:
        return Implies(sub, draw(formulas(depth - 1)))
    return Not(sub)


@st.composite
def responses(draw: st.DrawFn) -> Formula:
    """``G(p -> F[a,b] q) & F[c,d] p``: a dwell in a ``p`` region anchors a copy per dwell position."""
    a = draw(st.integers(0, 3))
    b = a + draw(st.integers(0, 3))
    c = draw(st.integers(2, 8))
    d = c + draw(st.integers(0, 3))
    return And((Always(Interval(Fraction(0), None), Implies(Atom("p"), Eventually(
        Interval(Fraction(a), Fraction(b), True, True), Atom("q")))),
                 Eventually(Interval(Fraction(c), Fraction(d), True, True), Atom("p"))))


@st.composite
def wts_cases(draw: st.DrawFn) -> tuple[Labels, Weights]:
    names = ["A", "B", "C", "D"][: draw(st.integers(3, 4))]
    labels = {n: tuple(sorted(draw(st.sets(st.sampled_from(("p", "q")), max_size=2)))) for n in names}
    weights = {(a, b): Fraction(draw(st.integers(1, 3))) for a, b in itertools.permutations(names, 2)
               if draw(st.integers(0, 4)) > 0}
    return labels, weights


def _cost(run: LassoRun) -> Fraction:
    return run.times[run.loop_start if run.loop_start is not None else run.size - 1]


def _plan(wts: object, f: Formula, **kw: object) -> LassoRun | None:
    try:
        return find_run(wts, f, dwell="observed", diagnose=False, **kw).run  # type: ignore[arg-type]
    except NoAcceptingRunError:
        return None


@given(case=wts_cases(), f=st.one_of(formulas(), responses()))
@example(case=({"A": ("p",), "B": ("q",), "C": ()},
               {("A", "B"): Fraction(2), ("B", "A"): Fraction(2), ("B", "C"): Fraction(3), ("C", "B"): Fraction(3),
                ("A", "C"): Fraction(4), ("C", "A"): Fraction(4)}),
         f=parse("G(p -> F[1,2] q) & F[5,6] p"))
@example(case=({"A": ("p",), "B": ("q",), "C": ()},
               {("A", "B"): Fraction(2), ("B", "A"): Fraction(2), ("B", "C"): Fraction(3), ("C", "B"): Fraction(3),
                ("A", "C"): Fraction(4), ("C", "A"): Fraction(4)}),
         f=parse("G[2,2] p"))
@example(case=({"A": ("p",), "B": ("q",), "C": ()},  # the optimum (5 s) misses the lower bound of F[4,5] p (4 s)
               {("A", "B"): Fraction(2), ("B", "A"): Fraction(2), ("B", "C"): Fraction(3), ("C", "B"): Fraction(3),
                ("A", "C"): Fraction(4), ("C", "A"): Fraction(4)}),
         f=parse("G(p -> F[3,4] q) & F[4,5] p"))
@example(case=({"A": ("p", "q"), "B": ("p",), "C": (), "D": ()},  # the lasso enters at 2 s: its state recurs at 4 s
               {("A", "C"): Fraction(3), ("A", "D"): Fraction(1), ("B", "C"): Fraction(1), ("B", "D"): Fraction(1),
                ("C", "B"): Fraction(1), ("C", "D"): Fraction(1), ("D", "A"): Fraction(1), ("D", "B"): Fraction(3),
                ("D", "C"): Fraction(1)}),  # with the F[3,5] copy anchored at 0 s met and another anchored at 2 s
         f=parse("G(p -> F[3,5] q) & F[2,2] p"))
@settings(max_examples=max(20, settings().max_examples), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
def test_zone_search_agrees_with_the_explicit_searches(case: tuple[Labels, Weights], f: Formula) -> None:
    labels, weights = case
    wts = make_wts(labels, weights, initial="A")
    zone = _plan(wts, f)
    events = _plan(wts, f, zones=False)
    alone = _plan(wts, f, first_attempt=False)
    assert (zone is None) == (events is None) == (alone is None), (str(f), labels, weights, zone, events, alone)
    if zone is None or events is None or alone is None:
        return
    for run in (zone, events, alone):
        assert holds(f, run, labels), (str(f), run)
    assert _cost(zone) == _cost(events) == _cost(alone), (str(f), labels, weights, zone, events, alone)
    first = _plan(wts, f, optimal=False)  # the first stage's own run, not re-checked by the exact search
    assert first is not None and holds(f, first, labels), (str(f), first)
    assert _cost(first) >= _cost(zone), (str(f), first, zone)
