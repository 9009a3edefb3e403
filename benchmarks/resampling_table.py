"""The materials guide's table of each named material's uniform grid and its measured
deviation from the data's own interpolation (``catalog.format_resampling_table``).

    python benchmarks/resampling_table.py [--write]

Prints the table; ``--write`` replaces the one in ``docs/guides/materials.md``.
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
GUIDE = REPO / "docs" / "guides" / "materials.md"
START, END = "<!-- resampling table: start -->", "<!-- resampling table: end -->"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="write it into the materials guide")
    args = ap.parse_args()
    from thinfilm_mi.materials.catalog import format_resampling_table
    table = format_resampling_table()
    if not args.write:
        print(table)
        return 0
    text = GUIDE.read_text()
    pattern = re.compile(re.escape(START) + r"\n(?:.*?\n)?" + re.escape(END), re.S)
    if not pattern.search(text):
        print(f"{GUIDE}: no {START} ... {END} block", file=sys.stderr)
        return 1
    GUIDE.write_text(pattern.sub(lambda _: f"{START}\n{table}\n{END}", text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
