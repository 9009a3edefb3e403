"""The multilayer optics core: one Rouard recursion, generic over array types.

Everything here works on *any* real array type that supports ``+ - * /`` and the
Dr.Jit math functions: Python floats (Mitsuba's ``scalar_*`` variants),
``drjit.llvm.Float`` / ``mi.Float`` (the float32 path traced into a render
kernel), ``mi.Spectrum`` (four wavelengths at once), and ``drjit.llvm.Float64``
(the float64 reference behind the numpy API in :mod:`thinfilm_mi.stack`). The
same source therefore runs in the kernel and in the reference, so a test of one
is a test of the other up to rounding.

Complex numbers are carried as :class:`Cx`, a pair ``(re, im)`` of such real
arrays, rather than Dr.Jit's ``Complex2f``: a pair of ``Spectrum`` arrays is a
complex spectrum, which ``Complex2f`` cannot express, and every branch choice
(square root, exponential) is made explicitly here instead of by a library.

Conventions (those of Born & Wolf and of tmm's ``tmm_core.py``):

* refractive index ``n + ik`` with ``k >= 0`` (absorption); the ambient medium
  (where light comes from) has a real index ``n0 > 0``;
* time dependence ``exp(-i w t)``, so a plane wave in layer ``j`` goes as
  ``exp(i 2 pi q_j z / lambda)`` with ``q_j = n_j cos(theta_j)
  = sqrt(n_j^2 - n0^2 sin^2 theta0)``; of the two roots we always take the
  decaying one (``Im q > 0``, or ``Im q = 0`` and ``Re q >= 0``), chosen
  explicitly in :func:`sqrt_decaying`, never by trusting a principal branch;
* the phase factor of a film is ``exp(i delta)`` with ``delta = 2 pi q d /
  lambda``; because ``Im q >= 0``, ``|exp(2 i delta)| <= 1`` and nothing can
  overflow, however thick or evanescent the layer. There are no transfer-matrix
  products (whose entries grow like ``exp(|Im delta|)`` and overflow in float32);
* Fresnel amplitudes for the s (TE) and p (TM) components of the electric field,
  with tmm's signs: ``r_s = (q_a - q_b)/(q_a + q_b)``,
  ``r_p = (n_b^2 q_a - n_a^2 q_b)/(n_b^2 q_a + n_a^2 q_b)`` (so ``r_p = -r_s`` at
  normal incidence), ``t_s = 2 q_a/(q_a + q_b)``,
  ``t_p = 2 n_a n_b q_a / (n_b^2 q_a + n_a^2 q_b)``;
* ``T`` is the time-averaged power flux (Poynting vector, z component) entering
  the exit medium, divided by the incident flux.

Reference: H. Hirayama, K. Kaneda, H. Yamashita, Y. Monden, "Visualization of
optical phenomena of objects coated with multilayer films" (eq. 1-6 and
appendix A), and M. Born, E. Wolf, *Principles of Optics*, sec. 1.6.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import drjit as dr

__all__ = [
    "Cx",
    "sqrt_decaying",
    "normal_index",
    "fresnel_s",
    "fresnel_p",
    "StackAmplitudes",
    "stack_amplitudes",
    "stack_rt",
    "film_attenuation",
    "transmittance_factor_s",
    "transmittance_factor_p",
]


class Cx:
    """A complex number (or array of them) as a pair of real arrays.

    ``re`` and ``im`` may be Python floats or any Dr.Jit real array type; mixed
    arithmetic with plain reals (floats or arrays) is supported.
    """

    __slots__ = ("re", "im")

    def __init__(self, re: Any, im: Any = 0.0):
        self.re = re
        self.im = im

    @staticmethod
    def of(value: Any) -> "Cx":
        """Wrap ``value`` (a :class:`Cx`, a Python complex, or a real) as :class:`Cx`."""
        if isinstance(value, Cx):
            return value
        if isinstance(value, complex):
            return Cx(value.real, value.imag)
        return Cx(value, 0.0)

    def __add__(self, o):
        if isinstance(o, Cx):
            return Cx(self.re + o.re, self.im + o.im)
        return Cx(self.re + o, self.im)

    __radd__ = __add__

    def __sub__(self, o):
        if isinstance(o, Cx):
            return Cx(self.re - o.re, self.im - o.im)
        return Cx(self.re - o, self.im)

    def __rsub__(self, o):
        return Cx(o - self.re, -self.im)

    def __neg__(self):
        return Cx(-self.re, -self.im)

    def __mul__(self, o):
        if isinstance(o, Cx):
            return Cx(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
        return Cx(self.re * o, self.im * o)

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, Cx):
            inv = 1.0 / (o.re * o.re + o.im * o.im)
            return Cx((self.re * o.re + self.im * o.im) * inv,
                      (self.im * o.re - self.re * o.im) * inv)
        inv = 1.0 / o
        return Cx(self.re * inv, self.im * inv)

    def __rtruediv__(self, o):
        return Cx.of(o) / self

    def conj(self) -> "Cx":
        return Cx(self.re, -self.im)

    def abs2(self):
        """``|z|^2``."""
        return self.re * self.re + self.im * self.im

    def square(self) -> "Cx":
        return Cx(self.re * self.re - self.im * self.im, 2.0 * self.re * self.im)

    def select(self, mask, other: "Cx") -> "Cx":
        """Elementwise ``self if mask else other``."""
        other = Cx.of(other)
        return Cx(dr.select(mask, self.re, other.re), dr.select(mask, self.im, other.im))

    def __repr__(self) -> str:
        return f"Cx({self.re!r}, {self.im!r})"


def sqrt_decaying(z: Cx) -> Cx:
    """The square root ``w`` of ``z`` with ``Im w > 0``, or ``Im w = 0`` and ``Re w >= 0``.

    This is the root of ``q^2 = n^2 - n0^2 sin^2 theta0`` that describes a wave
    decaying (or propagating) away from the interface. It is *not* the principal
    root when ``Im z < 0``, and it does not depend on the sign of a zero
    imaginary part (``sqrt(-1 - 0j)`` is ``+i`` here, ``-i`` for numpy).

    Computed without cancellation: the larger of ``|Re w|``, ``|Im w|`` comes
    from ``sqrt((|z| + |Re z|)/2)`` and the smaller from ``|Im z| / (2 * larger)``.
    """
    x, y = z.re, z.im
    ay = dr.abs(y)
    m = dr.sqrt(x * x + y * y)
    big = dr.sqrt(0.5 * (m + dr.abs(x)))
    small = dr.select(big > 0, ay / (2.0 * dr.select(big > 0, big, 1.0)), 0.0)
    re = dr.select(x >= 0, big, small)   # root of x + i|y| with Re >= 0, Im >= 0
    im = dr.select(x >= 0, small, big)
    return Cx(dr.select(y < 0, -re, re), im)


def normal_index(n: Cx, beta2) -> Cx:
    """``q = n cos(theta) = sqrt(n^2 - beta^2)``, decaying root, with ``beta = n0 sin(theta0)``.

    ``beta`` is the tangential wave-vector component conserved by Snell's law;
    ``beta2`` its square (real).
    """
    n = Cx.of(n)
    return sqrt_decaying(Cx(n.re * n.re - n.im * n.im - beta2, 2.0 * n.re * n.im))


def fresnel_s(qa: Cx, qb: Cx):
    """s (TE) amplitudes ``(r, t)`` from medium a into medium b."""
    inv = 1.0 / (qa + qb)
    return (qa - qb) * inv, (2.0 * qa) * inv


def fresnel_p(qa: Cx, qb: Cx, na: Cx, nb: Cx, na2: Cx | None = None, nb2: Cx | None = None):
    """p (TM) amplitudes ``(r, t)`` from medium a into medium b (tmm's sign convention)."""
    na2 = na.square() if na2 is None else na2
    nb2 = nb.square() if nb2 is None else nb2
    a = nb2 * qa
    b = na2 * qb
    inv = 1.0 / (a + b)
    return (a - b) * inv, (2.0 * (na * nb) * qa) * inv


def transmittance_factor_s(q_exit: Cx, q0):
    """Power factor ``Re(q_exit) / q0`` that turns ``|t_s|^2`` into transmittance.

    This is the paper's eq. 6 for a real exit index and its appendix A-20/A-21
    (``n Re s_z - k Im s_z = Re(n s_z) = Re q``) for an absorbing one.
    """
    return q_exit.re / q0


def transmittance_factor_p(n_exit: Cx, q_exit: Cx, q0, n0=None):
    """Power factor that turns ``|t_p|^2`` (ratio of electric-field amplitudes) into
    transmittance: ``Re(n_exit * conj(cos theta_exit)) / (n0 cos theta0)``.

    With ``cos theta_exit = q_exit / n_exit`` this is
    ``Re(n_exit^2 conj(q_exit)) / |n_exit|^2 / q0``; it equals the s factor for a real
    exit index. For an absorbing exit medium it is the exact z-flux of the
    Poynting vector (the appendix's A-21 applies ``Re q`` to both polarisations,
    which is exact for s only).
    """
    n2 = n_exit.square()
    num = n2.re * q_exit.re + n2.im * q_exit.im  # Re(n^2 * conj(q))
    return num / n_exit.abs2() / q0


@dataclass
class StackAmplitudes:
    """Composite amplitudes of a stack and what is needed to turn them into powers."""

    rs: Cx | None
    rp: Cx | None
    ts: Cx | None
    tp: Cx | None
    q0: Any            # n0 cos(theta0), real
    q_exit: Cx         # n_exit cos(theta_exit), decaying root
    n_exit: Cx
    grazing: Any       # mask: cos(theta0) <= 0 (R = 1, T = 0 exactly)


def _exp_i(delta: Cx) -> Cx:
    """``exp(i delta)`` for ``Im delta >= 0``: modulus ``exp(-Im delta) <= 1``."""
    mag = dr.exp(-delta.im)
    s, c = dr.sincos(delta.re)
    return Cx(mag * c, mag * s)


def stack_amplitudes(
    n0,
    cos0,
    films: Sequence[tuple[Any, Any]],
    n_exit,
    wavelength,
    *,
    s: bool = True,
    p: bool = True,
    transmission: bool = True,
) -> StackAmplitudes:
    """Composite reflection and transmission amplitudes of a thin-film stack.

    Parameters
    ----------
    n0 : real (float or array)
        Index of the ambient medium the light comes from (must be real, > 0).
    cos0 : real array, in [0, 1]
        Cosine of the angle of incidence in the ambient medium.
    films : sequence of (index, thickness)
        The films from the ambient side inwards; ``index`` is a :class:`Cx`, a
        Python complex or a real, ``thickness`` in the same unit as ``wavelength``.
    n_exit : Cx, complex or real
        Index of the exit medium (the substrate); may be absorbing.
    wavelength : real
        Vacuum wavelength (same unit as the thicknesses).
    s, p : bool
        Which polarisations to compute (skipped ones are ``None``).
    transmission : bool
        Whether to carry the transmission amplitude (skipped: ``ts = tp = None``).

    The recursion is the paper's eq. 1-4: starting from the innermost interface,
    ``gamma <- (r_j + gamma E_j) / (1 + r_j gamma E_j)`` and
    ``tau <- t_j tau sqrt(E_j) / (1 + r_j gamma E_j)`` with
    ``E_j = exp(2 i delta_j)``, ``delta_j = 2 pi q_j d_j / lambda``.
    """
    cos0 = dr.clip(cos0, 0.0, 1.0)
    sin2 = (1.0 - cos0) * (1.0 + cos0)
    beta2 = n0 * n0 * sin2
    q0 = n0 * cos0

    n_amb = Cx.of(n0)
    media = [n_amb] + [Cx.of(n) for n, _ in films] + [Cx.of(n_exit)]
    qs = [Cx(q0, 0.0)] + [normal_index(m, beta2) for m in media[1:]]
    sq = [m.square() for m in media] if p else None
    k0 = 2.0 * math.pi / wavelength

    # Innermost interface first (between the last film and the exit medium).
    last = len(media) - 2
    out = {}
    for pol, on in (("s", s), ("p", p)):
        if not on:
            out[pol] = (None, None)
            continue

        def iface(j):
            if pol == "s":
                return fresnel_s(qs[j], qs[j + 1])
            return fresnel_p(qs[j], qs[j + 1], media[j], media[j + 1], sq[j], sq[j + 1])

        gamma, tau = iface(last)
        if not transmission:
            tau = None
        for j in range(last - 1, -1, -1):
            n_film, d = films[j]
            e1 = _exp_i(qs[j + 1] * (k0 * d))
            e2 = e1.square()
            r, t = iface(j)
            ge = gamma * e2
            inv = 1.0 / (1.0 + r * ge)
            gamma = (r + ge) * inv
            if tau is not None:
                tau = (t * tau * e1) * inv
        out[pol] = (gamma, tau)

    grazing = cos0 <= 0.0
    rs, ts = out["s"]
    rp, tp = out["p"]
    minus_one = Cx(-1.0, 0.0)
    zero = Cx(0.0, 0.0)
    if rs is not None:
        rs = minus_one.select(grazing, rs)
    if rp is not None:
        rp = minus_one.select(grazing, rp)
    if ts is not None:
        ts = zero.select(grazing, ts)
    if tp is not None:
        tp = zero.select(grazing, tp)
    return StackAmplitudes(rs, rp, ts, tp, q0, qs[-1], media[-1], grazing)


def stack_rt(n0, cos0, films, n_exit, wavelength, *, transmission: bool = True):
    """Reflectance and transmittance ``(Rs, Rp, Ts, Tp)`` of a stack (energy fractions).

    ``Rs = |r_s|^2`` and ``Rp = |r_p|^2`` (eq. 5 averages them for unpolarised
    light); ``Ts, Tp`` are the powers entering the exit medium (eq. 6 and
    appendix A-21, with the exact p factor of :func:`transmittance_factor_p`).
    When ``transmission`` is false, ``Ts = Tp = None`` and no transmission work
    is done. At grazing incidence ``R = 1`` and ``T = 0`` exactly.
    """
    a = stack_amplitudes(n0, cos0, films, n_exit, wavelength, transmission=transmission)
    Rs = dr.minimum(a.rs.abs2(), 1.0)
    Rp = dr.minimum(a.rp.abs2(), 1.0)
    if not transmission:
        return Rs, Rp, None, None
    q0 = dr.select(a.grazing, 1.0, a.q0)
    Ts = a.ts.abs2() * transmittance_factor_s(a.q_exit, q0)
    Tp = a.tp.abs2() * transmittance_factor_p(a.n_exit, a.q_exit, q0)
    Ts = dr.select(a.grazing, 0.0, dr.clip(Ts, 0.0, 1.0))
    Tp = dr.select(a.grazing, 0.0, dr.clip(Tp, 0.0, 1.0))
    return Rs, Rp, Ts, Tp


def film_attenuation(n0, cos0, n_film, thickness, wavelength):
    """Energy attenuation ``k_a`` through an absorbing film along the refracted direction.

    Appendix A-18 of the paper: ``k_a = exp(-2 phi_e)`` with
    ``phi_e = (2 pi / lambda) Im(n_hat s_z) d = (2 pi / lambda) Im(q) d`` for a
    film of thickness ``d``, where ``q = n_hat cos(theta)`` is the decaying root
    for light arriving at ``cos0`` from an ambient of index ``n0``. (The printed
    A-7 reads ``n Re s_z + k Im s_z``; expanding A-3 gives
    ``Im(n_hat s_z) = n Im s_z + k Re s_z``, which is what is used here, and what
    decays as the paper states, "parallel to the interface".) The attenuation is
    that of the power flux crossing the film once, i.e. the planes of constant
    amplitude are parallel to the interface whatever the angle.
    """
    cos0 = dr.clip(cos0, 0.0, 1.0)
    beta2 = n0 * n0 * (1.0 - cos0) * (1.0 + cos0)
    q = normal_index(Cx.of(n_film), beta2)
    return dr.exp(-(4.0 * math.pi / wavelength) * q.im * thickness)
