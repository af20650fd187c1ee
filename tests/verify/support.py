"""Helpers shared by the tests of damaged and adversarial input (``test_no_false_pass.py``,
``test_damaged_input.py``, the reading rules): the fault campaign's log kit (``benchmarks/fuzz_certify.py``, imported
as a module of the repository) and the CLI run in this process."""

from __future__ import annotations

import pytest

from benchmarks import fuzz_certify as FUZZ  # noqa: N812  (the fault campaign: seed logs, runs, writers)
from tubempc.cli import main

__all__ = ["FUZZ", "one_line_error", "run"]


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``tubempc`` with ``argv`` in this process: (exit code, stdout, stderr)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    code = exc.value.code
    return (code if isinstance(code, int) else 0), out, err


def one_line_error(err: str, *needles: str) -> None:
    """stderr is one ``tubempc: error:`` line holding every needle."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("tubempc: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, err)
