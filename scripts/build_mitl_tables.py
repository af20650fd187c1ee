"""Write ``tubempc/mitl/_lalr_tables.py``: the MITL grammar's LALR tables, so that no start builds them.

    python3 scripts/build_mitl_tables.py

Run it after changing the grammar in ``tubempc/mitl/parser.py`` or upgrading Lark (``tests/test_mitl_parser.py``
fails until the committed tables match both).
"""

from __future__ import annotations

from pathlib import Path

from tubempc.mitl.parser import tables_source

TARGET = Path(__file__).resolve().parent.parent / "tubempc" / "mitl" / "_lalr_tables.py"


def main() -> None:
    TARGET.write_text(tables_source(), encoding="utf-8")
    print(f"wrote {TARGET}")


if __name__ == "__main__":
    main()
