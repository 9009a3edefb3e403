"""Coating design: from target spectra and colours to a stack of films.

    >>> from thinfilm_mi import design
    >>> result = design.design("examples/design/ar.yml")       # doctest: +SKIP
    >>> result.layers, result.merit                              # doctest: +SKIP
    ('1.38 99.2667; 2.35 36.1176; ...', 0.31)

A targets file (:mod:`.targets`) names the media, the film materials and the
targets (R, T, A, luminous Y, colour), each with a tolerance. :func:`design`
synthesises a stack with needle optimisation and refines it on exact gradients
(:mod:`.synthesis`, :mod:`.merit`, :mod:`.matrices`); :func:`refine` and
:func:`evaluate` take a given stack; :func:`parse_tolerance` and
:func:`tolerance_analysis` do Monte-Carlo thickness errors. The command line is
``python -m thinfilm_mi design TARGETS.yml``. :func:`fit` goes the other way:
from measured spectra (a measurements file, :mod:`.fitfile`) to the stack as
built, with standard errors (``python -m thinfilm_mi fit MEASUREMENTS.yml``).

This subpackage uses the optics conventions of :mod:`thinfilm_mi.optics.core`, the
materials of :mod:`thinfilm_mi.materials.catalog` and the colorimetry of
:mod:`thinfilm_mi.colour.report`; it renders nothing (``--render`` is the CLI's).
"""
from __future__ import annotations

from thinfilm_mi.design.api import design, evaluate, refine
from thinfilm_mi.design.fit import fit
from thinfilm_mi.design.fitfile import Measurement, load_measurements
from thinfilm_mi.design.fitresult import FitResult
from thinfilm_mi.design.merit import Design, Merit, TargetValues
from thinfilm_mi.design.result import DesignResult
from thinfilm_mi.design.targets import Problem, Target, load_problem
from thinfilm_mi.design.tolerance import ToleranceResult, ToleranceSpec, parse_tolerance, tolerance_analysis

__all__ = [
    "design", "refine", "evaluate", "load_problem", "Problem", "Target", "Design", "Merit",
    "TargetValues", "DesignResult", "parse_tolerance", "tolerance_analysis", "ToleranceSpec",
    "ToleranceResult", "fit", "load_measurements", "Measurement", "FitResult",
]
