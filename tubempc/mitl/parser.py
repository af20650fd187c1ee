"""MITL text -> formula AST (``parse``), built on a Lark LALR grammar.

Precedence, tightest first: unary operators (``!`` ``X`` ``F`` ``G`` with optional interval), ``U`` (right
associative), ``&``, ``|``, ``->`` (right associative). An absent interval means ``[0,inf)``.
Malformed text raises ``SpecSyntaxError`` (a ``ValueError``) naming the 1-based column and what was expected.

Limits (a formula beyond them is refused with ``SpecSyntaxError``, never a ``RecursionError``): at most
``MAX_FORMULA_CHARS`` characters, operators nested at most ``MAX_DEPTH`` deep (a chain ``a & b & c`` nests one
level per operator), interval bounds below ``10**MAX_BOUND_DIGITS`` seconds.
"""

from __future__ import annotations

import hashlib
import pprint
from fractions import Fraction
from functools import lru_cache
from typing import Any

import lark
from lark import Lark, Token, Transformer, Tree, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken, VisitError
from lark.grammar import Rule
from lark.lexer import TerminalDef

from tubempc.errors import SpecSyntaxError
from tubempc.mitl.ast import (
    FALSE,
    TRUE,
    UNBOUNDED,
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

__all__ = ["MAX_BOUND_DIGITS", "MAX_DEPTH", "MAX_FORMULA_CHARS", "parse"]

#: longest formula text accepted (characters)
MAX_FORMULA_CHARS = 20_000
#: deepest operator nesting accepted (the parser, the planner and the monitors recurse once per level)
MAX_DEPTH = 150
#: interval bounds have at most this many digits before the decimal point (and as many after it)
MAX_BOUND_DIGITS = 12

_GRAMMAR = r"""
?start: impl

?impl: disj
     | disj _implies impl           -> implies

?disj: conj
     | disj _or conj                -> or_

?conj: until
     | conj _and until              -> and_

?until: unary
      | unary _until interval? until -> until

?unary: atom
      | _not unary                  -> not_
      | _next interval? unary       -> next_
      | _eventually interval? unary -> eventually
      | _always interval? unary     -> always
      | LPAR impl RPAR              -> group

atom: NAME | QNAME | TRUE | FALSE

interval: (LSQB | LPAR) NUMBER COMMA (NUMBER | INF | INF_SYMBOL) (RSQB | RPAR)

_not: "!" | "not" | "¬"
_next: "X" | "next" | "○"
_eventually: "F" | "eventually" | "◇"
_always: "G" | "always" | "□"
_until: "U" | "until"
_and: "&&" | "&" | "and" | "∧"
_or: "||" | "|" | "or" | "∨"
_implies: "->" | "implies" | "→"
TRUE: "true"
FALSE: "false"
INF: "inf"
INF_SYMBOL: "∞"
LPAR: "("
RPAR: ")"
LSQB: "["
RSQB: "]"
COMMA: ","
NUMBER: /[0-9]+(\.[0-9]*)?|\.[0-9]+/
NAME: /[A-Za-z_][A-Za-z0-9_]*/
QNAME.2: /[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_]*/

%import common.WS
%ignore WS
"""

_HUMAN_NAMED = {
    "NAME": "an atomic proposition",
    "QNAME": "an atomic proposition",
    "NUMBER": "a number",
    "$END": "end of input",
}


# Error messages name each operator once, by its canonical spelling.
_CANONICAL = {
    alias: canon
    for canon, aliases in {
        "!": ("not", "¬"),
        "X": ("next", "○"),
        "F": ("eventually", "◇"),
        "G": ("always", "□"),
        "U": ("until",),
        "&": ("&&", "and", "∧"),
        "|": ("||", "or", "∨"),
        "->": ("implies", "→"),
    }.items()
    for alias in aliases
}

class _IntervalError(Exception):
    def __init__(self, message: str, column: int) -> None:
        super().__init__(message)
        self.message = message
        self.column = column


def _interval_of(children: list[Any]) -> Interval:
    return children[0] if children and isinstance(children[0], Interval) else UNBOUNDED


class _ToAst(Transformer[Token, Formula]):
    def atom(self, children: list[Token]) -> Formula:
        tok = children[0]
        if tok.type == "TRUE":
            return TRUE
        if tok.type == "FALSE":
            return FALSE
        return Atom(str(tok))

    def interval(self, c: list[Token]) -> Interval:
        lpar, lo_tok, _comma, hi_tok, rpar = c
        for tok in (lo_tok, hi_tok):
            if tok.type == "NUMBER" and any(len(part) > MAX_BOUND_DIGITS for part in str(tok).split(".")):
                raise _IntervalError(f"interval bound {str(tok)[:20]}... has more than {MAX_BOUND_DIGITS} digits "
                                     f"before or after the decimal point", tok.column or lpar.column or 1)
        lo = Fraction(str(lo_tok))
        hi = None if hi_tok.type in ("INF", "INF_SYMBOL") else Fraction(str(hi_tok))
        column = lpar.column or 1
        if hi is None and rpar.type == "RSQB":
            raise _IntervalError("an interval cannot be closed at inf: use ')'", rpar.column or column)
        if hi is not None and hi < lo:
            raise _IntervalError(f"interval lower bound {lo_tok} exceeds upper bound {hi_tok}", column)
        try:
            return Interval(lo, hi, lpar.type == "LSQB", rpar.type == "RSQB")
        except ValueError as err:
            raise _IntervalError(str(err), column) from err

    def not_(self, c: list[Any]) -> Formula:
        return Not(c[-1])

    def next_(self, c: list[Any]) -> Formula:
        return Next(_interval_of(c[:-1]), c[-1])

    def eventually(self, c: list[Any]) -> Formula:
        return Eventually(_interval_of(c[:-1]), c[-1])

    def always(self, c: list[Any]) -> Formula:
        return Always(_interval_of(c[:-1]), c[-1])

    def until(self, c: list[Any]) -> Formula:
        return Until(_interval_of(c[1:-1]), c[0], c[-1])

    def and_(self, c: list[Any]) -> Formula:
        return And((c[0], c[-1]))

    def or_(self, c: list[Any]) -> Formula:
        return Or((c[0], c[-1]))

    def implies(self, c: list[Any]) -> Formula:
        return Implies(c[0], c[-1])

    @v_args(inline=True)
    def group(self, _lpar: Token, inner: Formula, _rpar: Token) -> Formula:
        return inner


_LARK_OPTIONS: dict[str, Any] = {"parser": "lalr", "lexer": "basic", "maybe_placeholders": False}


def tables_key() -> str:
    """What the parse tables depend on: the grammar, the Lark options and Lark's version (sha256 hex)."""
    text = _GRAMMAR + repr(sorted(_LARK_OPTIONS.items())) + lark.__version__
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def tables_source() -> str:
    """The text of ``tubempc/mitl/_lalr_tables.py``: the LALR tables Lark builds from the grammar, serialised as
    Python literals (Lark's own ``memo_serialize``, the form its standalone generator embeds), keyed by
    ``tables_key()``. ``scripts/build_mitl_tables.py`` writes it; a test checks that the committed file's key is
    current and that the loaded parser parses and refuses exactly as a freshly built one does."""
    built = Lark(_GRAMMAR, **_LARK_OPTIONS)
    data, memo = built.memo_serialize([TerminalDef, Rule])
    return ('"""LALR tables of the MITL grammar (written by scripts/build_mitl_tables.py; do not edit).\n\n'
            "Building them takes about 0.25 s at every start; loading them about 0.01 s. ``parser._parser`` uses\n"
            "them only while ``KEY`` matches the grammar, the options and Lark's version; otherwise it builds the\n"
            'parser from the grammar.\n"""\n\n'
            "from typing import Any\n\n"
            f"KEY = {tables_key()!r}\n\n"
            f"DATA: dict[str, Any] = {pprint.pformat(data, width=120)}\n\n"
            f"MEMO: dict[int, Any] = {pprint.pformat(memo, width=120)}\n")


@lru_cache(maxsize=1)
def _parser() -> Lark:
    """The LALR parser: from the pre-built tables when they match the grammar and Lark, else built here."""
    try:
        from tubempc.mitl import _lalr_tables as tables  # generated; absent while it is being regenerated
    except ImportError:
        return Lark(_GRAMMAR, **_LARK_OPTIONS)
    if tables_key() != tables.KEY:
        return Lark(_GRAMMAR, **_LARK_OPTIONS)
    loaded: Lark = Lark._load_from_dict(tables.DATA, tables.MEMO)  # type: ignore[no-untyped-call]
    return loaded


@lru_cache(maxsize=1)
def _human_names() -> dict[str, str]:
    out = dict(_HUMAN_NAMED)
    for term in _parser().terminals:
        if term.name not in out and term.pattern.type == "str":
            value = str(term.pattern.value)
            out[term.name] = repr(_CANONICAL.get(value, value))
    out["INF_SYMBOL"] = "'inf'"
    return out


def _expected(names: set[str] | frozenset[str]) -> str:
    human_of = _human_names()
    human = sorted({human_of.get(n, n) for n in names})
    if not human:
        return "nothing more"
    if len(human) == 1:
        return human[0]
    return "one of " + ", ".join(human)


def _acceptable_after(prefix: str) -> set[str]:
    """Terminals the grammar accepts after ``prefix`` (used when the lexer meets a character no token starts)."""
    try:
        interactive = _parser().parse_interactive(prefix)
        interactive.exhaust_lexer()
        accepted: set[str] = interactive.accepts()  # type: ignore[no-untyped-call]
        return accepted
    except UnexpectedInput:
        return set()


@lru_cache(maxsize=4096)
def parse(text: str) -> Formula:
    """Parse MITL ``text`` into a formula; raise ``SpecSyntaxError`` (a ``ValueError``) when malformed."""
    if not isinstance(text, str):
        raise TypeError(f"text={text!r} is not a string")
    if not text.strip():
        raise SpecSyntaxError("empty formula: expected an atomic proposition, 'true', 'false' or an operator",
                              text=text, column=1)
    if len(text) > MAX_FORMULA_CHARS:
        raise SpecSyntaxError(f"formula of {len(text)} characters: at most {MAX_FORMULA_CHARS} are accepted",
                              text=text, column=MAX_FORMULA_CHARS + 1)
    try:
        tree = _parser().parse(text)
        depth, column = _depth(tree)
        if depth > MAX_DEPTH:
            raise SpecSyntaxError(f"operators nested {depth} deep: at most {MAX_DEPTH} levels are accepted",
                                  text=text, column=column)
        return _ToAst().transform(tree)
    except UnexpectedEOF as err:
        raise SpecSyntaxError(f"unexpected end of input, expected {_expected(set(err.expected))}",
                              text=text, column=len(text) + 1) from None
    except UnexpectedToken as err:
        got = "end of input" if err.token.type == "$END" else repr(str(err.token))
        column = len(text) + 1 if err.token.type == "$END" else int(err.column)
        raise SpecSyntaxError(f"unexpected {got}, expected {_expected(err.expected)}",
                              text=text, column=column) from None
    except UnexpectedCharacters as err:
        pos = int(err.pos_in_stream or 0)
        allowed = _acceptable_after(text[:pos])
        raise SpecSyntaxError(f"unexpected character {text[pos]!r}, expected {_expected(allowed)}",
                              text=text, column=int(err.column)) from None
    except UnexpectedInput as err:  # pragma: no cover - other Lark input errors
        raise SpecSyntaxError(str(err).splitlines()[0], text=text, column=int(getattr(err, "column", 1))) from None
    except VisitError as err:
        orig = err.orig_exc
        if isinstance(orig, _IntervalError):
            raise SpecSyntaxError(orig.message, text=text, column=orig.column) from None
        raise SpecSyntaxError(f"cannot build the formula ({orig.__class__.__name__}: {orig})", text=text,
                              column=1) from None
    except RecursionError:
        raise SpecSyntaxError(f"formula nested too deeply (at most {MAX_DEPTH} levels are accepted)", text=text,
                              column=1) from None


def _depth(tree: Tree[Token]) -> tuple[int, int]:
    """Operator nesting depth of a parse tree (iterative: no recursion), and the column where it is reached."""
    deepest, column = 0, 1
    stack: list[tuple[Tree[Token] | Token, int]] = [(tree, 0)]
    while stack:
        node, level = stack.pop()
        if isinstance(node, Tree):
            here = level + (0 if node.data in ("start", "group", "interval", "atom") else 1)
            if here > deepest:
                deepest = here
                column = next((c.column or 1 for c in node.children if isinstance(c, Token)), column)
            stack.extend((child, here) for child in node.children)
    return deepest, column
