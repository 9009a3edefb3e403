"""Sphinx extension: ``policy``, the directive that writes the ``tabulate`` policy's numbers.

In a MyST page::

    ```{policy}
    `auto` tabulates a side of `R` alone from {policy.AUTO_MIN_FILMS} film.
    ```

parses its content as Markdown where the directive stands, each ``{policy.NAME}``
replaced by :func:`thinfilm_mi.tabulate.policy.fill` with the constant's text, so the
page quotes the code's values and never a copy of them (``tests/cross/test_docblocks.py``
fails on a literal in the content). An unknown NAME is an error, so it fails the ``-W``
build.
"""
from __future__ import annotations

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective

from thinfilm_mi.tabulate import policy

__all__ = ["Policy", "setup"]


class Policy(SphinxDirective):
    """``{policy}``: its content, with the policy's placeholders filled, parsed in place."""

    has_content = True

    def run(self):
        try:
            text = policy.fill("\n".join(self.content))
        except KeyError as error:
            raise self.error(str(error)) from error
        node = nodes.container(classes=["tabulate-policy"])
        self.state.nested_parse(StringList(text.splitlines(), self.get_source_info()[0]),
                                self.content_offset, node)
        return [node]


def setup(app):
    app.add_directive("policy", Policy)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
