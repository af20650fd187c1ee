"""Parser tests: every form of the grammar, precedence, round trips and malformed inputs with their messages."""

from __future__ import annotations

from fractions import Fraction

import pytest

from tubempc.errors import SpecSyntaxError
from tubempc.mitl import (
    FALSE,
    TRUE,
    UNBOUNDED,
    Always,
    And,
    Atom,
    Eventually,
    Implies,
    Interval,
    Next,
    Not,
    Or,
    Until,
    atoms,
    parse,
)

a, b, c = Atom("a"), Atom("b"), Atom("c")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("a", a),
        ("true", TRUE),
        ("false", FALSE),
        ("(a)", a),
        ("((a))", a),
        ("!a", Not(a)),
        ("not a", Not(a)),
        ("¬a", Not(a)),
        ("X a", Next(UNBOUNDED, a)),
        ("next a", Next(UNBOUNDED, a)),
        ("○ a", Next(UNBOUNDED, a)),
        ("X[1,2] a", Next(Interval(1, 2, True, True), a)),
        ("F a", Eventually(UNBOUNDED, a)),
        ("eventually a", Eventually(UNBOUNDED, a)),
        ("◇a", Eventually(UNBOUNDED, a)),
        ("G a", Always(UNBOUNDED, a)),
        ("always a", Always(UNBOUNDED, a)),
        ("□a", Always(UNBOUNDED, a)),
        ("a U b", Until(UNBOUNDED, a, b)),
        ("a until b", Until(UNBOUNDED, a, b)),
        ("a U(0.5,3] b", Until(Interval(Fraction(1, 2), 3, False, True), a, b)),
        ("a & b", And((a, b))),
        ("a and b", And((a, b))),
        ("a ∧ b", And((a, b))),
        ("a | b", Or((a, b))),
        ("a or b", Or((a, b))),
        ("a ∨ b", Or((a, b))),
        ("a -> b", Implies(a, b)),
        ("a implies b", Implies(a, b)),
        ("a → b", Implies(a, b)),
        ("F[30,50] a", Eventually(Interval(30, 50, True, True), a)),
        ("F(30,50) a", Eventually(Interval(30, 50, False, False), a)),
        ("F[30,50) a", Eventually(Interval(30, 50, True, False), a)),
        ("F(30,50] a", Eventually(Interval(30, 50, False, True), a)),
        ("G[0,inf) a", Always(UNBOUNDED, a)),
        ("G[0,∞) a", Always(UNBOUNDED, a)),
        ("G(2,inf) a", Always(Interval(2, None, False, False), a)),
        ("F[3,3] a", Eventually(Interval(3, 3, True, True), a)),
        ("F[17.3,20.1] a", Eventually(Interval(Fraction("17.3"), Fraction("20.1"), True, True), a)),
        ("F[.5,1.] a", Eventually(Interval(Fraction(1, 2), 1, True, True), a)),
    ],
)
def test_every_form(text: str, expected: object) -> None:
    assert parse(text) == expected


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        # unary binds tighter than everything
        ("G[0,inf) !(obs_1 | obs_2) & F[30,50] m",
         And((Always(UNBOUNDED, Not(Or((Atom("obs_1"), Atom("obs_2"))))),
              Eventually(Interval(30, 50, True, True), Atom("m"))))),
        ("!a & b", And((Not(a), b))),
        ("F a U b", Until(UNBOUNDED, Eventually(UNBOUNDED, a), b)),
        # U is right-associative and tighter than &
        ("a U b U c", Until(UNBOUNDED, a, Until(UNBOUNDED, b, c))),
        ("a & b U c", And((a, Until(UNBOUNDED, b, c)))),
        # & tighter than |, | tighter than ->
        ("a | b & c", Or((a, And((b, c))))),
        ("a & b | c", Or((And((a, b)), c))),
        ("a | b -> c", Implies(Or((a, b)), c)),
        # -> is right-associative
        ("a -> b -> c", Implies(a, Implies(b, c))),
        ("(a -> b) -> c", Implies(Implies(a, b), c)),
        # & and | are associative: flattened
        ("a & b & c", And((a, b, c))),
        ("(a & b) & c", And((a, b, c))),
        ("a & (b & c)", And((a, b, c))),
        ("a | (b | c)", Or((a, b, c))),
        # keywords are whole words only
        ("note & Gate & Untilx & Fx", And((Atom("note"), Atom("Gate"), Atom("Untilx"), Atom("Fx")))),
    ],
)
def test_precedence(text: str, expected: object) -> None:
    assert parse(text) == expected


