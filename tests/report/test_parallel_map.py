"""The shared executor: inline and process pool give the same ordered list (Dask: see test_batch_real_logs)."""

from __future__ import annotations

import faulthandler
import functools
import operator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import pytest

from runkit.errors import OutputError
from runkit.executor import parallel_map

ITEMS = [3, -1, 4, -1, -5, 9, -2, 6]
EXPECTED = [abs(x) for x in ITEMS]


def test_inline_and_processes_keep_order() -> None:
    assert parallel_map(abs, ITEMS, workers=1, progress=False) == EXPECTED
    assert parallel_map(abs, ITEMS, workers=2, progress=False) == EXPECTED
    assert parallel_map(abs, [], workers=2, progress=False) == []


def test_exceptions_propagate() -> None:
    with pytest.raises(TypeError):
        parallel_map(operator.inv, [0.5], workers=1, progress=False)  # ~0.5: TypeError inside fn
    with pytest.raises(ValueError, match="invalid literal"):
        parallel_map(int, ["1", "x"], workers=2, progress=False)
    with pytest.raises(ValueError, match="workers=0"):
        parallel_map(abs, ITEMS, workers=0)


def test_bad_dask_address_is_unusable_input() -> None:
    with pytest.raises(OutputError, match="expected 'local'"):
        parallel_map(abs, ITEMS, dask="my-laptop", progress=False)


def test_the_kits_errors_are_ours_with_their_exit_codes() -> None:
    """``runkit``'s errors have their own root; the CLI still counts them as raised on purpose (one line, not an
    internal error): an unusable output or address exits 3, a missing extra 4."""
    from runkit.errors import MissingExtraError
    from tubempc.cli.exits import EXIT_NOT_AVAILABLE, EXIT_UNUSABLE, exit_code, is_ours

    assert is_ours(OutputError("no", path="out")) and exit_code(OutputError("no", path="out")) == EXIT_UNUSABLE
    assert is_ours(MissingExtraError("no dask")) and exit_code(MissingExtraError("no dask")) == EXIT_NOT_AVAILABLE


def test_the_abstraction_names_a_bad_dask_address(tmp_path: Path) -> None:
    from tests.planning.synthetic import straight_line_oracle
    from tubempc.errors import AbstractionError
    from tubempc.planning.wts import build_wts
    from tubempc.scenario import builtin_scenario

    with pytest.raises(AbstractionError, match=r"building the WTS .* expected 'local'"):
        build_wts(builtin_scenario(), oracle=straight_line_oracle, cache_path=tmp_path, dask="my-laptop",
                  progress=False)


def test_progress_bar_on_request(capsys: pytest.CaptureFixture[str]) -> None:
    parallel_map(abs, ITEMS, workers=1, progress=True, desc="certify")
    err = capsys.readouterr().err
    assert "certify" in err and f"{len(ITEMS)}/{len(ITEMS)}" in err
    parallel_map(abs, ITEMS, workers=1, progress=False, desc="certify")
    assert capsys.readouterr().err == ""


def test_a_worker_that_dies_is_rerun_alone_and_reported() -> None:
    """A segfault in one item breaks the pool: bystanders are rerun alone and finish; the item that dies again
    gets ``on_crash`` (the batch gives it exit 70) instead of aborting the whole map."""
    items = [functools.partial(abs, -1), faulthandler._sigsegv, functools.partial(abs, -2),
             functools.partial(abs, -3)]
    out = parallel_map(operator.call, items, workers=2, progress=False, on_crash=lambda item: "died")
    assert out == [1, "died", 2, 3]
    with pytest.raises(RuntimeError, match="died twice"):
        parallel_map(operator.call, items, workers=2, progress=False)


def test_a_pool_that_breaks_while_items_are_handed_out(monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker can die before every item is submitted (a crash in the first items on a loaded machine): the pool
    then refuses new work, and the items not handed out are rerun alone like the bystanders of a crash."""
    real = ProcessPoolExecutor.submit
    calls = {"n": 0}

    def submit(self: ProcessPoolExecutor, fn: Any, /, *args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 3:
            raise BrokenProcessPool("A child process terminated abruptly, the process pool is not usable anymore")
        return real(self, fn, *args, **kwargs)

    monkeypatch.setattr(ProcessPoolExecutor, "submit", submit)
    assert parallel_map(abs, [-1, -5, -2, -3], workers=2, progress=False) == [1, 5, 2, 3]


def test_dask_chunks_keep_order_and_balance() -> None:
    """Dask gets a few contiguous chunks per worker (one task and one pickled scenario per chunk, not per item)."""
    from runkit.executor import _chunks

    items = list(range(203))
    chunks = _chunks(items, 2)
    assert len(chunks) == 8 and [x for c in chunks for x in c] == items
    assert max(map(len, chunks)) - min(map(len, chunks)) <= 1
    assert _chunks([1, 2], 4) == [[1], [2]]
    assert _chunks([], 2) == []
