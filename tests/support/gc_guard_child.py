"""Child process of ``tests/cross/test_gc_guard.py``: the loop users run, in one process.

    python tests/support/gc_guard_child.py VARIANT ITERATIONS GC KIND [WHERE]

Each iteration loads a scene, renders it, makes a refused edit whose exception is kept
in a local (exception -> traceback -> frame -> locals -> scene: a reference cycle once
the function returns), renders again and returns. The next iteration's renders then
trace the dropped scene's BSDFs in Mitsuba's symbolic calls while the cyclic garbage
collector may run.

* ``thinfilm``: a scene holding every thin-film BSDF plugin, bare, inside ``blendbsdf``
  and (the reflective ones: Mitsuba nests no others) inside ``twosided``; ``thinfilm_mi``
  is imported (its guard is installed).
* ``plain``: a plain Python BSDF (Lambert, allocating as Python code does) in a process
  that does not import ``thinfilm_mi``: the defect as Mitsuba 3.9 has it, which must
  crash (the test's proof that it can fail).
* ``plain+guard``: the same, with :func:`thinfilm_mi.render.gc_guard.install` (and so
  ``thinfilm_mi``) imported.
* ``thinfilm-unguarded``: ``thinfilm`` with the guard taken out of ``gc.callbacks``.

``WHERE`` is where the loop runs: ``main`` (the default), ``worker`` (one worker thread,
while the main thread keeps running Python: a loop that appends small lists and sleeps
0.5 ms, as an event loop or a notebook kernel does) or ``workers`` (two worker threads,
each loading and rendering its own scenes, the main thread as for ``worker``). In the
``workers`` mode each iteration picks its BSDF at random (seeded per thread), so
that the two threads render different scenes; elsewhere the BSDFs come in turn.

``GC`` is ``default`` or ``1`` (``gc.set_threshold(1, 1, 1)``: a pass at every
allocation). On success it prints one line: ``ok ITERATIONS alive=N max_alive=M
freed_in_trace=F``, where N counts the BSDF instances still alive after a final
``gc.collect()``, M the most that were alive at any iteration's start (weak references, no
collection forced) and F those freed while a symbolic call was being traced.
"""
from __future__ import annotations

import gc
import math
import random
import sys
import threading
import time
import weakref

import drjit as dr
import mitsuba as mi

LAYERS = "SiO2 200; 1.8 90; 0.4+2.5j 12"
BASES = {
    "thinfilm_conductor": {"specular_reflectance": 0.9},
    "thinfilm_dielectric": {"specular_transmittance": 0.8},
    "thinfilm_diffuse": {"reflectance": 0.6},
    "thinfilm_roughconductor": {"alpha": 0.2},
    "thinfilm_roughdielectric": {"alpha": 0.2},
    "thinfilm_coating": {"bsdf": {"type": "diffuse"}},
}


