"""Helpers shared by the tests of damaged and adversarial input (``test_no_false_pass.py``,
``test_damaged_input.py``): the fuzzer's log kit and the CLI run in this process."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

from tubempc.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _fuzz() -> ModuleType:
    """``benchmarks/fuzz_certify.py`` (seed logs, runs, writers, the campaign) as a module, loaded once."""
    loaded = sys.modules.get("fuzz_certify")
    if loaded is not None:
        return loaded
    spec = importlib.util.spec_from_file_location("fuzz_certify", ROOT / "benchmarks" / "fuzz_certify.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_certify"] = module
    spec.loader.exec_module(module)
    return module


FUZZ = _fuzz()


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
