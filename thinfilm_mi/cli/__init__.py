"""The command-line layer.

* :mod:`thinfilm_mi.cli.render` -- ``thinfilm-render``: render scene files.
* :mod:`thinfilm_mi.cli.tools` -- ``python -m thinfilm_mi``: spectrum, colour, materials,
  demo and the other tool commands.
"""
