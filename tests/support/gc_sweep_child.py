"""Child process of ``tests/cross/test_gc_guard.py``: a sweep rendered on Dask worker
threads of this process, while its main thread runs the client's loop.

    python tests/support/gc_sweep_child.py GC OUT_DIR

The frames alternate between good ``-P`` thicknesses and refused ones (negative, NaN),
so that every other frame raises inside a worker thread and its exception is kept in
the manifest, with the garbage collector at Python's default thresholds or making a
pass at every allocation (``GC`` = ``1``). On success it prints ``ok GOOD FAILED`` (the
frames written and the frames refused).
"""
from __future__ import annotations

import gc
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
GOOD = [120.0, 240.0, 360.0]
BAD = [-5.0, math.nan, -1.0]


def main():
    threshold, out_dir = sys.argv[1], Path(sys.argv[2])
    from distributed import Client, LocalCluster

    import thinfilm_mi

    if threshold != "default":
        gc.set_threshold(int(threshold), 1, 1)
    values = [v for pair in zip(GOOD, BAD) for v in pair]
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        result = thinfilm_mi.sweep(ROOT / "scenes" / "fig8a_si_sio2.xml",
                                   parameters={"teapot.bsdf.layers.0.thickness": values},
                                   out_dir=out_dir, client=client, size="16x12", spp=2,
                                   frames_per_task=1, contact_sheet=False, progress=False)
    rows = result.rows
    good = [r for r in rows if r["status"] == "ok" and (out_dir / r["exr"]).is_file()]
    failed = [r for r in rows if r["status"] == "failed"]
    print(f"ok {len(good)} {len(failed)}", flush=True)


if __name__ == "__main__":
    main()