@pytest.mark.parametrize(
    "text",
    [
        "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[30,50] mission_2 & F[80,110] mission_1",
        "a U[0,5] b U c",
        "!(a & b) -> (c | F(1,2] a)",
        "G(a -> F[0,60] b)",
        "X X X a",
        "(a U b) U c",
        "F (G a)",
        "!!a",
        "true -> false",
        "G[0,inf) (a -> F[2,inf) b)",
    ],
)
def test_round_trip_examples(text: str) -> None:
    f = parse(text)
    assert parse(str(f)) == f
    assert str(parse(str(f))) == str(f)
    assert hash(parse(text)) == hash(f)


def test_canonical_text_of_paper_formula() -> None:
    f = parse("G[0,inf)!(obs_1|obs_2|obs_3|obs_4)&F[30,50]mission_2&F[80,110]mission_1")
    assert str(f) == "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[30,50] mission_2 & F[80,110] mission_1"
    assert atoms(f) == {"obs_1", "obs_2", "obs_3", "obs_4", "mission_1", "mission_2"}


@pytest.mark.parametrize(
    ("text", "column", "fragment"),
    [
        ("", 1, "empty formula"),
        ("   ", 1, "empty formula"),
        ("a &", 4, "unexpected end of input, expected one of '!', '('"),
        ("a b", 3, "unexpected 'b', expected one of '&'"),
        ("(a", 3, "unexpected end of input, expected ')'"),
        ("a)", 2, "unexpected ')'"),
        ("F[5,2] a", 2, "lower bound 5 exceeds upper bound 2"),
        ("F[1,inf] a", 8, "cannot be closed at inf"),
        ("F[1,1) a", 2, "is empty"),
        ("F(1,1] a", 2, "is empty"),
        ("F[-1,2] a", 3, "unexpected character '-', expected a number"),
        ("F[1,2 a", 7, "expected one of ')', ']'"),
        ("F[1;2] a", 4, "unexpected character ';'"),
        ("a $ b", 3, "unexpected character '$'"),
        ("U a", 1, "unexpected 'U'"),
        ("F[1,2]", 7, "unexpected end of input"),
        ("G inf", 3, "unexpected 'inf'"),
        ("a -> ", 6, "unexpected end of input"),
        ("F[a,2] b", 3, "expected a number"),
    ],
)
def test_malformed(text: str, column: int, fragment: str) -> None:
    with pytest.raises(SpecSyntaxError) as info:
        parse(text)
    assert isinstance(info.value, ValueError)
    assert info.value.column == column, str(info.value)
    assert fragment in str(info.value)
    assert f"column {column}" in str(info.value)


def test_interval_semantics() -> None:
    iv = Interval(30, 50, True, False)
    assert iv.contains(30) and iv.contains(Fraction("49.99")) and not iv.contains(50)
    assert not Interval(30, 50, False, True).contains(30)
    assert UNBOUNDED.contains(10**9) and not UNBOUNDED.bounded
    with pytest.raises(ValueError, match="negative"):
        Interval(-1, 2)
    with pytest.raises(ValueError, match="empty"):
        Interval(2, 2, True, False)
    assert str(Interval(Fraction("0.25"), None, False)) == "(0.25,inf)"


