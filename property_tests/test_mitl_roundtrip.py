"""Round trip of the MITL language over random formulas: parse(str(f)) == f, and text is canonical."""

from __future__ import annotations

from hypothesis import given

from tubempc import strategies
from tubempc.mitl import Formula, parse


@given(strategies.formulas(max_depth=4))
def test_parse_str_round_trip(f: Formula) -> None:
    text = str(f)
    g = parse(text)
    assert g == f
    assert hash(g) == hash(f)
    assert str(g) == text


@given(strategies.formulas(max_depth=3))
def test_text_with_extra_spaces_and_parentheses_parses_equal(f: Formula) -> None:
    assert parse(f"( {f} )") == f


@given(strategies.formulas(strategies.atom_names(("husky.dock", "a.p", "jackal.slow", "close_ab", "p")), max_depth=4))
def test_qualified_atoms_round_trip(f: Formula) -> None:
    """A robot's own atoms (``husky.dock``, several robots in one log) print and parse back unchanged."""
    assert parse(str(f)) == f
    assert str(parse(str(f))) == str(f)
