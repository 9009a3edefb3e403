"""optics.polarization: the registry of polarisations and each component's admittance."""
from __future__ import annotations

import numpy as np
import pytest
import tmm

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.core import COMPONENTS
from thinfilm_mi.optics.polarization import POLARIZATIONS, UNPOLARIZED, P, S, as_polarization


def test_registry_and_parsing():
    assert list(POLARIZATIONS) == ["unpolarized", "s", "p"]
    for text in ("unpolarized", "Unpolarised", "u", " U "):
        assert as_polarization(text) is UNPOLARIZED
    assert as_polarization("S") is S and as_polarization("p") is P
    assert as_polarization(P) is P
    with pytest.raises(ThinFilmError, match=r"^polarization: expected one of unpolarized, s, p, got 'x'$"):
        as_polarization("x")
    with pytest.raises(ThinFilmError, match=r"^pol: "):
        as_polarization("both", "pol")


def test_components_labels_descriptions():
    assert UNPOLARIZED.components == (S, P)
    # the recursion's per-component results are keyed by the components' names
    assert tuple(c.name for c in UNPOLARIZED.components) == COMPONENTS
    assert S.components == (S,) and P.components == (P,)
    assert [UNPOLARIZED.label("R"), S.label("R"), P.label("T")] == ["R", "Rs", "Tp"]
    assert [UNPOLARIZED.describe(), S.describe(), P.describe()] == ["", "s-pol", "p-pol"]


@pytest.mark.parametrize("angle", [0.0, 30.0, 60.0, 85.0])
def test_interface_reflectance_from_admittances_against_tmm(angle):
    """``r = (eta_0 - eta_1) / (eta_0 + eta_1)`` of one interface, against tmm's coh_tmm."""
    n0, n1 = 1.0 + 0j, 1.7 + 0.3j
    beta2 = (n0.real * np.sin(np.radians(angle))) ** 2
    for comp in (S, P):
        q0, q1 = np.sqrt(n0 * n0 - beta2), np.sqrt(n1 * n1 - beta2)     # both decaying roots here (Im >= 0)
        e0, e1 = comp.admittance(n0, q0), comp.admittance(n1, q1)
        R = abs((e0 - e1) / (e0 + e1)) ** 2
        want = tmm.coh_tmm(comp.name, [n0, n1], [np.inf, np.inf], np.radians(angle), 550.0)["R"]
        # two float64 closed forms of the same quantity: they agree to rounding
        assert abs(R - want) < 1e-13, (comp.name, R, want)


@pytest.mark.parametrize("comp", [S, P], ids=["s", "p"])
def test_admittance_derivative_against_central_difference(comp):
    beta2 = 0.6
    for n in (1.45 + 0j, 2.3 + 0.02j, 0.2 + 3.1j):
        for dn in (1.0, 1j):
            q = np.sqrt(n * n - beta2)
            dq = n * dn / q
            h = 1e-6
            fd = (comp.admittance(n + h * dn, np.sqrt((n + h * dn) ** 2 - beta2))
                  - comp.admittance(n - h * dn, np.sqrt((n - h * dn) ** 2 - beta2))) / (2 * h)
            # central difference: truncation ~h^2 |f'''| ~ 1e-12, rounding ~1e-16 / h ~ 1e-10
            assert abs(comp.admittance_derivative(n, q, dn, dq) - fd) <= 1e-8 * max(1.0, abs(fd))
