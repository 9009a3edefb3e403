"""Sphinx extension: ``generated``, the directive that shows a benchmark's generated tables.

In a MyST page::

    ```{generated} render_bench
    ```

parses ``docs/_generated/render_bench.md`` (written by ``python benchmarks/render_bench.py
--write-docs``; ``benchmarks/docs_output.py``) as Markdown where the directive stands, and
makes the page depend on it (an incremental build redoes the page when a benchmark writes
it again). A missing file is an error, so a stale reference fails the ``-W`` build, unless
the directive says ``:optional:`` (a benchmark another piece of work adds): then the page
says that no run is recorded yet and which command records one.
"""
from __future__ import annotations

from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective

__all__ = ["Generated", "setup"]

#: the include files' folder
GENERATED = Path(__file__).resolve().parents[1] / "_generated"


class Generated(SphinxDirective):
    """``{generated} NAME``: the Markdown of ``docs/_generated/NAME.md``, parsed in place."""

    required_arguments = 1
    option_spec = {"optional": directives.flag}

    def run(self):
        name = self.arguments[0]
        path = GENERATED / f"{name}.md"
        if not path.is_file():
            if "optional" not in self.options:
                raise self.error(f"generated: {path} does not exist "
                                 f"(python benchmarks/{name}.py --write-docs writes it)")
            return [nodes.paragraph(text=f"No run of benchmarks/{name}.py is recorded yet: "
                                         f"python benchmarks/{name}.py --write-docs records one.")]
        self.env.note_dependency(str(path))
        node = nodes.container(classes=["generated-benchmark"])
        text = path.read_text(encoding="utf-8").splitlines()
        self.state.nested_parse(StringList(text, str(path)), 0, node)
        return [node]


def setup(app):
    app.add_directive("generated", Generated)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
