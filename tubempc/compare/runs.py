"""One side of a comparison (a folder, a glob, a log, or a folder of certificates) -> certified runs with pair keys.

input: the side's path or glob, the scenario (and formula, time base) -> output: a ``Side`` of ``Run`` values (the
run's key, its source and its ``Certificate``); ``pair_runs`` matches the runs of two sides.

- A folder holding ``certificate.json`` files (batch certification's ``--out``, regress's ``--out``) is read as
  certificates; any other folder, file or glob is read as logs and certified with ``verify.batch.certify_many``
  (the project's certifier, in parallel). Either way the metrics come from the certificate model.
- A run's key, used to pair it with a run of the other side: by default its log's path relative to the side's folder
  without the suffix (``before/mission3.mcap`` -> ``mission3``; ``regress-out/R1-R3.s0/run.mcap`` ->
  ``R1-R3.s0/run``); ``pair_pattern`` (a regular expression searched in that key: the first group, or the match);
  ``pair_by`` (a field of the certificate, dotted: ``generator.seed``).
- A log that cannot be certified, a certificate that does not validate or that was made for another scenario or
  formula, and a side without runs are ``CompareInputError`` (exit 3) naming the file.
"""

from __future__ import annotations

import glob
import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from tubempc.errors import CompareInputError
from tubempc.scenario import Scenario
from verify.certificate import Certificate

__all__ = ["Pairing", "Run", "Side", "load_side", "pair_runs"]

_LOG_SUFFIXES = (".bag", ".mcap", ".db3")


@dataclass(frozen=True, slots=True)
class Run:
    key: str
    source: str  # the log or certificate file
    certificate: Certificate


@dataclass(frozen=True, slots=True)
class Side:
    label: str  # as given on the command line
    kind: str  # "logs" or "certificates"
    runs: tuple[Run, ...]


@dataclass(frozen=True, slots=True)
class Pairing:
    """``pairs``: (before, after) runs with the same key; ``paired``: every run has its partner (the paired tests
    apply); the runs without one are listed by key."""

    pairs: tuple[tuple[Run, Run], ...]
    paired: bool
    before_alone: tuple[str, ...]
    after_alone: tuple[str, ...]
    note: str


def _expand(text: str) -> list[Path]:
    if glob.has_magic(text):
        found = sorted(Path(p) for p in glob.glob(text, recursive=True))
        if not found:
            raise CompareInputError(f"{text}: the pattern matches no file or folder")
        return found
    path = Path(text)
    if not path.exists():
        raise CompareInputError(f"{text}: file or folder not found")
    return [path]


def _certificate_files(paths: Sequence[Path]) -> list[Path]:
    out: list[Path] = []
    for path in paths:
        if path.is_file() and path.suffix == ".json":
            out.append(path)
        elif path.is_dir():
            out.extend(sorted(path.rglob("certificate.json")))
    return out


def _read_certificate(path: Path) -> Certificate:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise CompareInputError(f"{path}: cannot read the certificate ({err.strerror or err})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CompareInputError(f"{path}: not a JSON certificate ({err.__class__.__name__})") from None
    try:
        return Certificate.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first.get("loc", ())) or "top level"
        raise CompareInputError(f"{path}: not a certificate of this version ({where}: {first.get('msg')})"
                                ) from None


def _relative_key(log: str, root: Path | None) -> str:
    path = Path(log)
    if root is not None:
        try:
            path = path.resolve().relative_to(root)
        except ValueError:
            path = Path(path.name)
    else:
        path = Path(path.name)
    text = path.as_posix()
    for suffix in _LOG_SUFFIXES:
        if text.lower().endswith(suffix):
            return text[: -len(suffix)]
    return text


def _common_root(logs: Sequence[str]) -> Path | None:
    parents = [str(Path(p).resolve().parent) for p in logs]
    if not parents:
        return None
    try:
        return Path(os.path.commonpath(parents))
    except ValueError:  # different drives
        return None


def _field(cert: Certificate, dotted: str, source: str) -> str:
    value: Any = cert
    for part in dotted.split("."):
        if isinstance(value, dict):
            if part not in value:
                raise CompareInputError(f"{source}: --pair-by {dotted}: the certificate has no field {part!r}")
            value = value[part]
        elif isinstance(value, Certificate) and part in type(value).model_fields:
            value = getattr(value, part)
        else:
            raise CompareInputError(f"{source}: --pair-by {dotted}: the certificate has no field {part!r}")
    if value is None or isinstance(value, dict | list):
        raise CompareInputError(f"{source}: --pair-by {dotted}: the field is {value!r}, not a value to pair by")
    return str(value)


