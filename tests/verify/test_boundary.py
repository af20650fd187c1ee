"""verify/ may import only the MITL language and the scenario model (and the shared errors) from tubempc."""

from __future__ import annotations

import ast
from pathlib import Path

ALLOWED = {"tubempc.mitl", "tubempc.scenario", "tubempc.errors"}
MINE = ["monitor.py", "timedrun.py", "geometry.py", "trajectory.py", "checks.py", "certify.py", "command.py",
        "errors.py", "__init__.py", "ingest"]


def test_verify_imports_only_spec_and_scenario_from_tubempc() -> None:
    root = Path(__file__).resolve().parents[2] / "verify"
    files = [p for name in MINE for p in ([root / name] if name.endswith(".py") else (root / name).rglob("*.py"))]
    assert files
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                if name == "tubempc" or name.startswith("tubempc."):
                    assert any(name == a or name.startswith(a + ".") for a in ALLOWED), f"{path}: imports {name}"
