"""verify/ may import only the MITL language and the scenario model from tubempc (never planner or controller)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ALLOWED = {"tubempc.mitl", "tubempc.scenario"}
ROOT = Path(__file__).resolve().parents[2] / "verify"


def test_verify_imports_only_spec_and_scenario_from_tubempc() -> None:
    files = sorted(ROOT.rglob("*.py"))
    assert len(files) > 10
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                if name == "tubempc" or name.startswith("tubempc."):
                    assert any(name == a or name.startswith(a + ".") for a in ALLOWED), f"{path}: imports {name}"


def test_importing_verify_loads_no_planner_or_controller() -> None:
    code = ("import sys, verify, verify.certify, verify.batch, verify.report, verify.online.watch; "
            "print(sorted(m for m in sys.modules if m.startswith('tubempc')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    loaded = ast.literal_eval(out.stdout)  # a printed list of module names
    forbidden = [m for m in loaded if m.startswith(("tubempc.control", "tubempc.planning", "tubempc.rosio",
                                                     "tubempc.regress", "tubempc.demo"))]
    assert not forbidden, forbidden
