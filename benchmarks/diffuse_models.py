"""``thinfilm_diffuse``: the paper's models ("single", "multiple") against the exact one.

Two measurements (issue 33: "measure the paper's models against the exact one on the
shipped scenes and decide the default from the measurements"):

1. **Scenes.** Every ``scenes/*.xml`` that uses ``thinfilm_diffuse`` and declares a
   ``model`` parameter is rendered with ``model`` = "single", "multiple" and "exact", in
   a spectral and an RGB variant, same seed. The table gives, per model, the mean
   per-pixel ``|image - exact image|`` over all channels divided by the exact image's
   mean, and the ratio of the image means (model / exact). The noise floor is the
   same figure for "exact" rendered with another seed (with the same seed the three
   models share their random numbers, so their differences sit below that floor).
2. **Normal incidence, independently of the plugin.** The issue's Cornell-box coating
   ``SiO2 300; Au 4`` in air (index data from :mod:`thinfilm_mi.materials`, optics
   from ``tmm``): the diffuse albedo for light at 0°, ``t(0) ρ T_hemi S`` with
   ``S = 1/(1 - ρ R_dh)`` ("single": ``S = 1``), for ρ = 0.6 and a white base (ρ = 1).
   Exact: ``t = T``, ``T`` of the whole coherent stack into air, ``R_dh`` of the reversed
   stack. Paper: ``t = k_t k_a``, ``k_t`` the coating's transmittance into bulk gold
   (tmm with gold as the semi-infinite exit medium), ``k_a = exp(-4π Im(q) d/λ)``
   through the 4 nm, ``R_dh = 2∫k_a² k_r μ dμ``. Each figure is printed beside the
   plugin's own (Monte Carlo diffuse-component albedo, 2^18 samples, ``llvm_ad_spectral``).

Usage: python benchmarks/diffuse_models.py [--size 120x80] [--spp 64] [--skip-scenes]
"""
from __future__ import annotations

import argparse
import math
import re
import time
from pathlib import Path

import numpy as np
import tmm

REPO = Path(__file__).resolve().parent.parent
MODELS = ("single", "multiple", "exact")
VARIANTS = ("llvm_ad_spectral", "llvm_ad_rgb")
WAVELENGTHS = (450.0, 550.0, 650.0, 680.0)
LAYERS = (("SiO2", 300.0), ("Au", 4.0))


def diffuse_scenes() -> list[Path]:
    """The shipped scenes that use ``thinfilm_diffuse`` with a ``model`` parameter."""
    out = []
    for path in sorted((REPO / "scenes").glob("*.xml")):
        text = path.read_text()
        if "thinfilm_diffuse" in text:
            if not re.search(r'<default\s+name="model"', text):
                raise SystemExit(f"{path.name} uses thinfilm_diffuse without a 'model' parameter")
            out.append(path)
    return out


def render_models(path: Path, size: tuple[int, int], spp: int) -> dict[str, np.ndarray]:
    from thinfilm_mi.batch.scene import load_scene, render_scene

    images = {}
    for model, seed in [(m, 0) for m in MODELS] + [("exact (seed 1)", 1)]:
        scene = load_scene(path, {"model": model.split()[0]}, size=size, spp=spp)
        images[model] = render_scene(scene, spp, seed=seed)[0][:, :, :3].astype(np.float64)
    return images


def scene_table(size: tuple[int, int], spp: int) -> None:
    from thinfilm_mi.batch.scene import setup_variant
    from thinfilm_mi.errors import UsageError

    print(f"## Scenes ({size[0]}x{size[1]}, {spp} spp): mean |model - exact| / mean(exact); "
          "mean(model) / mean(exact)")
    print("| scene | variant | single | multiple | noise floor (exact, other seed) | render s |")
    print("|---|---|---|---|---|---|")
    for variant in VARIANTS:
        setup_variant(variant)
        for path in diffuse_scenes():
            t0 = time.perf_counter()
            try:
                img = render_models(path, size, spp)
            except UsageError as e:  # e.g. a varying thickness where the variant refuses one
                print(f"| {path.stem} | {variant} | refused: {str(e).split('Error: ')[-1]} | | | |", flush=True)
                continue
            exact = img["exact"]

            def rel(model):
                return np.abs(img[model] - exact).mean() / exact.mean()

            cells = [f"{100 * rel(m):.1f} % ({img[m].mean() / exact.mean():.2f}x)"
                     for m in ("single", "multiple")]
            print(f"| {path.stem} | {variant} | {' | '.join(cells)} | {100 * rel('exact (seed 1)'):.1f} % "
                  f"| {time.perf_counter() - t0:.0f} |", flush=True)


