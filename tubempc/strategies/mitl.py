"""MITL formulas, intervals and atom names of bounded depth (every operator of the grammar)."""

from __future__ import annotations

from fractions import Fraction

from tubempc.mitl import (
    FALSE,
    TRUE,
    Always,
    And,
    Atom,
    Eventually,
    Formula,
    Implies,
    Interval,
    Next,
    Not,
    Or,
    Until,
)
from tubempc.strategies._common import st


def atom_names(pool: tuple[str, ...] = ("p", "q", "r", "obs_1", "mission_1")) -> st.SearchStrategy[str]:
    """Atomic proposition names drawn from ``pool``."""
    return st.sampled_from(pool)


@st.composite
def intervals(draw: st.DrawFn, max_s: int = 60, quantum: Fraction = Fraction(1, 2),
              allow_unbounded: bool = True) -> Interval:
    """Non-empty intervals with endpoints on a grid of ``quantum`` seconds, open or closed, maybe unbounded."""
    steps = int(max_s / quantum)
    lo = draw(st.integers(0, steps)) * quantum
    lo_closed = draw(st.booleans())
    if allow_unbounded and draw(st.integers(0, 3)) == 0:
        return Interval(lo, None, lo_closed, False)
    hi = lo + draw(st.integers(0, steps)) * quantum
    if hi == lo:
        return Interval(lo, hi, True, True)
    return Interval(lo, hi, lo_closed, draw(st.booleans()))


def formulas(atoms: st.SearchStrategy[str] | None = None, max_depth: int = 4,
             interval_strategy: st.SearchStrategy[Interval] | None = None,
             temporal: bool = True) -> st.SearchStrategy[Formula]:
    """MITL formulas of depth at most ``max_depth`` over ``atoms``, using every operator of the grammar."""
    names = atoms if atoms is not None else atom_names()
    ivs = interval_strategy if interval_strategy is not None else intervals()
    leaves: st.SearchStrategy[Formula] = st.one_of(names.map(Atom), st.sampled_from([TRUE, FALSE]))

    def extend(children: st.SearchStrategy[Formula]) -> st.SearchStrategy[Formula]:
        options: list[st.SearchStrategy[Formula]] = [
            children.map(Not),
            st.lists(children, min_size=2, max_size=3).map(lambda xs: And(tuple(xs))),
            st.lists(children, min_size=2, max_size=3).map(lambda xs: Or(tuple(xs))),
            st.builds(Implies, children, children),
        ]
        if temporal:
            options += [
                st.builds(Next, ivs, children),
                st.builds(Eventually, ivs, children),
                st.builds(Always, ivs, children),
                st.builds(Until, ivs, children, children),
            ]
        return st.one_of(options)

    return st.recursive(leaves, extend, max_leaves=2 ** max_depth)
