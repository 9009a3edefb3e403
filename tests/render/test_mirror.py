"""``render.mirror.either_side``: the sides of a stack under a symbolic conditional.

Dr.Jit 1.5.0 hands back the false branch's own variable for an output that both branches
return as the same literal; the LLVM backend defines it inside that branch, and a use after
the conditional aborts the process ("Instruction does not dominate all uses!"). Two opaque
sides of a ``thinfilm_dielectric`` both return ``T = 0`` and aborted
``tests/cross/test_stability_bsdf.py``. The checks run in a subprocess, where an abort is a
failed assertion rather than the end of the test run.
"""
from __future__ import annotations

import subprocess
import sys

CHILD = r'''
import drjit as dr, mitsuba as mi, numpy as np
mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: F401  (registers the plugins)
from thinfilm_mi.render.mirror import either_side

# 1. either_side itself: both sides return the literal T = 0, used after the conditional
U = mi.UnpolarizedSpectrum
x = dr.arange(mi.Float, 32) / 32 - 0.5
side = lambda inside: (U(dr.sin(x)) if inside else U(dr.cos(x)), U(0.0))
R, T = either_side(side, x < 0, True)
y = dr.select(x > 0.25, U(1.0), T)
dr.eval(R, y)
xs = np.array(x)
assert np.allclose(np.array(R)[0], np.where(xs < 0, np.sin(xs), np.cos(xs)), atol=1e-6)
assert np.array_equal(np.array(y)[0], np.where(xs > 0.25, 1.0, 0.0))

# 2. the plugin case that aborted: an opaque film on glass, lit from both sides in one packet
bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": "1.5+20j 1000", "int_ior": 1.5,
                     "tabulate": False})
si = dr.zeros(mi.SurfaceInteraction3f, 4)
si.wi = mi.Vector3f([0.6, 0.6, 0, 0], [0, 0, 0.6, 0.6], [0.8, -0.8, 0.8, -0.8])
si.wavelengths = mi.Spectrum(380.0, 470.0, 590.0, 760.0)
bs, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(0.5), mi.Point2f(0.5, 0.5))
dr.eval(bs, w)
w = np.array(w)
assert np.all(np.isfinite(w)) and np.all((w > 0) & (w <= 1)), w
assert np.all(np.array(bs.sampled_component) == 0)   # T = 0: reflection only
print("ok")
'''


def test_a_literal_both_sides_return_is_usable_after_the_conditional():
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), \
        f"status {out.returncode}: {out.stdout[-500:]} {out.stderr[-2000:]}"
