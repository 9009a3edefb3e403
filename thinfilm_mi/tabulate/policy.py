"""When ``tabulate`` builds a table and within which budgets: every threshold of the policy, in one place.

A side of a stack is tabulated by ``tabulate="auto"`` from a number of films (``*_MIN_FILMS``)
and within a size (``AUTO_MAX_*``) at which a lookup renders faster than the exact
recursion, but after an edit not for a side of :data:`EDIT_EXACT_MIN_FILMS` films or more;
every build, ``auto`` or ``true``, spends at most a budget of exact evaluations
(``MAX_BUILD_*``, times :data:`REQUESTED_BUDGET_SCALE` for ``true``). The plugins' doc rows
(:mod:`thinfilm_mi.render.doc_rows`) and the tables guide (``docs/guides/tables.md``) quote
these values through :func:`fill`, never as literals (``tests/cross/test_docblocks.py``).
The timings behind them are on the generated benchmark pages; how they moved, in CHANGELOG.md.
"""
from __future__ import annotations

import re

__all__ = ["AUTO_MAX_TEXELS", "AUTO_MIN_FILMS", "COATING_RT_MIN_FILMS", "EDIT_EXACT_MIN_FILMS",
           "LINEAR_MAX_FLOATS", "MAX_BUILD_POINTS", "MAX_BUILD_SECONDS", "MAX_BUILD_WORK", "MAX_TEXELS",
           "MIRROR_AUTO_MIN_FILMS", "MUELLER_AUTO_MAX_FLOATS", "MUELLER_AUTO_MIN_FILMS", "PLACEHOLDER",
           "REQUESTED_BUDGET_SCALE", "RT_AUTO_MIN_FILMS", "fill", "prose_values"]

#: A table of ``R`` alone (one channel) pays from one film: its lookup costs less than the
#: exact recursion of a single film.
AUTO_MIN_FILMS = 1
#: A table of ``R`` and ``T`` (two channels, read bilinearly) costs about what the exact
#: recursion of three films does, so it pays from four.
RT_AUTO_MIN_FILMS = 4
#: A lossless stack between media of constant index, whose both sides one table of ``R``
#: serves (:mod:`thinfilm_mi.render.mirror`), pays from as many films as a table of ``R``
#: and ``T``: its exact path is one real-amplitude recursion per lane.
MIRROR_AUTO_MIN_FILMS = 4
#: ``thinfilm_diffuse``'s coating: its factor table stands in for the coating's own tables
#: in spectral JIT variants, so a table of fewer films would be built at load and not read.
COATING_RT_MIN_FILMS = 5
#: A Mueller lookup (4 channels or more) costs what the exact amplitudes of tens of films do;
#: from this many the exact path is clearly the dearer.
MUELLER_AUTO_MIN_FILMS = 40
#: After an edit (``parameters_changed``) ``auto`` builds no table for a side of this many
#: films or more, which is then evaluated exactly unless a table of its new values is
#: cached: from here a rebuild costs more renders than an edit is worth (more with every
#: film), where a shallower side's costs a few and keeps its table.
EDIT_EXACT_MIN_FILMS = 4
#: ``auto`` keeps tables of the powers within this many texels over all channels (2 MiB of
#: float32): a lookup in a table that fits the cache is cheaper than the recursion, one
#: beyond it is not.
AUTO_MAX_TEXELS = 1 << 19
#: ``auto`` keeps Mueller tables within this many floats (8 MiB): a lookup slows with the
#: size, but the exact amplitudes of the deep stacks that need such tables cost more.
MUELLER_AUTO_MAX_FLOATS = 1 << 21
#: Spectral tables of the powers are resampled for bilinear lookups (4 texels a wavelength
#: instead of 16) where that takes at most this many floats; beyond it the spline stays,
#: as a bilinear lookup in a larger table is no cheaper.
LINEAR_MAX_FLOATS = 1 << 21
#: The largest table any build makes (texels per channel, ``tabulate=true``'s limit);
#: a stack that needs more is evaluated exactly.
MAX_TEXELS = 1 << 22
#: Exact evaluations one build may spend (probe, nodes and checks of every round), so that
#: a stack with sharp resonances is evaluated exactly instead of waiting on its table.
MAX_BUILD_POINTS = 3_000_000
#: Work (:func:`~thinfilm_mi.tabulate.refine.build_work`, film units) one build may spend,
#: decided before the work where it can be predicted, so that a deep stack is evaluated
#: exactly at once instead of spending seconds on a table the budget then rejects.
MAX_BUILD_WORK = 100_000_000
#: The wall time (s, two cores) :data:`MAX_BUILD_WORK` stands for: the wait the docs quote.
MAX_BUILD_SECONDS = 2
#: ``tabulate=true`` lets a build spend this many times :data:`MAX_BUILD_POINTS` and
#: :data:`MAX_BUILD_WORK`: a table asked for is worth a longer wait, paid once with the
#: table store.
REQUESTED_BUDGET_SCALE = 10.0

#: A number in prose that stands for a constant: ``{policy.NAME}``, NAME a key of
#: :func:`prose_values`.
PLACEHOLDER = re.compile(r"\{policy\.(\w+)\}")


def _power_of_two(n: int) -> str:
    """``n`` as ``2^k`` (it must be a power of two)."""
    if n <= 0 or n & (n - 1):
        raise ValueError(f"policy: {n} is not a power of two")
    return f"2^{n.bit_length() - 1}"


def _mib(floats: int) -> str:
    """The size of ``floats`` float32 values in MiB, as prose writes it."""
    return f"{floats * 4 / 2 ** 20:g}"


def prose_values() -> dict[str, str]:
    """Placeholder name -> the text the docs show for it, each from a constant of this module."""
    return {
        "AUTO_MIN_FILMS": str(AUTO_MIN_FILMS),
        "RT_AUTO_MIN_FILMS": str(RT_AUTO_MIN_FILMS),
        "MIRROR_AUTO_MIN_FILMS": str(MIRROR_AUTO_MIN_FILMS),
        "COATING_RT_MIN_FILMS": str(COATING_RT_MIN_FILMS),
        "EDIT_EXACT_MIN_FILMS": str(EDIT_EXACT_MIN_FILMS),
        "MUELLER_AUTO_MIN_FILMS": str(MUELLER_AUTO_MIN_FILMS),
        "AUTO_MAX_TEXELS": _power_of_two(AUTO_MAX_TEXELS),
        "AUTO_MAX_TEXELS_MIB": _mib(AUTO_MAX_TEXELS),
        "MUELLER_AUTO_MAX_FLOATS": _power_of_two(MUELLER_AUTO_MAX_FLOATS),
        "MUELLER_AUTO_MAX_MIB": _mib(MUELLER_AUTO_MAX_FLOATS),
        "LINEAR_MAX_MIB": _mib(LINEAR_MAX_FLOATS),
        "MAX_TEXELS": _power_of_two(MAX_TEXELS),
        "MAX_BUILD_SECONDS": f"{MAX_BUILD_SECONDS:g}",
        "REQUESTED_BUDGET_SCALE": f"{REQUESTED_BUDGET_SCALE:g}",
    }


def fill(text: str) -> str:
    """``text`` with every ``{policy.NAME}`` replaced by :func:`prose_values`'s text for NAME."""
    values = prose_values()

    def value(match: re.Match) -> str:
        if match.group(1) not in values:
            raise KeyError(f"policy.fill: {match.group(0)} names no constant (one of {sorted(values)})")
        return values[match.group(1)]
    return PLACEHOLDER.sub(value, text)
