"""``verify.monitor.engine.explain`` walks from a false or undecided formula to the sub-formula and time that decide
it: an exact-zero value is undecided, never false; an undecided conjunction or disjunction names its undecided
argument; a false conjunction its earliest false conjunct (not an undecided one)."""

from __future__ import annotations

import numpy as np

from tubempc.mitl import parse
from verify.monitor.engine import Positions, Truth, evaluate_at_points, explain

S = 1_000_000_000


def _pos(n: int) -> Positions:
    """``n`` sample points 1 s apart (no gaps)."""
    t = np.arange(n, dtype=np.int64) * S
    return Positions(t, t.copy(), np.ones(n, dtype=bool), int(t[-1]))


def _truth(lo: list[float], hi: list[float]) -> Truth:
    return Truth(np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64))


TRUE4 = _truth([1.0] * 4, [1.0] * 4)


def test_an_exact_zero_or_a_positive_upper_bound_is_undecided_not_false() -> None:
    pos = _pos(4)
    for hi in (0.0, 0.5):
        atoms = {"p": _truth([-1.0, -1.0, -1.0, -1.0], [hi, hi, hi, hi])}
        values = evaluate_at_points(parse("p"), pos, atoms)
        e = explain(parse("p"), 0, pos, values)
        assert e.reason.startswith("unknown here"), (hi, e)


def test_a_false_conjunction_names_its_earliest_false_conjunct_not_an_undecided_one() -> None:
    pos = _pos(4)
    f = parse("p & G[0,3] q")
    for hi in (0.0, 0.5):  # p undecided at 0 (its upper bound is not below zero); q false at 2 s
        atoms = {"p": _truth([-1.0] * 4, [hi] * 4), "q": _truth([1.0, 1.0, -1.0, 1.0], [1.0, 1.0, -1.0, 1.0])}
        values = evaluate_at_points(f, pos, atoms)
        e = explain(f, 0, pos, values)
        assert (e.subformula, e.time_ns) == ("q", 2 * S), (hi, e)


def test_an_undecided_disjunction_names_its_undecided_argument() -> None:
    pos = _pos(4)
    f = parse("p | q")
    atoms = {"p": _truth([0.0] * 4, [1.0] * 4), "q": _truth([-1.0] * 4, [-1.0] * 4)}  # p: lower bound exactly 0
    values = evaluate_at_points(f, pos, atoms)
    e = explain(f, 0, pos, values)
    assert e.subformula == "p" and e.reason.startswith("unknown here"), e


def test_an_undecided_conjunction_names_its_undecided_argument_not_a_true_one() -> None:
    pos = _pos(4)
    f = parse("p & q")
    atoms = {"p": _truth([0.5] * 4, [1.0] * 4), "q": _truth([-1.0] * 4, [1.0] * 4)}  # p true (0.5), q unknown
    values = evaluate_at_points(f, pos, atoms)
    e = explain(f, 0, pos, values)
    assert e.subformula == "q" and e.reason.startswith("unknown here"), e