def unpolarized_rt(n_list, d_list, cos_in: float, wl: float) -> tuple[float, float]:
    """tmm's (R, T), the mean of s and p, for light arriving at ``cos_in``."""
    rs = [tmm.coh_tmm(pol, n_list, d_list, math.acos(min(1.0, cos_in)) + 0j, wl) for pol in "sp"]
    return (float(np.real(rs[0]["R"] + rs[1]["R"])) / 2, float(np.real(rs[0]["T"] + rs[1]["T"])) / 2)


def reference_terms(wl: float, nodes: int = 64) -> dict[str, tuple[float, float, float]]:
    """``(t(0), T_hemi, R_dh)`` of the exact stack and of the paper's split, from tmm."""
    from thinfilm_mi.render.media import SpectralIndex

    n = [SpectralIndex.from_material(m, m).spectral_values(np.array([wl]))[0] for m, _ in LAYERS]
    d = [d for _, d in LAYERS]
    x, w = np.polynomial.legendre.leggauss(nodes)
    mus, weights = 0.5 * (x + 1.0), w  # 2 ∫ g(μ) μ dμ = Σ w μ g(μ) on [0, 1]

    def hemi(g) -> float:
        return float(sum(wt * mu * g(mu) for mu, wt in zip(mus, weights)))

    full, down = [1.0, *n, 1.0], [np.inf, *d, np.inf]

    def exact_t(mu):
        return unpolarized_rt(full, down, mu, wl)[1]

    exact = (exact_t(1.0), hemi(exact_t), hemi(lambda mu: unpolarized_rt(full[::-1], down[::-1], mu, wl)[0]))

    coating, thick = [1.0, n[0], n[1]], [np.inf, d[0], np.inf]

    def k_a(mu):
        q = np.sqrt(n[1] ** 2 - (1.0 - mu * mu) + 0j)
        q = q if q.imag >= 0 else -q
        return math.exp(-4 * math.pi * q.imag * d[1] / wl)

    def paper_t(mu):
        return unpolarized_rt(coating, thick, mu, wl)[1] * k_a(mu)

    r_up = hemi(lambda mu: k_a(mu) ** 2 * unpolarized_rt(coating, thick, mu, wl)[0])
    return {"exact": exact, "paper": (paper_t(1.0), hemi(paper_t), r_up)}


def albedo(terms, rho: float, series: bool) -> float:
    t0, t_hemi, r_dh = terms
    return t0 * rho * t_hemi / ((1.0 - rho * r_dh) if series else 1.0)


def plugin_albedo(model: str, rho: float, n: int = 1 << 18) -> np.ndarray:
    """The plugin's diffuse-component albedo at normal incidence (Monte Carlo)."""
    import drjit as dr
    import mitsuba as mi

    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "; ".join(f"{m} {d:g}" for m, d in LAYERS),
                      "model": model, "ext_ior": 1.0, "reflectance": rho, "tabulate": False})
    ctx = mi.BSDFContext()
    ctx.component = 1
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(0, 0, 1)
    si.wavelengths = mi.Spectrum(*WAVELENGTHS)
    rng = mi.PCG32(size=n, initstate=5)
    _, weight = b.sample(ctx, si, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()))
    return np.array(weight, np.float64).mean(axis=1)


def normal_incidence_table() -> None:
    from thinfilm_mi.batch.scene import setup_variant

    setup_variant("llvm_ad_spectral")
    terms = {wl: reference_terms(wl) for wl in WAVELENGTHS}
    print("\n## 'SiO2 300; Au 4' in air, diffuse albedo at normal incidence: tmm (plugin, Monte Carlo)")
    print("| ρ | model | " + " | ".join(f"{wl:.0f} nm" for wl in WAVELENGTHS) + " |")
    print("|---|---|" + "---|" * len(WAVELENGTHS))
    for rho in (0.6, 1.0):
        for model in MODELS:
            which = "exact" if model == "exact" else "paper"
            ours = plugin_albedo(model, rho)
            cells = [f"{albedo(terms[wl][which], rho, model != 'single'):.4f} ({v:.4f})"
                     for wl, v in zip(WAVELENGTHS, ours)]
            print(f"| {rho:g} | {model} | " + " | ".join(cells) + " |")
    print("\nterms (t(0), T_hemi, R_dh): " + "; ".join(
        f"{wl:.0f} nm exact {tuple(round(v, 3) for v in terms[wl]['exact'])} paper "
        f"{tuple(round(v, 4) for v in terms[wl]['paper'])}" for wl in WAVELENGTHS))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="120x80")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--skip-scenes", action="store_true", help="only the normal-incidence table")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.lower().split("x"))
    if not args.skip_scenes:
        scene_table((w, h), args.spp)
    normal_incidence_table()


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("diffuse_models"):   # --write-docs: docs/_generated/diffuse_models.md
        main()