def _plain_class():
    class PlainLambert(mi.BSDF):
        """Cosine sampling, Lambert eval; each traced method allocates ~2000 lists."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]
            self.albedo = mi.Float(props.get("albedo", 0.5))

        def sample(self, ctx, si, s1, s2, active=True):
            _ = [[i] for i in range(2000)]
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(s2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = mi.UInt32(0)
            return bs, dr.select(active & (bs.pdf > 0), mi.Spectrum(self.albedo), 0.0)

        def eval(self, ctx, si, wo, active=True):
            _ = [[i] for i in range(2000)]
            return mi.Spectrum(self.albedo / dr.pi) * dr.maximum(mi.Frame3f.cos_theta(wo), 0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.warp.square_to_cosine_hemisphere_pdf(wo)

        def eval_pdf(self, ctx, si, wo, active=True):
            _ = [[i] for i in range(2000)]
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            callback.put("albedo", self.albedo, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys):
            if not math.isfinite(self.albedo[0]):
                raise ValueError(f"albedo: got {self.albedo[0]}")

        def to_string(self):
            return "PlainLambert"

    return PlainLambert


def _bsdfs(kind):
    if kind.startswith("plain"):
        return {"plain": {"type": "plain_lambert"}}
    out = {}
    for name, extra in BASES.items():
        bsdf = {"type": name, "layers": LAYERS, **extra}
        out[name] = bsdf
        if "dielectric" not in name and name != "thinfilm_coating":   # twosided nests only BSDFs that do not transmit
            out[name + "_twosided"] = {"type": "twosided", "bsdf": dict(bsdf)}
        out[name + "_blend"] = {"type": "blendbsdf", "weight": 0.5, "a": dict(bsdf),
                                "b": {"type": "diffuse"}}
    return out


def _scene(bsdf):
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": 1},
                   "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}},
        "emitter": {"type": "constant"},
    }
    scene["ball"] = {"type": "sphere", "bsdf": bsdf}
    return scene


#: BSDFs freed while this thread was inside a symbolic scope, or while any thread was
#: inside Mitsuba's own ``mi.render`` (whose traces the per-thread flag does not show):
#: the defect's precondition (the next call on the freed object is a use-after-free,
#: which crashes only when the freed memory has been reused, so a crash alone is not a
#: reliable witness)
FREED_IN_TRACE = [0]
#: threads inside Mitsuba's own ``mi.render`` now
RENDERING = [0]


def _on_free():
    if dr.flag(dr.JitFlag.SymbolicScope) or RENDERING[0]:
        FREED_IN_TRACE[0] += 1


def _bracket_mitsuba_render():
    """Count the threads inside Mitsuba's own ``mi.render`` (under whatever wraps it
    later: ``thinfilm_mi`` covers it when imported, after this)."""
    render = mi.render

    def bracketed(*args, **kwargs):
        RENDERING[0] += 1
        try:
            return render(*args, **kwargs)
        finally:
            RENDERING[0] -= 1

    for name, module in list(sys.modules.items()):
        if name.partition(".")[0] == "mitsuba" and getattr(module, "render", None) is render:
            setattr(module, "render", bracketed)


def _register_counted(classes, alive):
    """Register each Python BSDF class so that every instance made is counted (weakly)
    and its freeing inside a trace is noticed."""
    def factory(cls):
        def make(props):
            bsdf = cls(props)
            alive.append(weakref.ref(bsdf))
            weakref.finalize(bsdf, _on_free)
            return bsdf
        return make
    for name, cls in classes.items():
        mi.register_bsdf(name, factory(cls))


def _iteration(bsdf):
    scene = mi.load_dict(_scene(bsdf))
    mi.render(scene, seed=1)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("thickness") or k.endswith("albedo"))
    try:
        params[key] = math.nan
        params.update()
    except Exception as e:   # noqa: BLE001 - kept in a local, as a notebook or helper keeps it
        kept = e
    else:
        raise SystemExit(f"the NaN edit of {key} was accepted")
    mi.render(scene, seed=2)
    return kept is not None


def _loop(bsdfs, iterations, alive, most, seed=None):
    """``iterations`` iterations over ``bsdfs``, in order or (with a seed) at random;
    ``most[0]`` keeps the most dropped BSDFs alive at an iteration's start."""
    rng = random.Random(seed)
    for i in range(iterations):
        alive[:] = [r for r in alive if r() is not None]
        most[0] = max(most[0], len(alive))
        _iteration(bsdfs[i % len(bsdfs)] if seed is None else rng.choice(bsdfs))


def _threaded(bsdfs, iterations, alive, most, workers):
    """The loop on ``workers`` threads while the main thread keeps running Python; a
    worker's exception is re-raised here."""
    errors = []

    def work(seed):
        try:
            _loop(bsdfs, iterations, alive, most, seed)
        except BaseException as e:   # noqa: BLE001 - reported by the main thread
            errors.append(e)

    seeds = [None] if workers == 1 else range(1, workers + 1)   # one: every BSDF in turn
    threads = [threading.Thread(target=work, args=(seed,)) for seed in seeds]
    for t in threads:
        t.start()
    junk = []
    while any(t.is_alive() for t in threads):
        junk.append([len(junk)])   # an event loop's small allocations
        if len(junk) > 1000:
            junk.clear()
        time.sleep(0.0005)
    if errors:
        raise errors[0]


def main():
    variant, iterations, threshold, kind = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    where = sys.argv[5] if len(sys.argv) > 5 else "main"
    mi.set_variant(variant)
    _bracket_mitsuba_render()
    alive = []
    if kind.startswith("plain"):
        _register_counted({"plain_lambert": _plain_class()}, alive)
        if kind == "plain+guard":
            from thinfilm_mi.render import gc_guard
            gc_guard.install()
    else:
        import importlib

        from thinfilm_mi.plugins import PLUGINS  # importing thinfilm_mi installs the guard
        _register_counted({name: getattr(importlib.import_module(f"thinfilm_mi.plugins.{module}"), cls)
                           for name, (module, cls) in PLUGINS.items()}, alive)
        if kind == "thinfilm-unguarded":   # the guard taken out: what it protects against
            from thinfilm_mi.render import gc_guard
            gc.callbacks.remove(gc_guard._guard)
    if threshold != "default":
        gc.set_threshold(int(threshold), 1, 1)
    bsdfs = list(_bsdfs(kind).values())
    most = [0]
    if where == "main":
        _loop(bsdfs, iterations, alive, most)
    else:
        _threaded(bsdfs, iterations, alive, most, {"worker": 1, "workers": 2}[where])
    gc.collect()
    left = sum(r() is not None for r in alive)
    print(f"ok {iterations} alive={left} max_alive={most[0]} freed_in_trace={FREED_IN_TRACE[0]}", flush=True)


if __name__ == "__main__":
    main()
