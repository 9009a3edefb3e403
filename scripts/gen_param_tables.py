#!/usr/bin/env python3
"""Copy the parameter tables (and XML examples) of the plugins' doc blocks into README.md.

Each plugin file ``thinfilm_mi/plugins/<name>.py`` opens with a Mitsuba-style doc block
holding a ``.. pluginparameters::`` list table (rows ``* - name``, ``- type``,
``- description``) and a ``.. code-tab:: xml`` example. This script turns every
table into a Markdown table, puts the example above it, and rewrites the region
of README.md between ``<!-- params:begin -->`` and ``<!-- params:end -->``, so
the README says exactly what the doc blocks say.

    python scripts/gen_param_tables.py          # rewrite README.md
    python scripts/gen_param_tables.py --check  # exit 1 if README.md is out of date

The plugin files are read as text (``ast``), not imported: no Mitsuba needed.
"""
from __future__ import annotations

import argparse
import ast
import re
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
BEGIN, END = "<!-- params:begin -->", "<!-- params:end -->"

# Mitsuba's doc substitutions and inline reST markup -> Markdown
_SUBST = {"|string|": "string", "|float|": "float", "|int|": "integer", "|bool|": "boolean",
          "|spectrum|": "spectrum", "|texture|": "texture", "|rgb|": "rgb",
          "|transform|": "transform", "|exposed|": "exposed", "|differentiable|": "differentiable",
          "|discontinuous|": "discontinuous"}


def _inline(text: str) -> str:
    for k, v in _SUBST.items():
        text = text.replace(k, v)
    text = re.sub(r":monosp:`([^`]*)`", r"`\1`", text)
    text = re.sub(r":(?:ref|math|paramtype):`([^`]*)`", r"\1", text)
    text = re.sub(r"``([^`]*)``", r"`\1`", text)
    text = re.sub(r"\*\*([^*]+)\*\*", r"**\1**", text)
    text = text.replace("|", "\\|")  # a pipe left over would break the Markdown table
    return " ".join(text.split())


def plugin_doc(path: Path) -> str:
    """The module docstring of a plugin file."""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
    if not doc:
        raise ValueError(f"{path}: no doc block (module docstring)")
    return doc


def parse_table(doc: str, where: str = "doc block") -> list[tuple[str, str, str]]:
    """The rows ``(name, type, description)`` of the ``.. pluginparameters::`` table."""
    lines = doc.splitlines()
    try:
        start = next(i for i, l in enumerate(lines) if l.strip() == ".. pluginparameters::")
    except StopIteration:
        raise ValueError(f"{where}: no '.. pluginparameters::' table") from None
    rows: list[list[str]] = []
    for line in lines[start + 1:]:
        stripped = line.strip()
        if not stripped:
            continue
        if not line[:1].isspace():  # the first unindented line after the table ends it
            break
        if stripped.startswith("* - "):
            rows.append([stripped[4:]])
        elif stripped.startswith("- ") and rows:
            rows[-1].append(stripped[2:])
        elif rows:  # continuation of the current cell
            rows[-1][-1] += " " + stripped
    if not rows:
        raise ValueError(f"{where}: empty '.. pluginparameters::' table")
    out = []
    for row in rows:
        if len(row) not in (3, 4):
            raise ValueError(f"{where}: row {row[0]!r} has {len(row)} cells, expected 3 "
                             "(name, type, description) or 4 (and Mitsuba's flags)")
        name, kind, desc = (_inline(c) for c in row[:3])
        if len(row) == 4:  # Mitsuba's |exposed|, |differentiable| column
            kind += f" ({_inline(row[3])})"
        out.append((name, kind, desc))
    return out


def xml_example(doc: str) -> str | None:
    """The ``.. code-tab:: xml`` example of a doc block (dedented), if any."""
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        if line.strip() == ".. code-tab:: xml":
            indent = len(line) - len(line.lstrip())
            body = []
            for l in lines[i + 1:]:
                if l.strip() and len(l) - len(l.lstrip()) <= indent:
                    break
                body.append(l)
            text = textwrap.dedent("\n".join(body)).strip("\n")
            return text or None
    return None


def plugin_title(doc: str, name: str) -> str:
    """The doc block's title line without its ``(:monosp:`name`)`` tag."""
    for line in doc.splitlines():
        if f":monosp:`{name}`" in line:
            return re.sub(r"\s*\(:monosp:`[^`]*`\)\s*$", "", line.strip())
    return name


def plugin_files(plugins: Path) -> list[Path]:
    return sorted(p for p in plugins.glob("*.py") if not p.name.startswith("_"))


def render_tables(plugins: Path) -> str:
    """The Markdown of all tables, one section per plugin, in file-name order."""
    parts = []
    for path in plugin_files(plugins):
        name = path.stem
        doc = plugin_doc(path)
        rows = parse_table(doc, f"thinfilm_mi/plugins/{path.name}")
        parts.append(f"#### `{name}` — {plugin_title(doc, name)}\n")
        parts.append(f"From the doc block of `thinfilm_mi/plugins/{path.name}`.\n")
        example = xml_example(doc)
        if example:
            parts.append(f"```xml\n{example}\n```\n")
        parts.append("| parameter | type | description |\n|---|---|---|")
        for pname, ptype, desc in rows:
            names = ", ".join(f"`{n.strip()}`" for n in pname.replace("`", "").split(","))
            parts.append(f"| {names} | {ptype} | {desc} |")
        parts.append("")
    return "\n".join(parts).rstrip() + "\n"


def rewrite(readme_text: str, tables: str) -> str:
    """``readme_text`` with the params region replaced by ``tables``."""
    if readme_text.count(BEGIN) != 1 or readme_text.count(END) != 1:
        raise ValueError(f"README.md must hold exactly one {BEGIN} ... {END} region")
    head, rest = readme_text.split(BEGIN)
    _, tail = rest.split(END)
    note = ("<!-- generated by scripts/gen_param_tables.py from the plugins' doc blocks; "
            "do not edit by hand -->\n")
    return f"{head}{BEGIN}\n{note}\n{tables}\n{END}{tail}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="do not write; exit 1 if README.md differs from the doc blocks")
    ap.add_argument("--readme", default=str(REPO / "README.md"))
    ap.add_argument("--plugins", default=str(REPO / "thinfilm_mi" / "plugins"))
    args = ap.parse_args(argv)
    readme = Path(args.readme)
    text = readme.read_text(encoding="utf-8")
    new = rewrite(text, render_tables(Path(args.plugins)))
    if args.check:
        if new != text:
            print(f"{readme}: the parameter tables are out of date; run "
                  "python scripts/gen_param_tables.py", file=sys.stderr)
            return 1
        return 0
    if new != text:
        readme.write_text(new, encoding="utf-8")
        print(f"rewrote the parameter tables in {readme}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