def _keys(runs: list[tuple[str, Certificate]], *, pair_by: str | None, pattern: re.Pattern[str] | None
          ) -> list[str]:
    root = _common_root([cert.log for _, cert in runs])
    keys = []
    for source, cert in runs:
        if pair_by is not None:
            keys.append(_field(cert, pair_by, source))
            continue
        key = _relative_key(cert.log, root)
        if pattern is not None:
            match = pattern.search(key)
            if match is None:
                raise CompareInputError(f"{source}: --pair-pattern {pattern.pattern!r} does not match its run "
                                        f"{key!r}")
            key = match.group(1) if match.groups() else match.group(0)
        keys.append(key)
    return keys


def _certify(paths: Sequence[Path], scenario: Scenario, *, spec: str | None, time_base: str,
             workers: int | None, progress: bool | None) -> list[tuple[str, Certificate]]:
    from verify.batch import certify_many

    batch = certify_many(paths, scenario, spec=spec, time_base=time_base,  # type: ignore[arg-type]
                         workers=workers, progress=progress)
    out = []
    for item in batch.items:
        if item.result is None:
            raise CompareInputError(f"{item.path}: cannot be certified: {item.error}")
        out.append((item.path, Certificate.model_validate(item.result.certificate)))
    return out


def load_side(text: str, scenario: Scenario, *, formula: str, spec: str | None = None, time_base: str = "auto",
              workers: int | None = None, progress: bool | None = None, pair_by: str | None = None,
              pair_pattern: str | None = None) -> Side:
    """Read (or certify) one side; ``formula`` is the canonical formula every certificate must state."""
    paths = _expand(text)
    certs = _certificate_files(paths)
    if certs:
        runs = [(str(p), _read_certificate(p)) for p in certs]
        kind = "certificates"
        for source, cert in runs:
            if cert.scenario_sha256 != scenario.sha256():
                raise CompareInputError(f"{source}: certified against another scenario ({cert.scenario!r}, sha256 "
                                        f"{cert.scenario_sha256[:12]}) than {scenario.name!r} "
                                        f"(sha256 {scenario.sha256()[:12]}): certify the logs again")
            if cert.formula != formula:
                raise CompareInputError(f"{source}: certified against another formula ({cert.formula}) than "
                                        f"{formula}")
    else:
        runs = _certify(paths, scenario, spec=spec, time_base=time_base, workers=workers, progress=progress)
        kind = "logs"
    try:
        pattern = re.compile(pair_pattern) if pair_pattern is not None else None
    except re.error as err:
        raise CompareInputError(f"--pair-pattern {pair_pattern!r}: not a regular expression ({err})") from None
    keys = _keys(runs, pair_by=pair_by, pattern=pattern)
    return Side(text, kind, tuple(Run(k, s, c) for k, (s, c) in zip(keys, runs, strict=True)))


def pair_runs(before: Side, after: Side, *, unpaired: bool = False) -> Pairing:
    """Pair runs by key. Keys that repeat on a side, or runs without a partner, make the comparison unpaired (two
    samples); the pairs found still carry the verdict rule (pass -> fail regresses), except with ``unpaired``."""
    def index(side: Side) -> tuple[dict[str, Run], set[str]]:
        seen: dict[str, Run] = {}
        twice: set[str] = set()
        for run in side.runs:
            if run.key in seen:
                twice.add(run.key)
            seen[run.key] = run
        return seen, twice

    b, b_twice = index(before)
    a, a_twice = index(after)
    common = sorted((set(b) & set(a)) - b_twice - a_twice)
    pairs = tuple((b[k], a[k]) for k in common)
    b_alone = tuple(sorted(set(b) - set(common)))
    a_alone = tuple(sorted(set(a) - set(common)))
    if unpaired:  # the user says the keys do not name the same missions: no pairs at all
        return Pairing((), False, tuple(sorted(b)), tuple(sorted(a)), "unpaired on request (--unpaired): two samples")
    if b_twice or a_twice:
        dup = sorted(b_twice | a_twice)
        return Pairing(pairs, False, b_alone, a_alone,
                       f"run keys repeat on a side ({', '.join(dup[:5])}): compared as two samples")
    if b_alone or a_alone or not pairs:
        return Pairing(pairs, False, b_alone, a_alone,
                       f"{len(b_alone)} run(s) before and {len(a_alone)} after have no partner of the same key: "
                       "compared as two samples")
    return Pairing(pairs, True, (), (), f"{len(pairs)} runs paired by key")
