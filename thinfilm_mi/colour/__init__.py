"""The colour layer: colorimetry of stacks with colour-science (the colour report).

* :mod:`thinfilm_mi.colour.report` -- CIE XYZ, xy, L*a*b*, sRGB swatches of ``R``/``T``.
"""
from thinfilm_mi.colour.report import colour_report, spectrum_colour

__all__ = ["colour_report", "spectrum_colour"]
