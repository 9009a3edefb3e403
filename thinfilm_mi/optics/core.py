"""The multilayer optics core: one Rouard recursion, generic over array types.

Everything here works on *any* real array type that supports ``+ - * /`` and the
Dr.Jit math functions: Python floats (Mitsuba's ``scalar_*`` variants),
``drjit.llvm.Float`` / ``mi.Float`` (the float32 path traced into a render
kernel), ``mi.Spectrum`` (four wavelengths at once), and ``drjit.llvm.Float64``
(the float64 reference behind the numpy API in :mod:`thinfilm_mi.materials.stack`). The
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

Mitsuba's polarized Fresnel code (``fresnel_polarized``, ``mueller.h``) works with
``n - ik`` and the root ``Im cos(theta_t) <= 0`` (time dependence ``exp(+i w t)``),
with the same s/p signs (its "Verdet convention" ``a_p`` is tmm's ``r_p``). A field
``Re(a exp(-i w t))`` is ``Re(conj(a) exp(+i w t))``, so **Mitsuba's amplitudes are
the complex conjugates of ours**: ``A_s = conj(r_s)``, ``A_p = conj(r_p)`` (and the
same for ``t``), which flips the sign of the s-p phase difference and hence of
``S3``. :mod:`thinfilm_mi.render.amplitudes` applies this map; tests/cross/test_polarized.py checks
it on bare interfaces (a conductor, glass from both sides, TIR) against
``mueller.specular_reflection`` and ``specular_transmission``.

The recursion comes in the forms that its callers need, each written once; they share
:func:`rouard_step`, the root choice and the guard of ``q = 0``, and differ in what the
arithmetic must carry:

* :func:`rouard_recursion`, the films unrolled at trace time (specialised on literal
  indices and :class:`FilmBounds`): complex amplitudes ``r, t`` for
  :func:`stack_amplitudes` (polarized paths), or the power form (``|T|^2`` only, no phase
  of ``t``) for :func:`stack_rt`;
* :func:`stack_loop_terms` (:func:`stack_rt_loop`), a Dr.Jit loop over any films, kernel
  size independent of their number: the power form, rescaled by exact powers of two (and
  the smooth scaling the band-limited tables sample);
* :func:`stack_rt_loop_real`, the same loop for lossless films above the ambient: real
  Fresnel amplitudes, about half the work per film;
* :func:`thinfilm_mi.optics.mueller.amplitude_loop`, the loop with complex ``t`` (the
  Mueller cross terms need the phase of ``t_s conj(t_p)``), rescaled by ``1 / (|Re D| +
  |Im D|)``. Folding it into :func:`stack_loop_terms` would change one of the two
  rescalings, and so their float32 bits; the two share :class:`LoopIncidence` instead.

Reference: H. Hirayama, K. Kaneda, H. Yamashita, Y. Monden, "Visualization of
optical phenomena of objects coated with multilayer films" (eq. 1-6 and
appendix A), and M. Born, E. Wolf, *Principles of Optics*, sec. 1.6.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Sequence

import drjit as dr

__all__ = [
    "COMPONENTS",
    "Cx",
    "sqrt_decaying",
    "normal_index",
    "fresnel_s",
    "fresnel_p",
    "StackAmplitudes",
    "FilmBounds",
    "film_bounds",
    "UNBOUNDED",
    "stack_amplitudes",
    "stack_rt",
    "stack_rt_loop",
    "stack_loop_terms",
    "film_attenuation",
    "transmittance_factor_s",
    "transmittance_factor_p",
]

#: The linear components the recursion computes, in the order of its results (s, then
#: p): the keys of its per-component dicts. The polarisations of
#: :mod:`thinfilm_mi.optics.polarization` name their components alike.
COMPONENTS = ("s", "p")


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
        """``|z|^2`` (``re^2`` where the imaginary part is a literal 0)."""
        if is_zero(self.im):
            return self.re * self.re
        return self.re * self.re + self.im * self.im

    def square(self) -> "Cx":
        """``z^2``; a literal 0 imaginary part stays a literal 0 (traced code specialises
        on it: a real medium's products and inverses)."""
        if is_zero(self.im):
            return Cx(self.re * self.re, 0.0)
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
    # |y|; where y carries gradients, with the derivative +1 at y = 0 (dr.abs has
    # 0 there): the one-sided derivative on the side of loss (k >= 0), the only
    # one an index can take, so that d/dk at a lossless film (k = 0) is right
    ay = dr.select(y < 0, -y, y) if dr.grad_enabled(y) else dr.abs(y)
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


def is_zero(v) -> bool:
    """True if ``v`` is a Python number equal to 0 (known at trace time)."""
    return isinstance(v, (int, float)) and v == 0


def _is_literal(v) -> bool:
    return isinstance(v, (int, float))


def cmul(a: Cx, b: Cx) -> Cx:
    """``a * b``, skipping the products with imaginary parts that are a literal 0."""
    if is_zero(b.im):
        return Cx(a.re * b.re, 0.0 if is_zero(a.im) else a.im * b.re)
    if is_zero(a.im):
        return Cx(a.re * b.re, a.re * b.im)
    return Cx(a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re)


# sin(2 pi g) = g * P(g^2) and cos(2 pi g) = Q(g^2) for |g| <= 1/8 (a least-squares
# fit on 20001 points, done for this module; largest error 2.4e-8 and 7.9e-9 with
# the float32 coefficients, below float32's half ulp of 1).
_SIN_C = (6.2831854820251465, -41.341670989990234, 81.59429931640625, -75.4881591796875)
_COS_C = (1.0, -19.739208221435547, 64.9393310546875, -85.44435119628906, 59.273799896240234)


def _is_float32(x) -> bool:
    return dr.is_array_v(x) and dr.type_v(x) == dr.VarType.Float32


def _sincos_turns(x):
    """``(sin(2 pi x), cos(2 pi x))`` for a phase ``x`` given in turns.

    Float32 arrays use an exact reduction to the nearest quarter turn (``x -
    round(4x)/4`` is exact) and short polynomials: cheaper than a general
    ``sincos`` and as accurate, because the phase in turns needs no reduction by
    an inexact ``pi``. Other types (Python floats, float64) use ``dr.sincos`` of the
    phase reduced to the nearest turn the same way (``x - round(x)`` is exact): Dr.Jit's
    float64 ``sincos`` returns values far outside [-1, 1] beyond ~1e9 rad, e.g. for a film
    of 1e12 nm, where float32 already holds the phase as whole turns.
    """
    if not _is_float32(x):
        return dr.sincos((2.0 * math.pi) * (x - dr.round(x)))
    j = dr.round(4.0 * x)
    g = dr.fma(j, -0.25, x)
    z = g * g
    sp = dr.fma(dr.fma(dr.fma(_SIN_C[3], z, _SIN_C[2]), z, _SIN_C[1]), z, _SIN_C[0]) * g
    cp = dr.fma(dr.fma(dr.fma(dr.fma(_COS_C[4], z, _COS_C[3]), z, _COS_C[2]), z, _COS_C[1]), z,
                _COS_C[0])
    k = j - 4.0 * dr.floor(0.25 * j)  # quadrant 0..3 (exact)
    odd = (k == 1.0) | (k == 3.0)
    sw = dr.select(odd, cp, sp)
    cw = dr.select(odd, sp, cp)
    sin = dr.select(k >= 2.0, -sw, sw)
    cos = dr.select((k == 1.0) | (k == 2.0), -cw, cw)
    return sin, cos


def phase_factor(q: Cx, u, twice: bool) -> Cx:
    """``exp(i m 2 pi q u)`` with ``m = 2`` if ``twice`` else ``1``; ``u = d / lambda``.

    ``Im q >= 0`` so the modulus ``exp(-m 2 pi Im(q) u)`` is at most 1.
    """
    m = 2.0 if twice else 1.0
    s, c = _sincos_turns(q.re * (m * u))
    if is_zero(q.im):
        return Cx(c, s)
    mag = dr.exp((-2.0 * math.pi * m) * (q.im * u))
    return Cx(mag * c, mag * s)


def normal_index_bounded(n: Cx, beta2, beta2_max, n2_min=None) -> Cx:
    """:func:`normal_index`, specialised at trace time where the index is known.

    For a real index ``n`` (a literal, or an array with a literal zero
    imaginary part and a literal lower bound ``n2_min`` on ``n^2``) with ``n^2
    >= beta2_max`` (a literal bound on ``beta^2``, i.e. ``n >= n0``) the root is
    real for every angle and only one square root is traced; for any other real
    index (literal, or an array with a literal zero imaginary part) the decaying
    root of the real number ``n^2 - beta^2`` is ``sqrt(x)`` or ``i sqrt(-x)``.
    """
    if is_zero(n.im) and (_is_literal(n.re) or n2_min is not None):
        x = n.re * n.re - beta2
        lower = n.re * n.re if _is_literal(n.re) else n2_min
        if _is_literal(beta2_max) and lower >= beta2_max:
            return Cx(dr.sqrt(dr.maximum(x, 0.0)), 0.0)
        r = dr.sqrt(dr.abs(x))
        pos = x >= 0
        return Cx(dr.select(pos, r, 0.0), dr.select(pos, 0.0, r))
    return normal_index(n, beta2)


def cinv(z: Cx) -> Cx:
    """``1 / z`` (evaluated in Python for literals)."""
    if _is_literal(z.re) and _is_literal(z.im):
        w = 1.0 / complex(z.re, z.im)
        return Cx(w.real, w.imag)
    if is_zero(z.im):
        return Cx(1.0 / z.re, 0.0)
    inv = 1.0 / z.abs2()
    return Cx(z.re * inv, -z.im * inv)


#: The projective recursion rescales (N, D, T) after every _RESCALE films. Between
#: rescalings |D| changes at most by a factor (|a_j| + |a_j+1|)(1 + |gamma|) per
#: film (|q| <= 22 for |n| <= 21 and n0 <= 6) or shrinks by |a_j + a_j+1| |1 + r
#: gamma E| (>= ~1e-7 even at cos = 1e-7), so three films stay far inside
#: float32's range (1e-38 .. 3e38).
_RESCALE = 3


def rouard_step(a: Cx, b: Cx, E_b: Cx, N: Cx, D: Cx):
    """One Rouard step of :func:`rouard_recursion` in projective form: ``(N, D)`` of the
    stack seen from medium ``b`` (``gamma_b = N / D``) to those seen from the
    medium ``a`` above it; ``E_b = exp(2 i delta_b)`` is ``b``'s phase factor.

    ``N' = a P - b M``, ``D' = a P + b M`` with ``X = E_b N``, ``P = D + X``,
    ``M = D - X``: the paper's ``gamma <- (r + gamma E) / (1 + r gamma E)`` with
    ``r = (a - b)/(a + b)``, multiplied through by ``(a + b) D``.
    """
    X = cmul(E_b, N)
    P = D + X
    M = D - X
    aP = cmul(a, P)
    bM = cmul(b, M)
    return aP - bM, aP + bM


def _rescale_factor(D: Cx):
    """The projective rescaling: the power of two nearest ``1 / (|Re D| + |Im D|)``
    (within a factor 2), so that multiplying ``(N, D, T)`` by it is exact and
    adds no rounding to the recursion. It is a constant of the ratios (no
    gradient flows through it)."""
    return _inverse_power_of_two(dr.abs(D.re) + dr.abs(D.im))


def _smooth_scale(a: Cx, b: Cx, N: Cx, D: Cx, T, mag2):
    """:func:`stack_loop_terms`' smooth step factor: ``(N, D)`` times ``1 / sqrt(|a|^2
    + |b|^2)``, ``T`` (``None``: not traced) times ``4 |a|^2 mag2`` (the interface's
    ``|t|^2`` factor) and its square."""
    s2 = 1.0 / (a.abs2() + b.abs2())
    scale = dr.sqrt(s2)
    return N * scale, D * scale, None if T is None else T * (4.0 * a.abs2() * mag2 * s2)


def _exponent_of(scale):
    """``k`` (a float of the same type) for a power of two ``scale = 2^-k`` of
    :func:`_rescale_factor` (float64 or float32 arrays), from the exponent bits."""
    U = dr.uint_array_t(type(scale))
    bits = dr.reinterpret_array(U, scale)
    if dr.type_v(scale) == dr.VarType.Float32:
        return 127.0 - type(scale)(bits >> 23)
    return 1023.0 - type(scale)(bits >> 52)


def _inverse_power_of_two(x):
    """``2^-e`` for ``x = m 2^e``, ``1 <= m < 2`` (``x >= 0``; 2^127 or 2^1023 for 0),
    from the exponent bits: exact and cheap, no division."""
    if not dr.is_array_v(x):
        return 2.0 ** (1 - math.frexp(x)[1]) if x > 0 else 1.0
    if dr.depth_v(x) > 1:   # e.g. mi.Spectrum: per component
        return type(x)(*[_inverse_power_of_two(x[i]) for i in range(len(x))])
    x = dr.detach(x)
    U = dr.uint_array_t(type(x))
    bits = dr.reinterpret_array(U, x)
    if dr.type_v(x) == dr.VarType.Float32:
        # exponent field E (x >= 2^(E - 127)) -> 254 - E: 2^(127 - E), for E <= 253
        return dr.reinterpret_array(type(x), U(0x7F000000) - (bits & U(0x7F800000)))
    return dr.reinterpret_array(type(x), U(0x7FE0000000000000) - (bits & U(0x7FF0000000000000)))


def rouard_recursion(a: list, E: list, e1: list | None, t_power: list | None, zero_pairs: list):
    """The recursion in projective form, for one polarisation.

    ``a[j]`` is the admittance of medium ``j`` (``q_j`` for s, ``q_j / n_j^2``
    for p): the Fresnel amplitude from ``j`` into ``j + 1`` is ``(a_j -
    a_{j+1})/(a_j + a_{j+1})`` and the transmission amplitude ``2 a_j / (a_j +
    a_{j+1})`` (times ``n_j / n_{j+1}`` for p). ``E[j] = exp(2 i delta_j)`` and
    ``e1[j] = exp(i delta_j)`` for the films. The composite reflection amplitude
    seen from medium ``j`` is ``gamma_j = N_j / D_j`` and the transmission
    amplitude ``tau_j = 2^(L+1-j) T_j / D_j`` (times the telescoped ``n_j /
    n_exit`` for p). Substituting the Fresnel amplitudes into the Rouard step

        gamma_j = (r + gamma_{j+1} E) / (1 + r gamma_{j+1} E),
        tau_j   = t e1 tau_{j+1} / (1 + r gamma_{j+1} E)

    and multiplying through by ``(a_j + a_{j+1}) D_{j+1}`` gives, with
    ``X = E N_{j+1}``, ``P = D_{j+1} + X``, ``M = D_{j+1} - X``:

        N_j = a_j P - a_{j+1} M,   D_j = a_j P + a_{j+1} M,   T_j = a_j e1 T_{j+1}

    -- no division per interface. Every ``_RESCALE`` films ``(N, D, T)`` are
    rescaled by ``1 / (|Re D| + |Im D|)`` (the ratios do not change) so that
    nothing overflows or underflows in float32 however many films there are.

    With ``t_power`` (a list of ``|a_j|^2 |e1_j|^2`` factors) instead of ``e1``,
    ``T`` is the real ``|T|^2`` (``|T_j|^2 = |a_j|^2 |e1|^2 |T_{j+1}|^2``),
    which is all that powers need.

    Where two neighbouring media both have ``q = 0`` exactly (then ``n_j^2 =
    n_{j+1}^2 = beta^2``: the same medium) the interface is transparent (``r =
    0``, ``t = 1``) instead of ``0/0``.
    """
    last = len(a) - 2
    one = Cx(1.0, 0.0)

    def pair(j):
        aj, bj = a[j], a[j + 1]
        z = zero_pairs[j]
        if z is not None:
            aj, bj = one.select(z, aj), one.select(z, bj)
        return aj, bj

    aj, bj = pair(last)
    N = aj - bj
    D = aj + bj
    if e1 is not None:
        T = aj
    elif t_power is not None:
        T = t_power[last]
    else:
        T = None
    steps = 0
    for j in range(last - 1, -1, -1):
        aj, bj = pair(j)
        N, D = rouard_step(aj, bj, E[j + 1], N, D)
        if e1 is not None:
            T = cmul(cmul(aj, e1[j + 1]), T)
        elif t_power is not None:
            T = T * t_power[j]
        steps += 1
        if steps % _RESCALE == 0 and j > 0:
            scale = _rescale_factor(D)
            N = N * scale
            D = D * scale
            if T is not None:
                T = T * (scale if e1 is not None else scale * scale)
    return N, D, T


def guard_zero_q(m: Cx, q: Cx, beta, like) -> Cx:
    """A film's ``q`` moved off 0 where it is within rounding of 0 (see :func:`prepare_stack`);
    ``like`` is any array of the working precision (float32 or wider)."""
    eps = 2.0 ** -24 if _is_float32(like) else 2.0 ** -53
    size = dr.abs(m.re) + dr.abs(m.im) + beta
    eps_q = (2.0 * math.sqrt(eps)) * size
    small = q.abs2() < eps_q * eps_q
    return Cx(dr.select(small, eps_q, q.re), q.im if is_zero(q.im) else dr.select(small, 0.0, q.im))


def incidence(n0, cos0):
    """``(cos0, beta^2, q0)``: the cosine clipped to [0, 1], the squared tangential
    index ``n0^2 sin^2`` (without cancellation) and ``q0 = n0 cos0``."""
    cos0 = dr.clip(cos0, 0.0, 1.0)
    return cos0, n0 * n0 * ((1.0 - cos0) * (1.0 + cos0)), n0 * cos0


def exit_admittances(n_exit, beta2, beta2_max):
    """``(n_exit, q_exit, {pol: admittance})`` of the exit medium (``q`` for s,
    ``q / n^2`` for p), as :class:`Cx`."""
    n_ex = Cx.of(n_exit)
    q_ex = normal_index_bounded(n_ex, beta2, beta2_max)
    return n_ex, q_ex, {"s": q_ex, "p": cmul(q_ex, cinv(n_ex.square()))}


class LoopIncidence:
    """What every general film loop (:func:`stack_loop_terms`,
    :func:`thinfilm_mi.optics.mueller.amplitude_loop`) derives from the incidence before
    it visits the films: :func:`incidence`'s ``cos0``, ``beta2`` and ``q0``, the exit
    medium's :func:`exit_admittances` (``n_ex``, ``q_ex``, ``a_ex``), ``grazing``, and a
    ``zero`` of the loop state's shape; ``n0_max`` and ``film_n_min`` are the loop's
    trace-time hints."""

    def __init__(self, n0, cos0, n_exit, wavelength, n0_max: float | None,
                 film_n_min: float | None):
        self.cos0, self.beta2, self.q0 = incidence(n0, cos0)
        self.beta2_max = n0_max * n0_max if n0_max is not None else None
        self.n2_min = film_n_min * film_n_min if film_n_min is not None else None
        self.beta = dr.sqrt(self.beta2)
        self.grazing = self.cos0 <= 0.0
        self.n_ex, self.q_ex, self.a_ex = exit_admittances(n_exit, self.beta2, self.beta2_max)
        self.zero = 0.0 * wavelength * self.cos0
        self.inv_wl = 1.0 / wavelength

    def full(self, z: Cx) -> tuple:
        """``(re, im)`` of ``z`` broadcast to the loop state's shape."""
        return (self.zero + z.re, self.zero + z.im)

    def film_admittances(self, m: Cx) -> tuple:
        """``(q, {pol: admittance})`` of a film of index ``m`` (``q`` guarded off 0,
        :func:`guard_zero_q`)."""
        q = guard_zero_q(m, normal_index_bounded(m, self.beta2, self.beta2_max, self.n2_min),
                         self.beta, self.zero)
        inv_m2 = 1.0 / (m.re * m.re) if is_zero(m.im) else cinv(m.square())
        return q, {"s": q, "p": cmul(q, Cx.of(inv_m2))}

    def ambient_admittances(self, n0) -> dict:
        """``{pol: admittance}`` of the ambient (real)."""
        return {"s": Cx(self.q0, 0.0), "p": Cx(self.q0 * (1.0 / (n0 * n0)), 0.0)}


@dataclass(frozen=True)
class FilmBounds:
    """What is known at trace time of one film's index over every wavelength and angle
    the kernel may see (:func:`stack_rt`'s ``bounds``): ``n2_min``, a lower bound of
    ``n^2`` for a real film (``None``: absorbing, or unknown), and ``q_away``: ``|q|``
    cannot come within :func:`guard_zero_q`'s reach of 0, so the guard is not traced."""

    n2_min: float | None = None
    q_away: bool = False


#: No trace-time knowledge of a film: the general root and the guard.
UNBOUNDED = FilmBounds()


def film_bounds(n_min: float, n_max: float, k_min: float, k_max: float,
                n0_max: float) -> FilmBounds:
    """:class:`FilmBounds` of a film whose index ``n + ik`` lies in ``[n_min, n_max] x
    [k_min, k_max]`` (``k_min >= 0``) at every wavelength, seen from an ambient of index
    at most ``n0_max`` (so ``beta^2 <= n0_max^2``), in float32 arithmetic.

    ``q^2 = n^2 - k^2 - beta^2 + 2ink``, so ``|q|^2 >= |Re q^2|`` and ``|q|^2 >= 2 n k``:
    for a real film ``|q|^2 >= n_min^2 - n0_max^2``, for an absorbing one ``|q|^2 >= 2
    n_min k_min``. The guard acts below ``eps_q^2 = 4 eps (|n| + |k| + beta)^2``
    (``eps = 2^-24``); a lower bound 16 times that (``|q|`` 4 times ``eps_q``) leaves room
    for the rounding of ``q^2`` itself (relative ``~eps (|n|^2 + beta^2) / |q|^2 <
    1/64``)."""
    eps_q2 = 4.0 * 2.0 ** -24 * (n_max + k_max + n0_max) ** 2
    if k_max == 0.0:
        q2_min = n_min * n_min - n0_max * n0_max
        return FilmBounds(n2_min=n_min * n_min, q_away=q2_min > 16.0 * eps_q2)
    return FilmBounds(q_away=2.0 * n_min * k_min > 16.0 * eps_q2)


def prepare_stack(n0, cos0, films, n_exit, wavelength, s, p, amplitudes, transmission,
                  bounds: Sequence[FilmBounds] | None = None, n0_max: float | None = None,
                  exit_bounds: FilmBounds = UNBOUNDED):
    """Everything the recursion needs, shared by both polarisations; ``bounds`` (per film),
    ``n0_max`` (a bound of the ambient's index) and ``exit_bounds`` as :func:`stack_rt`
    takes them."""
    cos0, beta2, q0 = incidence(n0, cos0)
    if _is_literal(n0):
        n0_max = n0
    beta2_max = n0_max * n0_max if n0_max is not None else None
    bounds = list(bounds) if bounds is not None else [UNBOUNDED] * len(films)

    media = [Cx.of(n0)] + [Cx.of(n) for n, _ in films] + [Cx.of(n_exit)]
    qs = [Cx(q0, 0.0)] + [normal_index_bounded(m, beta2, beta2_max, b.n2_min)
                          for m, b in zip(media[1:-1], bounds)] \
        + [normal_index_bounded(media[-1], beta2, beta2_max, exit_bounds.n2_min)]
    # A film whose q is within rounding of 0 (|q|^2 below the rounding error
    # ~eps (|n|^2 + beta^2) of q^2 = n^2 - beta^2: exactly at, or within rounding
    # of, its critical angle) makes the Rouard step 0/0: gamma -> -1 and
    # 1 + r gamma E -> 0. A film's response is an even function of its q (the
    # characteristic matrix holds cos(delta), q sin(delta) and sin(delta)/q), so
    # replacing such a q by the real eps_q = 2 sqrt(eps) (|n| + beta) changes q^2
    # only by the amount its own rounding already leaves open. Two neighbours
    # at q = 0 (the same medium) then get r = 0 as they should.
    beta = dr.sqrt(beta2)
    # (not traced where the film's bounds keep q away from 0)
    for j in range(1, len(media) - 1):
        if not bounds[j - 1].q_away:
            qs[j] = guard_zero_q(media[j], qs[j], beta, cos0)
    inv_wl = 1.0 / wavelength
    E = [None] * len(media)
    e1 = [None] * len(media) if (amplitudes and transmission) else None
    mag2 = [None] * len(media)   # |e1|^2 = |E|, None where it is 1
    for j, (_, d) in enumerate(films):
        q, u = qs[j + 1], d * inv_wl
        if e1 is not None:
            e1[j + 1] = phase_factor(q, u, False)
            E[j + 1] = cmul(e1[j + 1], e1[j + 1])
        else:
            E[j + 1] = phase_factor(q, u, True)
            if not is_zero(q.im):
                mag2[j + 1] = dr.exp((-4.0 * math.pi) * (q.im * u))

    zero_pairs = [None] * (len(media) - 1)

    adm = {}
    if s:
        adm["s"] = qs
    if p:
        adm["p"] = [qs[0] * (1.0 / (n0 * n0))] + \
            [cmul(q, cinv(m.square())) for q, m in zip(qs[1:], media[1:])]

    tpow = {}
    if transmission and not amplitudes:
        for pol, a in adm.items():
            lst = []
            for j in range(len(media) - 1):
                f = a[j].abs2()
                if mag2[j] is not None:
                    f = f * mag2[j]
                lst.append(f)
            tpow[pol] = lst
    return cos0, q0, media, qs, E, e1, tpow, zero_pairs, adm


#: Per polarisation: the transmission amplitude from the recursion's ``T / D``
#: (times the interfaces' factors 2) and the media. s: as it is; p (whose
#: admittances are ``q / n^2``): times the telescoped product of ``n_j / n_{j+1}``.
_AMPLITUDE_T = {
    "s": lambda t, media: t,
    "p": lambda t, media: cmul(t, cmul(media[0], cinv(media[-1]))),
}


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

    Notes
    -----
    The recursion is the paper's eq. 1-4: starting from the innermost interface,
    ``gamma <- (r_j + gamma E_j) / (1 + r_j gamma E_j)`` and
    ``tau <- t_j tau sqrt(E_j) / (1 + r_j gamma E_j)`` with
    ``E_j = exp(2 i delta_j)``, ``delta_j = 2 pi q_j d_j / lambda``, evaluated
    in the division-free projective form described in :func:`rouard_recursion`.
    """
    cos0, q0, media, qs, E, e1, _, zero_pairs, adm = prepare_stack(
        n0, cos0, films, n_exit, wavelength, s, p, True, transmission)
    grazing = cos0 <= 0.0
    two_l = 2.0 ** (len(films) + 1)  # the factors 2 of the interface t's
    res = {"s": (None, None), "p": (None, None)}
    for pol in adm:
        N, D, T = rouard_recursion(adm[pol], E, e1, None, zero_pairs)
        invD = cinv(D)
        r = cmul(N, invD)
        t = None
        if T is not None:
            t = _AMPLITUDE_T[pol](cmul(T, invD) * two_l, media)
        r = Cx(-1.0, 0.0).select(grazing, r)
        if t is not None:
            t = Cx(0.0, 0.0).select(grazing, t)
        res[pol] = (r, t)
    (rs, ts), (rp, tp) = res["s"], res["p"]
    return StackAmplitudes(rs, rp, ts, tp, q0, qs[-1], media[-1], grazing)


def stack_rt(n0, cos0, films, n_exit, wavelength, *, transmission: bool = True,
             bounds: Sequence[FilmBounds] | None = None, n0_max: float | None = None,
             exit_bounds: FilmBounds = UNBOUNDED):
    """Reflectance and transmittance ``(Rs, Rp, Ts, Tp)`` of a stack (energy fractions).

    ``Rs = |r_s|^2`` and ``Rp = |r_p|^2`` (eq. 5 averages them for unpolarised
    light); ``Ts, Tp`` are the powers entering the exit medium (eq. 6 and
    appendix A-21, with the exact p factor of :func:`transmittance_factor_p`).
    When ``transmission`` is false, ``Ts = Tp = None`` and no transmission work
    is done. At grazing incidence ``R = 1`` and ``T = 0`` exactly.

    Powers are formed from the projective ``(N, D, T)`` of :func:`rouard_recursion`
    directly (``R = |N|^2 / |D|^2``), one division per polarisation.

    ``bounds`` (one :class:`FilmBounds` per film, :func:`film_bounds`) and ``n0_max`` (an
    upper bound of ``n0``) are trace-time knowledge that lets the kernel skip work: a
    real film's single real root where ``n^2 >= n0_max^2``, no ``q = 0`` guard where
    ``q`` stays away from 0 (``exit_bounds``: the exit medium's ``n2_min``). They must
    hold for every input, or the results are wrong.
    """
    cos0, q0, media, qs, E, _, tpow, zero_pairs, adm = prepare_stack(
        n0, cos0, films, n_exit, wavelength, True, True, False, transmission,
        bounds, n0_max, exit_bounds)
    grazing = cos0 <= 0.0
    fac = None
    if transmission:
        fac = power_factors(n0, q0, media[-1], qs[-1], grazing, 4.0 ** (len(films) + 1))
    results = {pol: rouard_recursion(adm[pol], E, None, tpow.get(pol), zero_pairs)
               for pol in COMPONENTS}
    return _powers(results, fac, grazing)


def power_factors(n0, q0, n_ex: Cx, q_ex: Cx, grazing, scale):
    """``{pol: factor}`` that turn the projective ``|T|^2 / |D|^2`` into
    transmittance: ``scale`` (the ``4^(L+1)`` of the interface ``t``'s, where
    the recursion leaves them out) over ``q0``, times the power factor of
    :func:`transmittance_factor_s` / :func:`transmittance_factor_p` and, for p,
    the telescoped ``|n0 / n_exit|^2`` of ``|t_p|^2``."""
    inv_q0 = scale / dr.select(grazing, 1.0, q0)
    n2 = n_ex.square()
    re_n2q = n2.re * q_ex.re if is_zero(q_ex.im) else n2.re * q_ex.re + n2.im * q_ex.im
    abs2_nex = n_ex.abs2()
    if _is_literal(abs2_nex):
        fp_const = (n0 * n0) / (abs2_nex * abs2_nex)
    else:
        fp_const = (n0 * n0) * dr.square(1.0 / abs2_nex)
    return {"s": q_ex.re * inv_q0, "p": re_n2q * fp_const * inv_q0}


def _powers(results: dict, fac: dict | None, grazing):
    """``(Rs, Rp, Ts, Tp)`` from the projective ``{pol: (N, D, |T|^2)}``."""
    out = []
    for pol in COMPONENTS:
        N, D, T = results[pol]
        inv = 1.0 / D.abs2()
        R = dr.select(grazing, 1.0, dr.minimum(N.abs2() * inv, 1.0))
        Tr = None
        if fac is not None:
            Tr = dr.select(grazing, 0.0, dr.clip(T * inv * fac[pol], 0.0, 1.0))
        out.append((R, Tr))
    (Rs, Ts), (Rp, Tp) = out
    return Rs, Rp, Ts, Tp


def films_left(j, *_):
    """The film loops' condition: films remain above the current interface."""
    return j > 0


def loop_body(step):
    """``step`` as a ``dr.while_loop`` body. Some products mix types (mi.Spectrum
    with Dr.Jit's Array4f): they are cast back, as a loop's state may not change
    type."""
    def body(*st):
        return tuple(type(old)(new) if dr.is_array_v(old) else new
                     for old, new in zip(st, step(*st)))
    return body


def stack_rt_loop(n0, cos0, count, film, n_exit, wavelength, *, transmission: bool = True,
                  n0_max: float | None = None, film_n_min: float | None = None,
                  film_n_max: float | None = None, films_max: int | None = None,
                  label: str = "thinfilm_rouard", max_iterations: int | None = None):
    """:func:`stack_rt` with the films visited by a Dr.Jit loop instead of unrolled.

    ``count`` is the number of films, as an unsigned integer array of the
    Dr.Jit backend (``drjit.llvm.UInt32``; a Python ``int`` runs the loop in
    Python); ``film(j)`` returns ``(index, thickness)`` of film ``j``
    (``0`` next to the ambient) for an index array ``j`` of that type — in a
    render kernel a gather from a buffer. With Dr.Jit arrays the loop is
    *symbolic*: its body is traced once and becomes a loop in the kernel, so
    the kernel's size and compile time do not grow with the number of films.

    The body is the same step as :func:`rouard_recursion` (:func:`rouard_step`,
    the same root choice, the same guard of ``q = 0``), from the innermost film
    outwards, starting from ``gamma = 0`` inside the exit medium; it rescales
    after every film. ``(N, D)`` start at ``(0, 1)`` so the first step yields
    the innermost interface; the factor 4 of each interface's ``|t|^2`` is
    applied per film. ``R`` and ``T`` agree with :func:`stack_rt` to rounding.
    The films' indices are arrays here, so :func:`stack_rt`'s specialisation on
    literal indices is replaced by the hints below. Returns ``(Rs, Rp, Ts,
    Tp)`` (``Ts = Tp = None`` without ``transmission``).

    Trace-time hints, for the caller that knows its films: ``n0_max``, an
    upper bound of the ambient index, and ``film_n_min``, a lower bound of the
    films' real index when ``film`` returns indices with a literal ``0``
    imaginary part. With both and ``film_n_min >= n0_max`` every film's ``q`` is
    real at every angle and the loop body traces one real square root and no
    exponential per film (what :func:`stack_rt` does for literal indices).
    With ``film_n_min >= REAL_LOOP_MARGIN * n0_max`` the loop runs
    :func:`stack_rt_loop_real` instead (real Fresnel amplitudes, about half
    the work per film); ``film_n_max``, an upper bound of the films' index,
    and ``films_max``, of ``count``, then let it drop the rescaling where it
    cannot be needed. ``max_iterations`` (at least ``count``) lets Dr.Jit
    differentiate the loop in reverse mode (it stores the loop's state per film);
    it applies to the general loop, not the real-amplitude one.
    """
    if real_loop_applies(n0_max, film_n_min):
        return stack_rt_loop_real(n0, cos0, count, film, n_exit, wavelength,
                                   transmission=transmission, n0_max=n0_max,
                                   film_n_min=film_n_min, film_n_max=film_n_max,
                                   films_max=films_max, label=label)
    results, fac, grazing = stack_loop_terms(
        n0, cos0, count, film, n_exit, wavelength, transmission=transmission, n0_max=n0_max,
        film_n_min=film_n_min, label=label, max_iterations=max_iterations)
    return _powers(results, fac, grazing)


def stack_loop_terms(n0, cos0, count, film, n_exit, wavelength, *, transmission: bool = True,
                     n0_max: float | None = None, film_n_min: float | None = None,
                     label: str = "thinfilm_rouard", max_iterations: int | None = None,
                     exponents: bool = False, smooth: bool = False):
    """The general loop of :func:`stack_rt_loop` (arguments as there), stopped before
    the powers: ``(terms, factors, grazing)`` with ``terms[pol] = (N, D, |T|^2)``
    (``|T|^2`` ``None`` without ``transmission``), ``R = |N|^2 / |D|^2``, ``T =
    |T|^2 factors[pol] / |D|^2`` (``factors`` ``None`` without ``transmission``).

    **The rescaling policy** (the one of every film loop): after each film ``(N,
    D, T)`` are multiplied by the power of two nearest ``1 / (|Re D| + |Im D|)``
    (:func:`_rescale_factor`), exact and free of rounding, so nothing overflows in
    float32 at any depth. It makes ``N`` and ``D`` jump by factors of two along the
    wavelength; with ``exponents`` the loop also sums each polarisation's rescaling
    exponents and ``terms[pol]`` gets a fourth entry ``E`` (float, an integer):
    ``N 2^E`` and ``D 2^E`` are the amplitudes without the jumps. With ``smooth``
    each step (the last, onto the ambient, included) first multiplies ``(N, D)`` by
    ``1 / sqrt(|a_j|^2 + |a_j+1|^2)`` (``|T|^2`` by its square), a smooth function of
    the wavelength made of the two media's admittances only: ``N 2^E``, ``D 2^E``
    are then smooth where ``R`` has resonances, with no magnitude growing along the
    stack (what the band-limited tables' resonance search samples,
    :func:`thinfilm_mi.tabulate.band.amplitudes`). The power of two is exact,
    so ``R`` and the ratios of neighbouring samples do not depend on it.
    """
    if _is_literal(n0):
        n0_max = n0
    inc = LoopIncidence(n0, cos0, n_exit, wavelength, n0_max, film_n_min)

    def film_terms(j):
        m, d = film(j)
        q, a = inc.film_admittances(Cx.of(m))
        u = d * inc.inv_wl
        E = phase_factor(q, u, True)
        mag2 = 1.0 if is_zero(q.im) else dr.exp((-4.0 * math.pi) * (q.im * u))
        return a, E, mag2

    # State: j, then per polarisation N, D (complex), |T|^2 (a constant 1, not
    # traced, without transmission), the admittance of the medium below, and that
    # medium's phase factor (shared by s and p).
    t0 = inc.zero + 1.0 if transmission else 1.0
    # (with exponents, each polarisation's sum of rescaling exponents follows its T)
    e0 = (inc.zero,) if exponents else ()
    state = (count,
             *inc.full(Cx(0.0)), *inc.full(Cx(1.0)), t0, *e0,
             *inc.full(Cx(0.0)), *inc.full(Cx(1.0)), t0, *e0,
             *inc.full(inc.a_ex["s"]), *inc.full(inc.a_ex["p"]), *inc.full(Cx(0.0)))
    k = 6 if exponents else 5     # state entries per polarisation

    def components(st) -> list:
        """``(pol, (Nr, Ni, Dr, Di, T[, e]), admittance below)`` of s, then p, in the state ``st``."""
        return [(pol, st[i * k:(i + 1) * k], Cx(*st[2 * k + 2 * i:2 * k + 2 * i + 2]))
                for i, pol in enumerate(COMPONENTS)]

    def step(j, *st):
        j = j - 1
        a, E, mag2 = film_terms(j)
        out = []
        for pol, (Nr, Ni, Dr, Di, T, *e), b in components(st):
            out += _loop_step(a[pol], b, Cx(*st[2 * k + 4:]), Cx(Nr, Ni), Cx(Dr, Di), T, e, mag2,
                              transmission=transmission, smooth=smooth, exponents=exponents)
        return (j, *out, a["s"].re, a["s"].im, a["p"].re, a["p"].im, E.re, E.im)

    _, *st = dr.while_loop(state, films_left, loop_body(step), label=label,
                           max_iterations=max_iterations)
    a0 = inc.ambient_admittances(n0)
    E_top = Cx(*st[2 * k + 4:])
    results = {}
    for pol, (Nr, Ni, Dr, Di, T, *e), b in components(st):
        N, D = rouard_step(a0[pol], b, E_top, Cx(Nr, Ni), Cx(Dr, Di))
        if smooth:
            N, D, T = _smooth_scale(a0[pol], b, N, D, T if transmission else None, 1.0)
        elif transmission:
            T = T * 4.0 * a0[pol].abs2()
        results[pol] = (N, D, T if transmission else None, *e)
    fac = power_factors(n0, inc.q0, inc.n_ex, inc.q_ex, inc.grazing, 1.0) if transmission else None
    return results, fac, inc.grazing


def _loop_step(a: Cx, b: Cx, E_b: Cx, N: Cx, D: Cx, T, e: list, mag2, *, transmission: bool,
               smooth: bool, exponents: bool) -> list:
    """One film of :func:`stack_loop_terms`, one polarisation: the Rouard step from the
    medium below (admittance ``b``, phase factor ``E_b``) to the film above (``a``, its
    ``|e^{i delta}|^2 = mag2``), then the rescaling; returns the new state entries ``[N.re,
    N.im, D.re, D.im, |T|^2]`` (and the exponents' sum, ``e`` holding the old one)."""
    N, D = rouard_step(a, b, E_b, N, D)
    if smooth:
        N, D, T = _smooth_scale(a, b, N, D, T if transmission else None, mag2)
    scale = _rescale_factor(D)
    if not transmission:
        T = 1.0
    elif smooth:
        T = T * (scale * scale)
    else:
        T = T * (4.0 * a.abs2() * mag2) * (scale * scale)
    out = [N.re * scale, N.im * scale, D.re * scale, D.im * scale, T]
    if exponents:
        out.append(e[0] + _exponent_of(scale))
    return out


#: :func:`stack_rt_loop` uses the real-amplitude loop when every film's index is
#: real and at least this factor above the ambient's: then ``q_j >= n0 sqrt(m^2 -
#: 1) > 0`` for every film at every angle (no evanescent film, no ``q = 0``).
REAL_LOOP_MARGIN = 1.001
#: The real-amplitude loop keeps ``|D|`` within ``2^+-_REAL_RANGE_BITS`` of 1
#: without rescaling when the films' contrast allows it (see
#: :func:`real_loop_rescale`); float32 spans 2^+-126.
_REAL_RANGE_BITS = 100


def real_loop_applies(n0_max: float | None, film_n_min: float | None) -> bool:
    """Whether :func:`stack_rt_loop` with these hints runs the real-amplitude loop
    (``film_n_min``: a lower bound of the films' real index, ``None`` where
    some film absorbs; ``n0_max``: an upper bound of the ambient's index)."""
    return (film_n_min is not None and n0_max is not None
            and film_n_min >= REAL_LOOP_MARGIN * n0_max)


@functools.lru_cache(maxsize=64)
def real_loop_rescale(n0_max: float, film_n_min: float, film_n_max: float | None) -> int:
    """How many films the real-amplitude loop may run before ``(N, D, T)`` must be
    rescaled (0: rescale after every film).

    In that loop ``|gamma| <= 1`` inside every film (lossless films over a
    passive exit: ``|gamma|^2`` is a reflectance), so a step ``D' = D + r E N``
    changes ``|D|`` by a factor in ``[1 - |r|, 1 + |r|]`` and ``|T|^2`` by one
    in ``[(1 - |r|)^2, (1 + |r|)^2]``. ``|r|`` is bounded from the largest ratio of two
    films' admittances at one angle, for indices in ``[n_min, n_max]``: ``q =
    sqrt(n^2 - beta^2)`` grows with ``n`` (largest ratio at ``beta = n0``);
    ``q / n^2`` is unimodal in ``n``, its ratio is taken on a grid of ``n`` and
    ``beta`` (with a 2 % margin: the grid is fine and the function smooth).
    Returns the number of films after which ``|D|`` or ``|T|^2`` could have left
    ``2^+-_REAL_RANGE_BITS``.
    """
    if film_n_max is None:
        return 0
    lo, hi = film_n_min, max(film_n_max, film_n_min)
    ratio_s = math.sqrt((hi * hi - n0_max * n0_max) / (lo * lo - n0_max * n0_max))
    ratio_p = 1.0
    for i in range(65):
        beta = n0_max * i / 64
        a = [math.sqrt(n * n - beta * beta) / (n * n)
             for n in (lo + (hi - lo) * k / 256 for k in range(257))]
        ratio_p = max(ratio_p, 1.02 * max(a) / min(a))
    ratio = max(ratio_s, ratio_p)
    r_max = (ratio - 1.0) / (ratio + 1.0)
    bits = 2.0 * max(math.log2(1.0 + r_max), -math.log2(1.0 - r_max))   # |T|^2, |D|^2
    return int(_REAL_RANGE_BITS / bits)


def stack_rt_loop_real(n0, cos0, count, film, n_exit, wavelength, *, transmission: bool,
                        n0_max: float, film_n_min: float, film_n_max: float | None,
                        films_max: int | None, label: str):
    """:func:`stack_rt_loop` for films of real index above the ambient's
    (``film_n_min >= REAL_LOOP_MARGIN * n0_max``).

    Every film's ``q`` is then real and positive at every angle, and so are its
    admittances ``a`` (``q`` for s, ``q / n^2`` for p) and the Fresnel
    amplitudes ``r = (a_j - a_j+1) / (a_j + a_j+1)`` between films. Dividing
    the Rouard step by ``a_j + a_j+1`` (instead of multiplying through by it,
    as :func:`rouard_step` does) leaves, with ``X = E N``::

        N' = r D + X,    D' = D + r X,    |T'|^2 = (1 + r)^2 |T|^2

    (``1 + r`` is the interface's ``t``; the films' ``|e^{i delta}| = 1``): the
    paper's ``gamma <- (r + gamma E)/(1 + r gamma E)`` with ``gamma = N / D``.
    That is four real multiply-adds besides ``E N`` per polarisation, where
    the complex admittances of the general step need twice that. The
    interfaces with the exit medium (possibly absorbing) and with the ambient
    are done outside the loop in complex arithmetic; the loop starts from
    ``(N, D) = (a - a_exit, a + a_exit)`` below the innermost film and carries the film
    above's ``q``, ``a_p`` and thickness into the next iteration, so each film's
    index is gathered once. For constant films ``film(j)`` may return indices
    that do not depend on the wavelength (one per lane): then ``q``, ``a`` and
    ``r`` are computed once for all wavelengths.

    The loop rescales ``(N, D, T)`` by a power of two after every film unless
    :func:`real_loop_rescale` shows, from the trace-time bounds, that ``|D|``
    and ``|T|^2`` cannot leave float32's range for ``films_max`` films (the
    traced code then depends only on which side of that bound the depth lies).
    """
    cos0, beta2, q0 = incidence(n0, cos0)
    grazing = cos0 <= 0.0
    n_ex, q_ex, a_ex = exit_admittances(n_exit, beta2, n0_max * n0_max)
    inv_wl = 1.0 / wavelength
    zero = 0.0 * wavelength * cos0

    def phase(q, d):
        return phase_factor(Cx(q, 0.0), d * inv_wl, True)

    state = _real_loop_start(n0, count, film, a_ex, beta2, zero, transmission)
    every = real_loop_rescale(n0_max, film_n_min, film_n_max)
    in_loop_rescale = films_max is None or films_max > every

    def step(N: Cx, D: Cx, T, r, E: Cx, rescale: bool = True):
        return _real_step(N, D, T, r, E, transmission=transmission,
                          rescale=rescale and in_loop_rescale)

    def body(j, Nsr, Nsi, Dsr, Dsi, Ts, Npr, Npi, Dpr, Dpi, Tp, q_b, ap_b, d_b):
        j = j - 1
        E = phase(q_b, d_b)                 # the film below the interface
        m_a, d_a = film(j)                  # the film above it
        q_a, ap_a = _real_admittances(Cx.of(m_a).re, beta2)
        r_s = (q_a - q_b) / (q_a + q_b)
        r_p = (ap_a - ap_b) / (ap_a + ap_b)
        Ns, Ds, Ts = step(Cx(Nsr, Nsi), Cx(Dsr, Dsi), Ts, r_s, E)
        Np, Dp, Tp = step(Cx(Npr, Npi), Cx(Dpr, Dpi), Tp, r_p, E)
        return (j, Ns.re, Ns.im, Ds.re, Ds.im, Ts, Np.re, Np.im, Dp.re, Dp.im, Tp,
                q_a, ap_a, d_a)

    (_, Nsr, Nsi, Dsr, Dsi, Ts, Npr, Npi, Dpr, Dpi, Tp, q_b, ap_b, d_b) = dr.while_loop(
        tuple(state), films_left, loop_body(body), label=label)
    # The first film's phase and the interface with the ambient (a0 >= 0, real).
    E = phase(q_b, d_b)
    results = {}
    for pol, (N, D, T, a_b, a0) in (
            ("s", (Cx(Nsr, Nsi), Cx(Dsr, Dsi), Ts, q_b, q0)),
            ("p", (Cx(Npr, Npi), Cx(Dpr, Dpi), Tp, ap_b, q0 * (1.0 / (n0 * n0))))):
        N, D, T = step(N, D, T, (a0 - a_b) / (a0 + a_b), E, rescale=False)
        results[pol] = (N, D, T if transmission else None)
    fac = power_factors(n0, q0, n_ex, q_ex, grazing, 1.0) if transmission else None
    return _powers(results, fac, grazing)


def _real_admittances(n, beta2):
    """``(q, q / n^2)`` of a film of real index ``n`` above the ambient's in
    :func:`stack_rt_loop_real`: ``n^2 - beta^2 >= n_min^2 - n0_max^2 > 0``, the real root,
    no guard."""
    inv_n2 = 1.0 / (n * n)
    q = dr.sqrt(dr.maximum(dr.fma(n, n, -beta2), 0.0))
    return q, q * inv_n2


def _real_loop_start(n0, count, film, a_ex: dict, beta2, zero, transmission: bool) -> list:
    """The state :func:`stack_rt_loop_real` enters its loop with: the innermost
    interface, film L-1 | exit medium (complex), without its division: ``(N, D) = (a -
    a_exit, a + a_exit)``, ``|T|^2 = 4 a^2`` (``gamma = r`` and ``|T / D|^2 = |t|^2 = |1 +
    r|^2``; later steps are linear in ``(N, D)`` and ``T``), then that film's ``q``,
    ``a_p`` and thickness. Without films (``count = 0``) the "innermost film" is the
    ambient itself, 0 nm thick: the ambient step is then transparent (``r = 0``, ``E =
    1``)."""
    some = count > 0
    j_last = dr.maximum(count, 1) - 1
    m_last, d_last = film(j_last)
    n_last = dr.select(some, Cx.of(m_last).re, n0)
    d_last = dr.select(some, d_last, 0.0)
    q_b, ap_b = _real_admittances(n_last, beta2)
    state = [j_last]
    for pol, a_b in (("s", q_b), ("p", ap_b)):
        a_x = a_ex[pol]
        t = (zero + 4.0 * a_b * a_b) if transmission else 1.0
        state += [zero + (a_b - a_x.re), zero - a_x.im, zero + (a_b + a_x.re), zero + a_x.im, t]
    return state + [q_b, ap_b, d_last]


def _real_step(N: Cx, D: Cx, T, r, E: Cx, *, transmission: bool, rescale: bool):
    """One interface of :func:`stack_rt_loop_real`, real Fresnel amplitude ``r``, the
    medium below's phase factor ``E``: ``N' = r D + E N``, ``D' = D + r E N``, ``|T'|^2 =
    (1 + r)^2 |T|^2``, then (``rescale``) the exact power-of-two rescaling."""
    X = cmul(E, N)
    N, D = Cx(dr.fma(r, D.re, X.re), dr.fma(r, D.im, X.im)), \
        Cx(dr.fma(r, X.re, D.re), dr.fma(r, X.im, D.im))
    if transmission:
        T = T * dr.square(1.0 + r)
    if rescale:
        scale = _rescale_factor(D)
        N, D = N * scale, D * scale
        if transmission:
            T = T * (scale * scale)
    return N, D, T


def clip_transmittance(T, R):
    """``T`` clipped to ``[0, 1 - R]`` (rounding can push a lossless stack's ``T``
    past ``1 - R``), with the derivative of the unclipped ``T``: the clip corrects
    rounding only, and where it acts (``R + T = 1``, a lossless stack) its own
    derivative, ``-dR``, would be that of a stack with gain (``k < 0``), not the
    one-sided derivative on the side of loss."""
    out = dr.clip(T, 0.0, 1.0 - R)
    if dr.grad_enabled(T):
        out = dr.detach(out) + (T - dr.detach(T))
    return out


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
