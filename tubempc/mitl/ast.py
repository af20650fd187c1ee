"""MITL abstract syntax: frozen, hashable formula values and canonical text.

input: constructor arguments (or the parser's output) -> output: immutable formula trees whose ``str`` is the
canonical text; ``parse(str(f)) == f`` for every formula ``f``.

Interval endpoints are exact ``fractions.Fraction`` seconds (never floats: planners add them up exactly).
``And``/``Or`` are n-ary and flattened, so ``(a & b) & c`` and ``a & (b & c)`` are the same value.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from decimal import Decimal
from fractions import Fraction
from typing import TypeAlias

__all__ = [
    "FALSE",
    "TRUE",
    "UNBOUNDED",
    "Always",
    "And",
    "Atom",
    "Const",
    "Eventually",
    "Formula",
    "Implies",
    "Interval",
    "Next",
    "Not",
    "Or",
    "Until",
    "atoms",
    "format_seconds",
    "subformulas",
    "to_fraction",
]


def to_fraction(value: object, *, name: str = "value") -> Fraction:
    """Exact rational from int, Fraction, Decimal, decimal string or float (floats via their shortest repr)."""
    if isinstance(value, bool):
        raise TypeError(f"{name}={value!r} is not a number")
    if isinstance(value, Fraction):
        return value
    if isinstance(value, int):
        return Fraction(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{name}={value!r} is not a finite number")
        return Fraction(repr(value))
    if isinstance(value, Decimal | str):
        try:
            return Fraction(value)
        except (ValueError, ArithmeticError) as err:
            raise ValueError(f"{name}={value!r} is not a number") from err
    raise TypeError(f"{name}={value!r} is not a number")


def format_seconds(value: Fraction) -> str:
    """Exact decimal text of a rational with a terminating expansion (``Fraction(173, 10)`` -> ``'17.3'``)."""
    den = value.denominator
    twos = fives = 0
    while den % 2 == 0:
        den //= 2
        twos += 1
    while den % 5 == 0:
        den //= 5
        fives += 1
    if den != 1:
        raise ValueError(f"value={value} has no finite decimal expansion")
    digits = max(twos, fives)
    return f"{Decimal(value.numerator) / Decimal(value.denominator):.{digits}f}" if digits else str(value.numerator)


@dataclass(frozen=True, slots=True)
class Interval:
    """A time interval in seconds. ``hi is None`` means unbounded (``inf``, always open)."""

    lo: Fraction = Fraction(0)
    hi: Fraction | None = None
    lo_closed: bool = True
    hi_closed: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "lo", to_fraction(self.lo, name="lo"))
        if self.hi is not None:
            object.__setattr__(self, "hi", to_fraction(self.hi, name="hi"))
        if self.lo < 0:
            raise ValueError(f"interval lower bound lo={format_seconds(self.lo)} is negative")
        if self.hi is None:
            if self.hi_closed:
                raise ValueError("an unbounded interval cannot be closed at inf")
        else:
            if self.hi < self.lo:
                raise ValueError(
                    f"interval bounds lo={format_seconds(self.lo)} > hi={format_seconds(self.hi)}"
                )
            if self.hi == self.lo and not (self.lo_closed and self.hi_closed):
                raise ValueError(f"interval {self} is empty")
        format_seconds(self.lo)
        if self.hi is not None:
            format_seconds(self.hi)

    @property
    def bounded(self) -> bool:
        return self.hi is not None

    @property
    def lo_s(self) -> float:
        return float(self.lo)

    @property
    def hi_s(self) -> float:
        return float("inf") if self.hi is None else float(self.hi)

    def contains(self, t: Fraction | float | int) -> bool:
        """Whether the duration ``t`` (seconds) lies in the interval."""
        if t < self.lo or (t == self.lo and not self.lo_closed):
            return False
        if self.hi is None:
            return True
        return t < self.hi or (t == self.hi and self.hi_closed)

    def __str__(self) -> str:
        left = "[" if self.lo_closed else "("
        hi = "inf" if self.hi is None else format_seconds(self.hi)
        right = "]" if self.hi_closed else ")"
        return f"{left}{format_seconds(self.lo)},{hi}{right}"


UNBOUNDED = Interval()

_RESERVED = frozenset(
    {"X", "F", "G", "U", "true", "false", "inf", "not", "next", "eventually", "always", "until", "and", "or",
     "implies"}
)

# Binding strength, tightest first: unary > U > & > | > ->.
_PREC_IMPLIES, _PREC_OR, _PREC_AND, _PREC_UNTIL, _PREC_UNARY = 1, 2, 3, 4, 5


def _wrap(f: Formula, min_prec: int) -> str:
    text = str(f)
    return f"({text})" if _prec(f) < min_prec else text


def _prec(f: Formula) -> int:
    if isinstance(f, Implies):
        return _PREC_IMPLIES
    if isinstance(f, Or):
        return _PREC_OR
    if isinstance(f, And):
        return _PREC_AND
    if isinstance(f, Until):
        return _PREC_UNTIL
    return _PREC_UNARY


def _plain_name(name: str) -> bool:
    return bool(name) and (name[0].isalpha() or name[0] == "_") and all(c.isalnum() or c == "_" for c in name) \
        and name.isascii()


@dataclass(frozen=True, slots=True)
class Atom:
    name: str

    def __post_init__(self) -> None:
        parts = self.name.split(".") if isinstance(self.name, str) else [""]
        if len(parts) > 2 or not all(_plain_name(p) for p in parts):
            raise ValueError(f"name={self.name!r} is not an atomic proposition name")
        reserved = [p for p in parts if p in _RESERVED]
        if reserved and len(parts) == 1:
            raise ValueError(f"name={self.name!r} is a reserved word of the MITL grammar")
        if reserved:
            raise ValueError(f"name={self.name!r}: {reserved[0]!r} is a reserved word of the MITL grammar")

    @property
    def qualifier(self) -> str | None:
        """``husky`` for the qualified atom ``husky.dock`` (a robot's own atom); None for a plain atom."""
        return self.name.split(".", 1)[0] if "." in self.name else None

    @property
    def local_name(self) -> str:
        """``dock`` for ``husky.dock``; the name itself for a plain atom."""
        return self.name.rsplit(".", 1)[-1]

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True, slots=True)
class Const:
    value: bool

    def __str__(self) -> str:
        return "true" if self.value else "false"


