"""Difference-bound matrices and the zone search: each operation against enumerated integer valuations, and the
observed-dwell formula of the built-in scenario decided by the zone search alone."""

from __future__ import annotations

import itertools
from fractions import Fraction

import pytest

from tubempc.mitl import parse
from tubempc.planning import holds
from tubempc.planning.automaton import compile_formula, tick_of
from tubempc.planning.zones import INF, Dbm, close, constrain, delay, extrapolate, included, up_t, zone_search

RANGE = range(9)


def zone(bounds: dict[tuple[int, int], int], n: int = 3) -> Dbm:
    d = [[0 if i == j else INF for j in range(n)] for i in range(n)]
    for (i, j), c in bounds.items():
        d[i][j] = c
    assert close(d)
    return d


def points(d: Dbm) -> set[tuple[int, ...]]:
    n = len(d)
    out = set()
    for v in itertools.product(RANGE, repeat=n - 1):
        x = (0, *v)
        if all(x[i] - x[j] <= d[i][j] for i in range(n) for j in range(n) if d[i][j] < INF):
            out.add(v)
    return out


# x1 in [1, 3], x2 in [0, 2], x1 - x2 >= 1
Z = {(1, 0): 3, (0, 1): -1, (2, 0): 2, (0, 2): 0, (2, 1): -1}


@pytest.mark.parametrize(("lo", "hi"), [(1, 1), (2, 4), (1, INF), (0, 0)])
def test_delay_is_exact(lo: int, hi: int) -> None:
    d = zone(Z)
    later = delay(d, lo, hi)
    expect = {(a + k, b + k) for a, b in points(d) for k in range(lo, (hi if hi < INF else 8) + 1)}
    expect = {v for v in expect if all(c in RANGE for c in v)}
    assert points(later) == expect
    # canonical: closing again changes nothing
    again = [row[:] for row in later]
    close(again)
    assert again == later


def test_constrain_keeps_the_zone_canonical_and_detects_emptiness() -> None:
    d = zone(Z)
    assert constrain(d, 1, 0, 2)  # x1 <= 2
    assert points(d) == {v for v in points(zone(Z)) if v[0] <= 2}
    again = [row[:] for row in d]
    close(again)
    assert again == d
    assert not constrain(d, 0, 1, -3)  # x1 >= 3: empty


def test_up_t_lets_the_global_time_grow_and_inclusion_compares_zones() -> None:
    d = zone(Z)
    grown = up_t(d)  # clock 1 plays the global time here
    assert points(grown) == {(a + k, b) for a, b in points(d) for k in range(9) if a + k in RANGE}
    assert included(d, grown) and not included(grown, d)


def test_extrapolation_only_merges_ages_above_the_constant() -> None:
    d = zone({(0, 1): -5, (1, 0): 7, (0, 2): 0, (2, 0): 1})  # x1 in [5, 7], x2 in [0, 1]
    extrapolate(d, [0, 3, 8])  # x1 alike above 3: its bounds become x1 >= 4; x2 kept
    assert d[0][1] == -4 and d[1][0] == INF and d[2][0] == 1


# the built-in scenario's transition times (seconds), mission_1 in R1, mission_2 in R3
NEXUS = {
    ("R1", "R2"): "19.9", ("R1", "R3"): "16.7", ("R1", "R4"): "30.7", ("R1", "R5"): "22.5",
    ("R2", "R3"): "13", ("R2", "R4"): "37.2", ("R2", "R5"): "32.5", ("R3", "R4"): "13.4",
    ("R3", "R5"): "14.9", ("R4", "R5"): "21.1"}


def test_zone_search_alone_decides_the_observed_response_formula() -> None:
    # G(mission_1 -> F[10,20] mission_2) & F[50,60] mission_1 with observed dwells: every dwell position in R1
    # anchors a copy of F[10,20] that cannot be merged before its window opens, one per tick for the explicit
    # product (tick 0.05 s); a dwell of any length is one symbolic step here
    labels = {"R1": ("mission_1",), "R2": (), "R3": ("mission_2",), "R4": (), "R5": ()}
    names = sorted(labels)
    weights = {**{k: Fraction(v) for k, v in NEXUS.items()}, **{(b, a): Fraction(v) for (a, b), v in NEXUS.items()}}
    f = parse("G(mission_1 -> F[10,20] mission_2) & F[50,60] mission_1")
    tick = tick_of([*weights.values(), Fraction(10), Fraction(20), Fraction(50), Fraction(60)], refine=2)
    aut = compile_formula(f, tick)
    cls = [aut.label_class(labels[n]) for n in names]
    adj = [[(names.index(b), int(w / tick)) for (a, b), w in weights.items() if a == n] for n in names]
    found, created = zone_search(aut, names, cls, adj, 0)
    assert found is not None and created < 200
    run = found[0]
    assert holds(f, run, labels)
    assert run.loop_start is not None and run.times[run.loop_start] == 50  # the optimum (the window's lower end)
    assert ("R3", Fraction(333, 10)) in set(zip(run.regions, run.times, strict=True))  # the aimed dwell
