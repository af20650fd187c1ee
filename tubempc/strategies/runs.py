"""Label maps and finite timed runs (region, exact rational time)."""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction

from tubempc.strategies._common import st


@st.composite
def label_maps(draw: st.DrawFn, *, max_regions: int = 4, atoms: tuple[str, ...] = ("p", "q", "r"),
               min_regions: int = 1) -> dict[str, tuple[str, ...]]:
    """``{region name: labels}`` for min_regions..max_regions regions ``R1, R2, ...`` with labels from ``atoms``."""
    if not 1 <= min_regions <= max_regions:
        raise ValueError(f"need 1 <= min_regions={min_regions} <= max_regions={max_regions}")
    n = draw(st.integers(min_regions, max_regions))
    return {f"R{i + 1}": tuple(sorted(draw(st.sets(st.sampled_from(atoms), max_size=len(atoms)))))
            for i in range(n)}


@dataclass(frozen=True, slots=True)
class TimedRun:
    """A finite timed run: ``entries`` = ((region, time), ...) with exact, non-decreasing times from 0."""

    entries: tuple[tuple[str, Fraction], ...]
    labels: Mapping[str, tuple[str, ...]] = field(hash=False)

    def __post_init__(self) -> None:
        if not self.entries:
            raise ValueError("a timed run needs at least one entry")
        if self.entries[0][1] != 0:
            raise ValueError(f"the first entry's time {self.entries[0][1]} must be 0")
        for (_, a), (_, b) in itertools.pairwise(self.entries):
            if b < a:
                raise ValueError(f"times must not decrease ({a} then {b})")
        unknown = {r for r, _ in self.entries} - set(self.labels)
        if unknown:
            raise ValueError(f"regions {sorted(unknown)} are not in the label map")

    def as_floats(self) -> list[tuple[str, float]]:
        """The run as ``[(region, seconds), ...]`` (the certifier's ``check_timed_run`` input)."""
        return [(r, float(t)) for r, t in self.entries]

    def label_lists(self) -> dict[str, list[str]]:
        return {k: list(v) for k, v in self.labels.items()}


@st.composite
def timed_runs(draw: st.DrawFn, labels: Mapping[str, tuple[str, ...]] | None = None, *, max_len: int = 6,
               quantum: Fraction = Fraction(1, 2), max_gap: int = 8, allow_repeats: bool = True,
               strictly_increasing: bool = True) -> TimedRun:
    """Finite timed runs over ``labels`` (drawn by ``label_maps()`` when None): the first entry at time 0,
    gaps ``k * quantum`` with k in [1, max_gap] (k >= 0 when not ``strictly_increasing``). Consecutive entries
    differ in region unless ``allow_repeats`` (a dwell observed as a new position)."""
    lab = dict(labels) if labels is not None else draw(label_maps())
    names = sorted(lab)
    length = draw(st.integers(1, max_len))
    entries: list[tuple[str, Fraction]] = [(draw(st.sampled_from(names)), Fraction(0))]
    t = Fraction(0)
    for _ in range(length - 1):
        prev = entries[-1][0]
        options = names if allow_repeats else [n for n in names if n != prev]
        if not options:
            break
        t += draw(st.integers(1 if strictly_increasing else 0, max_gap)) * quantum
        entries.append((draw(st.sampled_from(options)), t))
    return TimedRun(entries=tuple(entries), labels=lab)
