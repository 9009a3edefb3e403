"""Write the shared parameter rows into the plugins' doc blocks.

    python scripts/compose_docblocks.py          # rewrite the doc blocks that differ
    python scripts/compose_docblocks.py --check  # list them and exit 1, change nothing

The rows of ``thickness``, ``tabulate``, ``table_error``, ``spectral_resolution`` and
``coherence_thickness`` are written once, in :mod:`thinfilm_mi.render.doc_rows`. A plugin
whose doc block lists them names its family in an RST comment before its
``.. pluginparameters::`` table (``.. shared-rows: conductor``; a comment renders to
nothing), and this script replaces each of those rows, where it stands in the table, by
the family's text: every doc block still reads alone (Mitsuba's doc generator reads the
module docstring as it is), and the text exists once. Only the module docstring of a
plugin file is rewritten; the code below it is left byte for byte.
``tests/cross/test_docblocks.py`` runs :func:`composed` on every plugin.
"""
from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))   # this checkout's package, not an installed one
from thinfilm_mi.render.doc_rows import SHARED_NAMES, shared_rows  # noqa: E402

__all__ = ["MARKER", "composed", "family_of", "plugin_paths", "main"]

#: the comment that names a doc block's family: ``.. shared-rows: NAME``
MARKER = re.compile(r"^\.\. shared-rows: (\S+)\s*$", re.M)
#: a row's first line in a ``.. pluginparameters::`` table
ROW = re.compile(r"^ \* - (.+)$")


def plugin_paths() -> list[Path]:
    """The plugin modules (``thinfilm_mi/plugins/*.py`` but ``__init__``), in name order."""
    return sorted(p for p in (REPO / "thinfilm_mi" / "plugins").glob("*.py") if not p.name.startswith("_"))


def _docstring_lines(source: str, path: Path) -> tuple[int, int]:
    """The 0-based line range ``[first, last)`` of the module docstring in ``source``."""
    tree = ast.parse(source)
    node = tree.body[0] if tree.body else None
    if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)):
        raise ValueError(f"{path}: no doc block (module docstring)")
    return node.lineno - 1, node.end_lineno


def family_of(doc: str, path: Path) -> str | None:
    """The family a doc block names (``.. shared-rows: NAME``), or None when it names none."""
    found = MARKER.findall(doc)
    if len(found) > 1:
        raise ValueError(f"{path}: {len(found)} '.. shared-rows:' comments, expected one")
    return found[0] if found else None


def composed(source: str, path: Path) -> str:
    """``source`` (a plugin file) with the shared rows of its doc block rewritten."""
    first, last = _docstring_lines(source, path)
    lines = source.splitlines(keepends=True)
    doc = lines[first:last]
    family = family_of("".join(doc), path)
    listed = {m.group(1).strip() for line in doc if (m := ROW.match(line.rstrip("\n")))}
    shared = listed & set(SHARED_NAMES)
    if family is None:
        if shared:
            raise ValueError(f"{path}: its doc block lists {sorted(shared)} but names no family "
                             "('.. shared-rows: FAMILY' before its table)")
        return source
    rows = shared_rows(family)
    missing = set(SHARED_NAMES) - listed
    if missing:
        raise ValueError(f"{path}: '.. shared-rows: {family}' but its table lacks {sorted(missing)}")
    out, i = [], 0
    while i < len(doc):
        match = ROW.match(doc[i].rstrip("\n"))
        if match and match.group(1).strip() in rows:
            out.append(rows[match.group(1).strip()] + "\n")
            i += 1
            # the row goes on while its lines are indented deeper than " * - " (or blank within it)
            while i < len(doc) and (doc[i].startswith("   ") or (doc[i].strip() == "" and i + 1 < len(doc)
                                                                    and doc[i + 1].startswith("   "))):
                i += 1
        else:
            out.append(doc[i])
            i += 1
    return "".join(lines[:first] + out + lines[last:])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="list the doc blocks that differ; change nothing")
    args = parser.parse_args(argv)
    differ = []
    for path in plugin_paths():
        source = path.read_text(encoding="utf-8")
        new = composed(source, path)
        if new != source:
            differ.append(path.relative_to(REPO))
            if not args.check:
                path.write_text(new, encoding="utf-8")
    verb = "differ from the composition" if args.check else "rewritten"
    print(f"{len(differ)} doc block(s) {verb}" + "".join(f"\n  {p}" for p in differ))
    return 1 if args.check and differ else 0


if __name__ == "__main__":
    sys.exit(main())
