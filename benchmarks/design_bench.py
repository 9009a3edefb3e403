"""Coating design benchmarks (issue 34), every design checked with tmm.

    .venv/bin/python benchmarks/design_bench.py [--cases 30] [--seed 1]

1. Broadband AR: ``examples/design/ar.yml`` (n = 1.38 / 2.35 on 1.52, at most 8
   films, no start) designed from scratch; wall and CPU seconds, and R_avg, R_max
   over 420-680 nm at 1 nm from tmm's ``coh_tmm`` of the returned ``layers``.
   Targets: R_avg <= 0.15 %, R_max <= 0.35 %, within 60 s on the 2-core machine.
2. Colour targets a 3-film stack can reach: ``--cases`` random stacks (n = 1.46 /
   2.35 alternating, 20-300 nm each, on 1.52) give L*a*b* targets at 0, 30 and
   60 degrees (D65, 2°, tmm + colour-science); each is designed from no start
   (at most 3 films, 8 seeds) and counts as reached when the design's colours,
   again from tmm + colour-science, are within dE2000 2 of every target.
3. ``examples/design/decorative.yml`` (two colours, at most 7 films): seconds and merit.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.support.design import labs, numeric_layers, tmm_rt  # noqa: E402  (the tests' tmm + colour-science)
from thinfilm_mi.design import design  # noqa: E402
from thinfilm_mi.design.colourmath import delta_e2000  # noqa: E402


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def ar() -> None:
    result, wall, cpu = timed(lambda: design(REPO / "examples" / "design" / "ar.yml"))
    wl = np.arange(420.0, 680.5, 1.0)
    R, _ = tmm_rt(numeric_layers(result.layers), 1.52, 1.0, wl, 0.0)
    ok = R.mean() <= 0.0015 and R.max() <= 0.0035 and wall <= 60
    print(f"AR: {len(result.design.films)} films in {wall:.1f} s wall ({cpu:.1f} s CPU): "
          f"R_avg {100 * R.mean():.3f} %, R_max {100 * R.max():.3f} % (tmm, 420-680 nm at 1 nm) "
          f"-> target {'met' if ok else 'MISSED'}")
    print(f"    layers: {result.layers}")


def colour_cases(cases: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    angles = [0.0, 30.0, 60.0]
    reached, walls, worst = 0, [], []
    for case in range(cases):
        first = int(rng.integers(2))
        truth = [((1.46, 2.35)[(first + k) % 2], float(rng.uniform(20, 300))) for k in range(3)]
        wanted = labs(truth, angles)
        targets = {"substrate": "1.52", "materials": ["1.46", "2.35"], "max_layers": 3, "seeds": 8,
                   "targets": [{"quantity": "colour", "angles": [a], "Lab": wanted[i].tolist(), "tolerance": 1.0}
                               for i, a in enumerate(angles)]}
        result, wall, _ = timed(lambda: design(targets))
        dE = delta_e2000(wanted, labs(numeric_layers(result.layers), angles))
        reached += bool(np.all(dE <= 2.0))
        walls.append(wall)
        worst.append(float(dE.max()))
        print(f"  case {case:2d}: {'reached' if dE.max() <= 2 else 'MISSED '} max dE2000 {dE.max():6.3f} "
              f"in {wall:.1f} s  truth {'; '.join(f'{n} {d:.1f}' for n, d in truth)} -> {result.layers}",
              flush=True)
    print(f"colour: {reached}/{cases} reached within dE2000 2 at 0, 30, 60 deg "
          f"({100 * reached / cases:.0f} %); seconds per design mean {np.mean(walls):.1f}, max {np.max(walls):.1f}; "
          f"median max-dE {np.median(worst):.2g}")


def decorative() -> None:
    result, wall, cpu = timed(lambda: design(REPO / "examples" / "design" / "decorative.yml"))
    print(f"decorative: {len(result.design.films)} films, merit {result.merit:.3g} in {wall:.1f} s wall "
          f"({cpu:.1f} s CPU)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=30, help="random colour targets (default 30)")
    p.add_argument("--seed", type=int, default=1, help="seed of the random stacks (default 1)")
    args = p.parse_args()
    ar()
    colour_cases(args.cases, args.seed)
    decorative()


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("design_bench"):   # --write-docs: docs/_generated/design_bench.md
        main()
