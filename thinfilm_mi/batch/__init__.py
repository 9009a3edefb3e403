"""The batch layer: sweeps of scene renders over Dask (EXR output).

* :mod:`thinfilm_mi.batch.sweeps` -- parameter sweeps (imports Dask ``distributed``).
* :mod:`thinfilm_mi.batch.exr` -- EXR writing and reading.
"""