def test_reserved_words_are_not_atoms() -> None:
    with pytest.raises(ValueError, match="reserved"):
        Atom("U")
    with pytest.raises(ValueError, match="not an atomic proposition"):
        Atom("1a")


_TABLE_CORPUS = ("a", "!a & b | c -> d", "G(a -> F[0,5] b)", "a U[1,2) b U c", "X[0,1] □◇ a", "(a", "a &", "a b",
                 "F[1,2 a", "a $ b", "U a", "G inf", "F[-1,2] a", "a ∧ b ∨ ¬c → d", "F[.5,∞) a",
                 "G !(a.door & b.door)", "a.b.c", "a.")


def _tree_or_error(parser: object, text: str) -> object:
    from lark.exceptions import UnexpectedInput

    try:
        return parser.parse(text)  # type: ignore[attr-defined]  # Trees compare by rule name and children
    except UnexpectedInput as err:
        return f"{type(err).__name__} at {err.column}: {sorted(getattr(err, 'expected', ()) or ())}"


def test_committed_tables_match_the_grammar_and_lark() -> None:
    """The pre-built LALR tables are current (else: ``python3 scripts/build_mitl_tables.py``) and the parser loaded
    from them accepts, builds and refuses exactly as one built from the grammar."""
    from lark import Lark

    from tubempc.mitl import _lalr_tables
    from tubempc.mitl.parser import _GRAMMAR, _LARK_OPTIONS, _parser, tables_key

    assert tables_key() == _lalr_tables.KEY
    built = Lark(_GRAMMAR, **_LARK_OPTIONS)
    for text in _TABLE_CORPUS:
        assert _tree_or_error(_parser(), text) == _tree_or_error(built, text), text


def test_parser_loads_tables_instead_of_building_the_grammar(monkeypatch: pytest.MonkeyPatch) -> None:
    """Starting the parser compiles no grammar (that took about 0.25 s of every ``certify``); with stale tables it
    builds from the grammar and parses the same."""
    import lark.lark

    from tubempc.mitl import parser as mod

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the grammar was compiled")

    mod._parser.cache_clear()
    monkeypatch.setattr(lark.lark, "load_grammar", refuse)
    try:
        assert mod._parser().parse("G(a -> F[0,5] b)") is not None
        mod._parser.cache_clear()
        monkeypatch.setattr(mod, "tables_key", lambda: "stale")
        with pytest.raises(AssertionError, match="grammar was compiled"):
            mod._parser()
        monkeypatch.undo()
        mod._parser.cache_clear()
        monkeypatch.setattr(mod, "tables_key", lambda: "stale")
        assert repr(mod._parser().parse("G(a -> F[0,5] b)")).startswith("Tree('always'")
    finally:
        mod._parser.cache_clear()


# ---- qualified atoms (a robot's own atom in a multi-robot scenario: ``husky.dock``) ----------------------------
@pytest.mark.parametrize("text", ["G (husky.dock -> F[0,5] jackal.stopped)", "G !(a.door & b.door)",
                                  "husky.dock U[0,3] close_ab", "F[0,60] (a.dock & b.dock)"])
def test_qualified_atoms_parse_and_round_trip(text: str) -> None:
    f = parse(text)
    assert parse(str(f)) == f
    qualified = {a for a in atoms(f) if "." in a}
    assert qualified and all(Atom(a).qualifier and Atom(a).local_name for a in qualified)


def test_qualified_atom_parts() -> None:
    a = Atom("husky.dock")
    assert (a.qualifier, a.local_name, str(a)) == ("husky", "dock", "husky.dock")
    assert (Atom("dock").qualifier, Atom("dock").local_name) == (None, "dock")


@pytest.mark.parametrize("text", ["a.b.c", "a.", ".a", "a.F", "G.x", "a . b"])
def test_malformed_qualified_atoms_are_refused(text: str) -> None:
    with pytest.raises(SpecSyntaxError):
        parse(text)
