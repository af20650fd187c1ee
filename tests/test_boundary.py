"""The layers of the three packages (docs/architecture.md), read from the source with ``ast``.

under everything: the run-time kit ``runkit`` (executor, optional extras, output folders, gc pause), which imports
nothing of ``tubempc`` or ``verify``; bottom: the language, the scenario and the errors (``tubempc.mitl``,
``tubempc.scenario``, ``tubempc.errors``); middle, side by side: planning and control (``tubempc.planning``,
``tubempc.control``) and certification (``verify``, which uses only ``tubempc.mitl`` and ``tubempc.scenario`` of
``tubempc``); tools: falsify, regress, demo, compare, batch, the log writer and the scaffold; on top, the CLI. An
import may stay in its layer or go down, never up; the two middle sides never import each other; and no import cycle
joins two subpackages. Every import counts, lazy ones inside functions too.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]

KIT, BOTTOM, MIDDLE, TOOLS, TOP = 0, 1, 2, 3, 4
PACKAGES = ("runkit", "tubempc", "verify")
#: the packages that are one unit each (their modules are not told apart, ``verify.batch`` aside)
WHOLE = ("runkit", "verify")
#: subpackage (or top-level module) -> (layer, side); the side matters in the middle layer only
UNITS: dict[str, tuple[int, str]] = {
    "runkit": (KIT, ""),
    "tubempc": (BOTTOM, ""),
    "tubempc.errors": (BOTTOM, ""),
    "tubempc.mitl": (BOTTOM, ""),
    "tubempc.scenario": (BOTTOM, ""),
    "tubempc.control": (MIDDLE, "planning"),
    "tubempc.planning": (MIDDLE, "planning"),
    "verify": (MIDDLE, "certification"),
    "tubempc.rosio": (TOOLS, ""),
    "tubempc.falsify": (TOOLS, ""),
    "tubempc.regress": (TOOLS, ""),
    "tubempc.demo": (TOOLS, ""),
    "tubempc.compare": (TOOLS, ""),
    "tubempc.scaffold": (TOOLS, ""),
    "tubempc.strategies": (TOOLS, ""),
    "verify.batch": (TOOLS, ""),
    "tubempc.cli": (TOP, ""),
    "tubempc.__main__": (TOP, ""),
}


def unit_of(module: str) -> str:
    """The subpackage a module belongs to: its longest ``UNITS`` prefix of two or more parts, else the package for a
    module of ``verify`` or ``runkit`` (``verify.certify``), else its first two name parts (a subpackage without a
    layer)."""
    parts = module.split(".")
    for n in range(len(parts), 1, -1):
        name = ".".join(parts[:n])
        if name in UNITS:
            return name
    return parts[0] if len(parts) == 1 or parts[0] in WHOLE else ".".join(parts[:2])


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, root: Path = ROOT) -> list[str]:
    """Every module ``path`` imports (absolute and relative, at the top or inside functions)."""
    name = module_name(path, root)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.extend(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found.append(base)
            for alias in node.names:  # ``from pkg import submodule``
                where = root.joinpath(*base.split("."), alias.name)
                if where.is_dir() or where.with_suffix(".py").is_file():
                    found.append(f"{base}.{alias.name}")
    return [name for name in found if name.split(".")[0] in PACKAGES]


def unit_graph(root: Path = ROOT) -> nx.DiGraph:
    """unit -> unit it imports, each edge with one (file, module) that makes it."""
    graph = nx.DiGraph()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            source = unit_of(module_name(path, root))
            graph.add_node(source)
            for name in imports(path, root):
                target = unit_of(name)
                if target != source and not graph.has_edge(source, target):
                    graph.add_edge(source, target, where=f"{path.relative_to(root)} imports {name}")
    return graph


def layer_problems(graph: nx.DiGraph) -> list[str]:
    problems = [f"{unit} has no layer in UNITS (place it)" for unit in graph.nodes if unit not in UNITS]
    for source, target, data in graph.edges(data=True):
        if source not in UNITS or target not in UNITS:
            continue
        (layer_a, side_a), (layer_b, side_b) = UNITS[source], UNITS[target]
        if layer_b > layer_a:
            problems.append(f"climbs a layer ({source} -> {target}): {data['where']}")
        elif layer_a == layer_b == MIDDLE and side_a != side_b:
            problems.append(f"crosses the middle layer ({source} -> {target}): {data['where']}")
    return problems


def cycle_problems(graph: nx.DiGraph) -> list[str]:
    return [" <-> ".join(sorted(c)) for c in nx.strongly_connected_components(graph) if len(c) > 1]


def test_no_import_climbs_a_layer_or_crosses_the_middle() -> None:
    graph = unit_graph()
    assert graph.number_of_edges() > 20
    assert layer_problems(graph) == []


def verify_reaches_into_tubempc(graph: nx.DiGraph) -> list[str]:
    """The imports of ``verify`` (``verify.batch`` too) from ``tubempc`` beyond its language and scenario."""
    return [data["where"] for source, target, data in graph.edges(data=True)
            if source.split(".")[0] == "verify" and target.split(".")[0] == "tubempc"
            and target not in ("tubempc.mitl", "tubempc.scenario")]


def test_verify_uses_only_the_language_and_the_scenario_of_tubempc() -> None:
    assert verify_reaches_into_tubempc(unit_graph()) == []


def test_the_verify_rule_catches_an_import_of_tubempc_errors(tmp_path: Path) -> None:
    root = _tree(tmp_path, {"verify/batch/run.py": "from tubempc.errors import TubeMPCError\n",
                            "verify/certify.py": "from tubempc.scenario import Scenario\n"})
    assert verify_reaches_into_tubempc(unit_graph(root)) == [
        "verify/batch/run.py imports tubempc.errors"]


def test_no_import_cycle_between_subpackages() -> None:
    assert cycle_problems(unit_graph()) == []


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for name, text in {**{f"{package}/__init__.py": "" for package in PACKAGES}, **files}.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return tmp_path


@pytest.mark.parametrize(("files", "expected"), [
    ({"tubempc/planning/__init__.py": "def f():\n    from verify.certify import certify_log\n"},
     "crosses the middle layer (tubempc.planning -> verify)"),
    ({"tubempc/scenario/__init__.py": "from tubempc.control import x\n"},
     "climbs a layer (tubempc.scenario -> tubempc.control)"),
    ({"verify/certify.py": "from tubempc.cli import main\n"}, "climbs a layer (verify -> tubempc.cli)"),
    ({"tubempc/gadgets/__init__.py": "from tubempc.mitl import parse\n"}, "tubempc.gadgets has no layer"),
    ({"runkit/outputs.py": "from tubempc.errors import TubeMPCError\n"},
     "climbs a layer (runkit -> tubempc.errors)"),
    ({"runkit/executor.py": "def f():\n    from verify.errors import VerifyError\n"},
     "climbs a layer (runkit -> verify)"),
])
def test_the_layer_rule_catches_an_import_that_breaks_it(tmp_path: Path, files: dict[str, str],
                                                         expected: str) -> None:
    problems = layer_problems(unit_graph(_tree(tmp_path, files)))
    assert any(p.startswith(expected) for p in problems), problems


def test_the_cycle_rule_catches_two_tools_importing_each_other(tmp_path: Path) -> None:
    root = _tree(tmp_path, {"tubempc/falsify/run.py": "from tubempc.regress.suite import derived_spec\n",
                            "tubempc/regress/runner.py": "def g():\n    from . import suite\n"
                                                         "    from tubempc.falsify import run\n"})
    assert cycle_problems(unit_graph(root)) == ["tubempc.falsify <-> tubempc.regress"]


def test_importing_verify_loads_no_planner_or_controller() -> None:
    code = ("import sys, verify, verify.certify, verify.batch, verify.report, verify.online.watch; "
            "print(sorted(m for m in sys.modules if m.startswith('tubempc')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    loaded = ast.literal_eval(out.stdout)  # a printed list of module names
    forbidden = [m for m in loaded if m.startswith(("tubempc.control", "tubempc.planning", "tubempc.rosio",
                                                     "tubempc.regress", "tubempc.demo", "tubempc.cli"))]
    assert not forbidden, forbidden
