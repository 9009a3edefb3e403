"""The plugins' shared parameter rows are written once, and quote the ``tabulate`` policy.

The rows of ``thickness``, ``tabulate``, ``table_error``, ``spectral_resolution`` and
``coherence_thickness`` live in :mod:`thinfilm_mi.render.doc_rows`;
``scripts/compose_docblocks.py`` writes them into each doc block that names its family
(``.. shared-rows: FAMILY``). Here: every BSDF of :data:`thinfilm_mi.plugins.PLUGINS` that
reads one of those properties has all five rows, and each equals the composition, so a
row edited in one doc block and not in the module (or the other way round) fails. And no
number of the ``tabulate`` policy is written as a literal, in the rows' templates or in the
``{policy}`` blocks of the docs: each is a ``{policy.NAME}`` filled from
:mod:`thinfilm_mi.tabulate.policy`, so tuning a constant cannot leave the prose wrong.
"""
from __future__ import annotations

import ast
import importlib.util
import re
import sys
from pathlib import Path

import pytest

from thinfilm_mi.plugins import PLUGINS
from thinfilm_mi.render.doc_rows import FAMILIES, SHARED_NAMES, shared_rows, templates
from thinfilm_mi.tabulate import policy

REPO = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("compose_docblocks", REPO / "scripts" / "compose_docblocks.py")
compose = importlib.util.module_from_spec(_spec)
sys.modules["compose_docblocks"] = compose
_spec.loader.exec_module(compose)

#: the property names the BSDFs read through render.reader's stack_options (measured by
#: tests/cross/test_docs.py, which checks that a doc block lists exactly what its plugin reads)
PATHS = {name: REPO / "thinfilm_mi" / "plugins" / f"{module}.py" for name, (module, _) in PLUGINS.items()}


def _listed(path: Path) -> set[str]:
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
    return {m.group(1).strip() for line in doc.splitlines() if (m := compose.ROW.match(line))}


@pytest.mark.parametrize("name", sorted(PATHS))
def test_doc_block_rows_equal_the_composition(name):
    path = PATHS[name]
    source = path.read_text(encoding="utf-8")
    listed = _listed(path)
    if not listed & set(SHARED_NAMES):
        pytest.skip(f"{name} reads none of the shared properties")
    assert set(SHARED_NAMES) <= listed, f"{name} lists {sorted(listed & set(SHARED_NAMES))} only"
    assert compose.composed(source, path) == source, (
        f"{path.name}: the shared rows of its doc block differ from thinfilm_mi/render/doc_rows.py; "
        "edit the rows there and run `python scripts/compose_docblocks.py`")


def test_every_film_stack_bsdf_shares_the_rows():
    # the five BSDFs of issue 40 all read a stack; a new one (the coating) joins by its reads
    sharing = [n for n, p in PATHS.items() if set(SHARED_NAMES) <= _listed(p)]
    assert {"thinfilm_conductor", "thinfilm_dielectric", "thinfilm_diffuse", "thinfilm_roughconductor",
            "thinfilm_roughdielectric"} <= set(sharing)


def test_a_row_edited_in_one_doc_block_is_found(tmp_path):
    path = PATHS["thinfilm_conductor"]
    source = path.read_text(encoding="utf-8")
    edited = source.replace("(default: 0.001)", "(default: 0.002)", 1)
    assert edited != source
    assert compose.composed(edited, path) == source   # the composition restores it
    assert compose.composed(source.replace(".. shared-rows: conductor", ".. shared-rows: dielectric"),
                            path) != source           # another family's text differs


def test_each_family_composes_every_row_and_only_those():
    for family in FAMILIES:
        rows = shared_rows(family)
        assert tuple(rows) == SHARED_NAMES
        for name, row in rows.items():
            lines = row.splitlines()
            assert lines[0] == f" * - {name}" and lines[1].startswith("   - |")
            assert all(len(line) <= 88 and line.startswith("   ") for line in lines[1:]), (family, name)
    with pytest.raises(Exception, match="family='metal'"):
        shared_rows("metal")


def test_a_doc_block_listing_shared_rows_without_a_family_is_refused():
    path = PATHS["thinfilm_conductor"]
    source = path.read_text(encoding="utf-8").replace(".. shared-rows: conductor\n", "", 1)
    with pytest.raises(ValueError, match="names no family"):
        compose.composed(source, path)


#: a number the policy could own, as prose writes one: films, a size, a time, a factor, 2^N
POLICY_NUMBER = re.compile(r"\d+(?:\.\d+)?\s*(?:films?|MiB|texels|floats|s|x|×)(?![\w-])|\d+\s*\^\s*\d+")
#: a ``{policy}`` block of a docs page (docs/_ext/thinfilm_policy.py fills it)
POLICY_BLOCK = re.compile(r"^```\{policy\}\n(.*?)^```", re.M | re.S)


def _literals(template: str) -> list[str]:
    """The policy-like numbers of ``template`` that are not placeholders."""
    return POLICY_NUMBER.findall(policy.PLACEHOLDER.sub("", template))


def _policy_blocks() -> dict[str, list[str]]:
    """docs page -> the contents of its ``{policy}`` blocks."""
    pages = sorted((REPO / "docs").rglob("*.md"))
    return {p.relative_to(REPO).as_posix(): POLICY_BLOCK.findall(p.read_text(encoding="utf-8")) for p in pages}


def test_the_rows_write_no_number_of_the_policy_as_a_literal():
    found = {t[:60]: _literals(t) for t in templates() if _literals(t)}
    assert not found, f"write these as {{policy.NAME}} (thinfilm_mi/tabulate/policy.py): {found}"


def test_the_docs_policy_blocks_write_no_number_as_a_literal():
    blocks = _policy_blocks()
    assert blocks["docs/guides/tables.md"], "the tables guide has lost its {policy} block"
    found = {page: _literals(b) for page, bs in blocks.items() for b in bs if _literals(b)}
    assert not found, f"write these as {{policy.NAME}} (thinfilm_mi/tabulate/policy.py): {found}"
    for bs in blocks.values():
        for b in bs:
            policy.fill(b)   # every placeholder names a constant (an unknown one raises)


def test_the_literal_check_sees_the_numbers_the_placeholders_become():
    # filled, the templates carry the policy's numbers, and the check finds them: a number
    # hard-coded where a placeholder stands would be found the same way
    guide = _policy_blocks()["docs/guides/tables.md"][0]
    assert len(_literals(policy.fill(guide))) >= 10
    assert any(_literals(policy.fill(t)) for t in templates())
    assert _literals("from 4 films within 2^19 texels, 8 MiB, ~2 s, 10x") == [
        "4 films", "2^19", "8 MiB", "2 s", "10x"]
