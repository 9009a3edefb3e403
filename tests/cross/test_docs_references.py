"""What the documentation cites exists (issue 41).

The Limitations page names, for each limitation, the test that bounds it as
``tests/....py::test_name`` and the benchmark that measures it; the benchmark page shows
the tables the benchmarks write. Here: every ``tests/...py[::name]`` and ``benchmarks/*.py``
that a page of ``docs/`` (or the README) cites is a file, and every cited test function is
defined in it; every benchmark the page shows (``{generated} NAME``) is a script with the
``--write-docs`` option that ``benchmarks/write_docs.py`` runs, and a table of it is
committed unless the directive says ``:optional:``.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
PAGES = [REPO / "README.md"] + sorted(p for p in DOCS.rglob("*.md")
                                      if not {"_build", "_generated"} & set(p.relative_to(DOCS).parts))
#: ``tests/x/test_y.py`` or ``tests/x/test_y.py::test_name`` (a ``[param]`` after it is allowed)
TEST_REF = re.compile(r"\b(tests/[\w/]+\.py)(?:::(\w+))?")
BENCH_REF = re.compile(r"\b(benchmarks/\w+\.py)\b")
GENERATED = re.compile(r"^```\{generated\} (\w+)\n(:optional:\n)?", re.M)


def _functions(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {n.name for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_cited_tests_and_benchmarks_exist(page):
    text = page.read_text(encoding="utf-8")
    missing = []
    for path, name in TEST_REF.findall(text):
        if not (REPO / path).is_file():
            missing.append(path)
        elif name and name not in _functions(REPO / path):
            missing.append(f"{path}::{name}")
    # a benchmark the page shows as ``:optional:`` is another piece of work's, maybe not there yet
    optional = {f"benchmarks/{name}.py" for name, flag in GENERATED.findall(text) if flag}
    missing += [path for path in BENCH_REF.findall(text) if not (REPO / path).is_file() and path not in optional]
    assert not missing, f"{page.relative_to(REPO)} cites what does not exist: {missing}"


def test_every_shown_benchmark_writes_its_table_and_is_run_by_write_docs():
    import importlib.util

    spec = importlib.util.spec_from_file_location("write_docs", REPO / "benchmarks" / "write_docs.py")
    write_docs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(write_docs)
    shown = GENERATED.findall((DOCS / "benchmarks.md").read_text(encoding="utf-8"))
    assert len(shown) > 10
    for name, optional in shown:
        if optional:
            continue
        script = (REPO / "benchmarks" / f"{name}.py").read_text(encoding="utf-8")
        assert "write_docs_option" in script or "docs_output.write" in script, name
        assert name in write_docs.BENCHMARKS, f"benchmarks/write_docs.py does not run {name}"
        assert (DOCS / "_generated" / f"{name}.md").is_file(), f"no table of {name}: run it with --write-docs"
    assert set(write_docs.BENCHMARKS) <= {name for name, _ in shown}, "write_docs runs a table no page shows"
