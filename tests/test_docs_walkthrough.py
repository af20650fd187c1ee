"""Every command of docs/certify-your-log.md runs, and prints what the page shows.

Each ```bash block runs (in order, stdout and stderr together) in a scratch folder that sees the repository's
``logs/`` and ``docs/examples/`` (read only: the certifier never modifies its inputs); when a ```text block follows
it, the output must be exactly that text. The walkthrough's scenario on the page must be the shipped file.
``python3 tests/test_docs_walkthrough.py --print`` prints each block's real output (to refresh the page).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "certify-your-log.md"
FENCE = re.compile(r"```(\w+)\n(.*?)```", re.S)


def blocks(text: str) -> list[tuple[str, str | None]]:
    """(bash source, the text block right after it or None), in page order."""
    found = [(m.group(1), m.group(2), m.start(), m.end()) for m in FENCE.finditer(text)]
    out: list[tuple[str, str | None]] = []
    for i, (lang, body, _start, end) in enumerate(found):
        if lang != "bash":
            continue
        expected = None
        if i + 1 < len(found) and found[i + 1][0] == "text" and not text[end : found[i + 1][2]].strip():
            expected = found[i + 1][1]
        out.append((body, expected))
    return out


def run_block(source: str, cwd: Path) -> str:
    prelude = ('exec 2>&1\n'  # one stream, in the order a terminal shows it
               'tubempc() { "$DOC_PYTHON" -m tubempc "$@"; }\n'
               'python3() { "$DOC_PYTHON" "$@"; }\n')
    env = {**os.environ, "DOC_PYTHON": sys.executable, "PYTHONPATH": str(ROOT),
           "TUBEMPC_CACHE": str(cwd / ".cache"), "COLUMNS": "120"}
    done = subprocess.run(["bash", "-c", prelude + source], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600, check=False)
    return done.stdout


def scratch(tmp: Path) -> Path:
    (tmp / "docs").mkdir(parents=True)
    (tmp / "logs").symlink_to(ROOT / "logs")
    (tmp / "docs" / "examples").symlink_to(ROOT / "docs" / "examples")
    return tmp


def test_the_scenario_on_the_page_is_the_shipped_file() -> None:
    page = DOC.read_text()
    yaml_blocks = [m.group(2) for m in FENCE.finditer(page) if m.group(1) == "yaml"]
    shipped = (ROOT / "docs" / "examples" / "diffdrive-room.yaml").read_text()
    body = "".join(line for line in shipped.splitlines(keepends=True) if not line.startswith("#"))
    assert yaml_blocks[0] == body


def test_every_command_runs_and_prints_what_the_page_shows(tmp_path: Path) -> None:
    cwd = scratch(tmp_path)
    page_blocks = blocks(DOC.read_text())
    assert len(page_blocks) >= 8
    for source, expected in page_blocks:
        output = run_block(source, cwd)
        assert "Traceback" not in output and "internal error" not in output, (source, output)
        assert "command not found" not in output, (source, output)
        if expected is not None:
            assert output.rstrip() == expected.rstrip(), f"{source}\n--- page:\n{expected}\n--- real:\n{output}"


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        where = scratch(Path(tmp))
        for source, expected in blocks(DOC.read_text()):
            print("=" * 20, source.splitlines()[0][:80], "(shown)" if expected is not None else "")
            print(run_block(source, where), end="")
