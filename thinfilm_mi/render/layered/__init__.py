"""The layered BSDF engine: a top interface over a bottom, the light between them summed by
a registered estimator (pbrt-v4's ``LayeredBxDF``; no plugin classes here). The modules:

* :mod:`~thinfilm_mi.render.layered.engine` — :class:`~thinfilm_mi.render.layered.engine.Layered`,
  the engine (components, enabled lobes, parameters), the registry of estimators by the
  kinds of top and bottom (:data:`~thinfilm_mi.render.layered.engine.ESTIMATORS`) and
  :func:`~thinfilm_mi.render.layered.engine.layered`, which builds the engine;
* :mod:`~thinfilm_mi.render.layered.top` — the top interface (:class:`~thinfilm_mi.render.layered.top.Top`)
  and the smooth thin-film stack (:class:`~thinfilm_mi.render.layered.top.SmoothTop`);
* :mod:`~thinfilm_mi.render.layered.bottom` — a diffuse bottom, a nested Mitsuba BSDF;
* :mod:`~thinfilm_mi.render.layered.coat` — the absorbing medium between them;
* :mod:`~thinfilm_mi.render.layered.models` — the closed forms over a diffuse bottom (the
  paper's ``single`` and ``multiple``, the ``exact`` one), applied by
  :mod:`~thinfilm_mi.render.layered.series` from the spectral factors and load-time terms
  of :mod:`~thinfilm_mi.render.layered.factors`;
* :mod:`~thinfilm_mi.render.layered.coated` — what the two estimators over a nested BSDF
  share (:class:`~thinfilm_mi.render.layered.coated.CoatedEstimator`);
* :mod:`~thinfilm_mi.render.layered.nested` — the estimator over a nested BSDF, summed by a
  closed form (:mod:`~thinfilm_mi.render.layered.forms`) or the random walk
  (:mod:`~thinfilm_mi.render.layered.walk`), with the delta-base chain
  (:mod:`~thinfilm_mi.render.layered.delta`);
* :mod:`~thinfilm_mi.render.layered.rough` — the estimator under a rough top
  (:class:`~thinfilm_mi.render.layered.top.RoughTop`), pbrt-v4's walk with next-event
  estimation through it.
"""

__all__: list = []
