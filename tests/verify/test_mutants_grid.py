"""Tests written against mutants of the regular-grid monitor (``verify.monitor.grid``, ``verify.monitor.gridwindows``).

Each one failed on a mutant that the rest of the kill suite let live (docs/property-testing.md, "Mutation testing").
The sweeps compare with the general engine (``verify.monitor.engine`` on the interleaved samples and gaps) on every
window a few-nanosecond interval can cut out of a small grid, with a distinct value at every sample and gap, so that a
window one position too wide or too narrow changes a min or max somewhere.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from fractions import Fraction
from itertools import product

import numpy as np
import pytest

from tests.verify.positions import engine_on_grid as _engine
from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Interval, Next, Not, Or, parse
from verify.monitor.grid import Grid, UnsupportedFormulaError, evaluate_grid, evaluate_root, regular_grid

NS = Fraction(1, 10**9)
P, Q = Atom("p"), Atom("q")
# dt = 3 ns, span 9 ns: a window of a few ns starts and ends at a sample, inside a gap, or past the end
GRID = Grid(0, 3, 4)
# no two samples or gap bounds alike (the gap bounds are (m_i + m_i+1) / 2 -+ step / 2)
MARGINS = {"p": np.array([0.5, -1.0, 2.0, -0.25]), "q": np.array([-0.75, 1.25, 0.25, 1.0])}
STEP = np.array([0.3, 0.7, 0.1])




def _same(got: np.ndarray, want: np.ndarray, what: str, g: Formula, f: Formula) -> None:
    # np.array_equal, not assert_array_equal, and the message formatted only on a failure: the sweeps make thousands
    # of comparisons (NaN equals NaN, as in assert_array_equal)
    if not np.array_equal(got, want, equal_nan=True):
        raise AssertionError(f"{what} of {g} in {f}: {got} != {want}")


def _agree(f: Formula, grid: Grid = GRID, margins: dict[str, np.ndarray] | None = None,
           step: np.ndarray = STEP) -> None:
    """``evaluate_root`` and ``evaluate_grid`` (every sub-formula, samples and gaps) equal the general engine."""
    margins = MARGINS if margins is None else margins
    want, point_at, gap_at = _engine(f, grid, margins, step)
    root = evaluate_root(f, grid, margins, step)
    _same(root.lo, want[f].lo[point_at], "root lo", f, f)
    _same(np.array(root.hi_first), want[f].hi[point_at[0]], "root hi", f, f)
    res = evaluate_grid(f, grid, margins, step)
    _same(res.root.p_lo, want[f].lo[point_at], "grid lo", f, f)
    _same(res.root.p_hi, want[f].hi[point_at], "grid hi", f, f)
    for g, v in res.values().items():
        w = want[g]
        _same(v.p_lo, w.lo[point_at], "lo", g, f)
        _same(v.p_hi, w.hi[point_at], "hi", g, f)
        if v.g_lo is not None and v.g_hi is not None:
            _same(v.g_lo, w.lo[gap_at], "gap lo", g, f)
            _same(v.g_hi, w.hi[gap_at], "gap hi", g, f)


def _ns(lo: int, hi: int | None, lo_closed: bool = True, hi_closed: bool = True) -> Interval:
    """The interval between ``lo`` and ``hi`` nanoseconds (hi None: unbounded, open)."""
    return Interval(lo * NS, None if hi is None else hi * NS, lo_closed, hi_closed and hi is not None)


def _intervals(max_lo: int = 7, max_width: int = 8) -> Iterator[Interval]:
    """Every interval with integer-ns ends up to the given offsets: closed, open, half-open, a point, unbounded."""
    for lo in range(max_lo + 1):
        yield _ns(lo, None)
        yield _ns(lo, None, False)
        yield _ns(lo, lo)
        for width in range(1, max_width + 1):
            for lo_closed, hi_closed in itertools.product((True, False), repeat=2):
                yield _ns(lo, lo + width, lo_closed, hi_closed)


_TEMPORAL: tuple[type[Eventually] | type[Always], ...] = (Eventually, Always)
_WRAPS: tuple[Callable[[Formula], Formula], ...] = (lambda g: g, Not)


def test_root_bounds_of_a_window_over_an_atom_equal_the_engine() -> None:
    """``F_I p``, ``G_I p`` and their negations (the root's upper bound at the first sample is then the lower bound
    of the window) for every interval."""
    for iv in _intervals():
        for op in _TEMPORAL:
            for wrap in _WRAPS:
                _agree(wrap(op(iv, P)))


#: windows that start and end at samples or inside gaps, a point, an empty one on integer ns, unbounded ones, one past
#: the end from the first sample on (9 ns is the last sample)
_SOME = (_ns(0, 0), _ns(0, 2, True, False), _ns(1, 4, False, True), _ns(2, 7, True, False), _ns(3, 3),
         _ns(1, 2, False, False), _ns(0, None), _ns(4, None, False), _ns(5, 12), _ns(0, 30))
#: sub-formulas whose lower and upper bounds differ (a window past the end, a Next at the last sample), with explicit
#: gap values (temporal, Next) or centred ones (negation, and/or/implication of atoms)
_INNER: tuple[Formula, ...] = (Eventually(_ns(0, 4), Q), Always(_ns(1, 5, False, True), Q),
                               Next(_ns(0, 3), Eventually(_ns(0, 6), Q)), Not(Q), And((P, Q)), Or((P, Not(Q))),
                               Implies(Q, P))
#: the formula around a window: each bound of the root reaches the window's lower or upper bound through negation,
#: implication, and/or, a Next, or a sub-formula also needed at the gaps
_ROOTS: tuple[Callable[[Formula], Formula], ...] = (
    lambda t: t, Not, lambda t: Implies(t, P), lambda t: Implies(Q, t), lambda t: And((t, Q)),
    lambda t: Or((t, Not(Q))), lambda t: Not(And((P, t, Q))), lambda t: Not(Or((t, P))), lambda t: Not(Implies(P, t)),
    lambda t: Not(Next(_ns(0, 3), t)), lambda t: And((Always(_ns(0, 3), t), Not(t))))


def test_root_bounds_of_formulas_around_windows_equal_the_engine() -> None:
    for iv, inner, op, root in product(_SOME, _INNER, _TEMPORAL, _ROOTS):
        _agree(root(op(iv, inner)))


#: sub-formulas below a window whose gap values are explicit: a negated window, an and/or of windows and Nexts
#: (explicit only), an and/or of an atom and a window (centred and explicit mixed)
_EXPLICIT: tuple[Formula, ...] = (Not(Eventually(_ns(0, 4), Q)), Not(Next(_ns(0, 3), Q)),
                                  And((Eventually(_ns(0, 4), Q), Next(_ns(0, 3), P))),
                                  Or((Always(_ns(1, 5, False, True), P), Not(Eventually(_ns(0, 2), Q)))),
                                  And((P, Eventually(_ns(0, 4), Q))), Implies(Always(_ns(0, 2), Q), P))


def test_windows_over_explicit_gap_values_equal_the_engine() -> None:
    for iv, inner, op, wrap in product(_SOME, _EXPLICIT, _TEMPORAL, _WRAPS):
        _agree(wrap(op(iv, inner)))


def test_a_value_whose_gap_bounds_were_half_computed_negates_as_the_engine() -> None:
    """``p`` is first needed for its gaps' upper bound only (under the negated F), then negated below G: the
    negation reads the mid-points, not the half-filled cache."""
    for iv in _SOME:
        _agree(And((Not(Eventually(iv, P)), Always(_ns(0, 3), Not(P)))))
        _agree(And((Eventually(iv, P), Always(_ns(0, 3), Not(P)))))


def test_a_grid_needs_two_samples_and_an_instant_between_them() -> None:
    for dt_ns, n in ((1, 5), (5, 1), (0, 0)):
        with pytest.raises(ValueError, match=rf"^a grid needs dt_ns >= 2 and n >= 2, got dt_ns={dt_ns}, n={n}$"):
            Grid(0, dt_ns, n)


def test_regular_grid_of_two_samples_a_late_start_and_the_shortest_period() -> None:
    assert regular_grid(np.array([0, 10], dtype=np.int64)) == Grid(0, 10, 2)
    assert regular_grid(np.array([5, 15, 25], dtype=np.int64)) == Grid(5, 10, 3)
    assert regular_grid(np.array([7, 9, 11, 13], dtype=np.int64)) == Grid(7, 2, 4)
    assert regular_grid(np.array([5, 15, 26], dtype=np.int64)) is None


def test_grid_refusals_name_what_is_wrong() -> None:
    grid, ones = Grid(0, 10, 3), np.ones(3)
    with pytest.raises(ValueError, match=r"^step_m has shape \(3,\), expected \(2,\)$"):
        evaluate_grid(parse("p"), grid, {"p": ones}, np.ones(3))
    with pytest.raises(KeyError, match=r"atom='r' has no valuation"):
        evaluate_grid(parse("p & r"), grid, {"p": ones}, np.ones(2))
    with pytest.raises(UnsupportedFormulaError, match=r"^p U\[0,1\] q \(until\) is evaluated by the general engine$"):
        evaluate_grid(parse("p U[0,1] q"), grid, {"p": ones, "q": ones}, np.ones(2))
    with pytest.raises(TypeError, match=r"^unknown formula node 'p'$"):
        evaluate_grid("p", grid, {"p": ones}, np.ones(2))  # type: ignore[arg-type]


def test_sub_formulas_needed_at_the_samples_only_have_no_gap_values() -> None:
    """``SplitTruth``: gap values only for what a window reads (here ``q`` and ``true`` under F, not ``p``, ``false``
    or the root's conjunction)."""
    values = evaluate_grid(parse("(p | false) & F[0,1] (q & true)"), GRID, MARGINS, STEP).values()
    samples_only: tuple[Formula, ...] = (P, Const(False), Or((P, Const(False))))
    with_gaps: tuple[Formula, ...] = (Q, Const(True), And((Q, Const(True))))
    for g in samples_only:
        assert values[g].g_lo is None and values[g].g_hi is None, g
    for g in with_gaps:
        assert values[g].g_lo is not None and values[g].g_hi is not None, g
