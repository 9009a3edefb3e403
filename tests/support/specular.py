"""Helpers of the specular plugins' tests: wavelengths, the float32 tolerance, an
interaction at a given cosine, a sampled weight, tmm's R, a lit scene with a floor."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import tmm

from tests.support.bsdf import context

WLS = [380.0, 470.0, 590.0, 760.0]
VARIANTS = ["llvm_ad_spectral", "scalar_spectral"]
# Float32 tolerance for a weight against float64: the in-kernel recursion runs in
# float32 (relative rounding 6e-8 per operation); for the <= 3 films and
# thicknesses <= 500 nm used here the phase error is below 1e-5 rad and the
# reflectance error below 1e-5 (see tests/optics/test_core.py); 3e-5 leaves margin for
# the 1 nm spectral resampling of datasets and the float32 cos(theta).
F32_TOL = 3e-5


def interaction(cos_theta, wls=WLS):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum(wls)
    s = float(np.sqrt(max(0.0, 1.0 - cos_theta ** 2)))
    si.wi = mi.Vector3f(s, 0.0, float(cos_theta))
    return si


def weight(bsdf, cos_theta, component=None, sample1=0.3):
    bs, w = bsdf.sample(context(component), interaction(cos_theta), float(sample1),
                        mi.Point2f(0.5, 0.5))
    return bs, np.array(w, dtype=np.float64).ravel()


def tmm_R(n_list, d_list, theta, wl):
    return 0.5 * sum(tmm.coh_tmm(p, n_list, d_list, theta, wl)["R"] for p in "sp")


def lit_floor_scene(bsdf, size=24):
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at([0, 1, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size},
                   "sampler": {"type": "independent", "sample_count": 8}},
        "env": {"type": "constant", "radiance": 0.3},
        "light": {"type": "point", "position": [2.0, 3.0, 2.0], "intensity": 20.0},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, -1, 0])
                  @ mi.ScalarTransform4f().rotate([1, 0, 0], -90) @ mi.ScalarTransform4f().scale(3),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard"}}},
        "obj": {"type": "sphere", "bsdf": bsdf},
    })
