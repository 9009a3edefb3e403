"""The command-line layer: commands over one parser class, one error report and
one progress bar.

* :mod:`thinfilm_mi.cli.render` -- ``thinfilm-render``: render scene files.
* :mod:`thinfilm_mi.cli.sweep` -- ``thinfilm-render sweep``: parameter grids on Dask.
* :mod:`thinfilm_mi.cli.tools` -- ``python -m thinfilm_mi``: spectrum, colour, materials,
  demo and the other tool commands.
* :mod:`thinfilm_mi.cli.parser` -- what they share: :class:`~thinfilm_mi.cli.parser.ArgumentParser`
  (errors raised, not printed) and :func:`~thinfilm_mi.cli.parser.report_error` (one line,
  the exit status of each error class).

The work itself is the batch layer's (:mod:`thinfilm_mi.batch`); the progress bar is
:func:`thinfilm_mi.batch.scene.progress_bar` (tqdm).
"""
__all__: list[str] = []


def render_main(argv=None) -> int:
    """``thinfilm-render`` (:func:`thinfilm_mi.cli.render.render_main`)."""
    from thinfilm_mi.cli.render import render_main as main

    return main(argv)


def main(argv=None) -> int:
    """``python -m thinfilm_mi`` (:func:`thinfilm_mi.cli.tools.main`)."""
    from thinfilm_mi.cli.tools import main as tools_main

    return tools_main(argv)


__all__ = ["main", "render_main"]