TRUE = Const(True)
FALSE = Const(False)


@dataclass(frozen=True, slots=True)
class Not:
    arg: Formula

    def __str__(self) -> str:
        return "!" + _wrap(self.arg, _PREC_UNARY)


def _flatten(kind: type[And] | type[Or], args: tuple[Formula, ...]) -> tuple[Formula, ...]:
    out: list[Formula] = []
    for a in args:
        if isinstance(a, kind):
            out.extend(a.args)
        else:
            out.append(a)
    return tuple(out)


@dataclass(frozen=True, slots=True)
class And:
    args: tuple[Formula, ...]

    def __post_init__(self) -> None:
        flat = _flatten(And, tuple(self.args))
        if len(flat) < 2:
            raise ValueError(f"And needs at least two operands, got {len(flat)}")
        object.__setattr__(self, "args", flat)

    def __str__(self) -> str:
        return " & ".join(_wrap(a, _PREC_AND + 1) for a in self.args)


@dataclass(frozen=True, slots=True)
class Or:
    args: tuple[Formula, ...]

    def __post_init__(self) -> None:
        flat = _flatten(Or, tuple(self.args))
        if len(flat) < 2:
            raise ValueError(f"Or needs at least two operands, got {len(flat)}")
        object.__setattr__(self, "args", flat)

    def __str__(self) -> str:
        return " | ".join(_wrap(a, _PREC_OR + 1) for a in self.args)


@dataclass(frozen=True, slots=True)
class Implies:
    left: Formula
    right: Formula

    def __str__(self) -> str:
        return f"{_wrap(self.left, _PREC_IMPLIES + 1)} -> {_wrap(self.right, _PREC_IMPLIES)}"


@dataclass(frozen=True, slots=True)
class Next:
    interval: Interval
    arg: Formula

    def __str__(self) -> str:
        return f"X{self.interval} {_wrap(self.arg, _PREC_UNARY)}"


@dataclass(frozen=True, slots=True)
class Eventually:
    interval: Interval
    arg: Formula

    def __str__(self) -> str:
        return f"F{self.interval} {_wrap(self.arg, _PREC_UNARY)}"


@dataclass(frozen=True, slots=True)
class Always:
    interval: Interval
    arg: Formula

    def __str__(self) -> str:
        return f"G{self.interval} {_wrap(self.arg, _PREC_UNARY)}"


@dataclass(frozen=True, slots=True)
class Until:
    interval: Interval
    left: Formula
    right: Formula

    def __str__(self) -> str:
        return f"{_wrap(self.left, _PREC_UNARY)} U{self.interval} {_wrap(self.right, _PREC_UNTIL)}"


Formula: TypeAlias = Atom | Const | Not | And | Or | Implies | Next | Eventually | Always | Until


def subformulas(f: Formula) -> Iterator[Formula]:
    """Every sub-formula of ``f`` (``f`` included), children before parents, each once per occurrence."""
    if isinstance(f, Not | Next | Eventually | Always):
        yield from subformulas(f.arg)
    elif isinstance(f, And | Or):
        for a in f.args:
            yield from subformulas(a)
    elif isinstance(f, Implies | Until):
        yield from subformulas(f.left)
        yield from subformulas(f.right)
    yield f


def atoms(f: Formula) -> frozenset[str]:
    """Names of the atomic propositions that occur in ``f``."""
    return frozenset(g.name for g in subformulas(f) if isinstance(g, Atom))
