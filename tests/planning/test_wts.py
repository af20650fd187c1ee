"""Abstraction: nodes are the safe regions, failed pairs keep their reason, cache and parallel builds agree."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import pytest

from tests.planning.synthetic import straight_line_oracle
from tubempc.planning.wts import build_wts, wts_cache_file, wts_edges, wts_failed, wts_labels
from tubempc.scenario import builtin_scenario

CALLS: list[tuple[str, str]] = []


def test_nodes_are_safe_regions_with_labels(tmp_path: Path) -> None:
    s = builtin_scenario()
    g = build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1)
    assert set(g.nodes) == {r.name for r in s.safe_regions}
    assert wts_labels(g, "R1") == ("mission_1",)
    for _, _, w in wts_edges(g):
        assert isinstance(w, Fraction) and w > 0
    n = len(s.safe_regions)
    assert g.number_of_edges() + len(wts_failed(g)) == n * (n - 1)
    assert all("passes region" in why for why in wts_failed(g).values())


def test_cache_and_process_pool_agree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import tubempc.planning.wts as wts_module

    s = builtin_scenario()
    cold = build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=2)
    (cache_file,) = tmp_path.glob("wts-*.json")
    written = cache_file.stat().st_mtime_ns

    def no_evaluation(*args: object) -> None:
        raise AssertionError("the warm build evaluated a region pair instead of reading the cache")

    monkeypatch.setattr(wts_module, "_evaluate", no_evaluation)  # workers=1 evaluates in this process
    warm = build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1)
    assert wts_cache_file(warm) == str(cache_file)
    assert cache_file.stat().st_mtime_ns == written  # read, not recomputed and rewritten
    assert sorted(wts_edges(cold)) == sorted(wts_edges(warm))
    assert wts_failed(cold) == wts_failed(warm)
    with pytest.raises(AssertionError, match="instead of reading the cache"):  # the guard itself can fire
        build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1, use_cache=False)


def test_cache_key_depends_on_the_scenario(tmp_path: Path) -> None:
    s = builtin_scenario()
    build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1)
    other = s.model_copy(update={"initial_region_name": "R2"})
    build_wts(other, oracle=straight_line_oracle, cache_path=tmp_path, workers=1)
    assert len(list(tmp_path.glob("wts-*.json"))) == 2


def test_the_abstraction_runs_on_the_shared_executor(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """build_wts hands its region pairs to runkit.executor.parallel_map (workers, Dask, progress passed
    through)."""
    import runkit.executor
    from tubempc.planning import wts as wts_module

    real = runkit.executor.parallel_map
    seen: list[dict[str, object]] = []

    def spy(fn: object, items: list[object], **kwargs: object) -> list[object]:
        seen.append({"fn": fn, "jobs": len(items), **kwargs})
        return real(fn, items, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(runkit.executor, "parallel_map", spy)
    s = builtin_scenario()
    g = build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1, progress=False, use_cache=False)
    n = len(s.safe_regions)
    (call,) = seen
    assert call["fn"] is wts_module._evaluate and call["jobs"] == n * (n - 1)
    assert (call["workers"], call["dask"], call["progress"], call["unit"]) == (1, None, False, "pair")
    assert "tests.planning.synthetic" in call["preload"]  # type: ignore[operator]
    assert g.number_of_edges() + len(wts_failed(g)) == n * (n - 1)


def test_the_graph_keys_are_read_through_the_accessors_alone() -> None:
    """Outside ``tubempc/planning/wts.py`` no code of the package reads a WTS attribute by its key (``graph[...]``,
    ``graph.get(...)``, a node's or an edge's attribute dict) or imports a key constant."""
    import ast

    root = Path(__file__).resolve().parents[2] / "tubempc"
    keys = {"FAILED", "LABELS", "ORACLE", "WEIGHT", "INITIAL", "SCENARIO_SHA"}
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.name == "wts.py" and path.parent.name == "planning":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("tubempc.planning"):
                found.extend(f"{path.name} imports {a.name}" for a in node.names if a.name.lstrip("_") in keys)
            if isinstance(node, ast.Attribute) and node.attr == "graph" and isinstance(node.value, ast.Name) \
                    and node.value.id == "wts":
                found.append(f"{path.name}:{node.lineno} reads wts.graph")
            key = node.slice if isinstance(node, ast.Subscript) else (
                node.args[0] if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get" and node.args else None)
            if isinstance(key, ast.Constant) and key.value in {"oracle", "t_ij", "failed", "labels", "initial"} \
                    and path.parent.name == "planning":
                found.append(f"{path.name}:{node.lineno} reads the key {key.value!r}")
    assert found == []
