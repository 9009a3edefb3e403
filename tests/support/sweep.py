"""The sweeps' scene, bounds and manifest reader (the fixtures are in tests/conftest.py)."""
from __future__ import annotations

import csv
from pathlib import Path

from thinfilm_mi.batch import outputs

TIMEOUT = 120  # seconds: bound of every sweep (they take a few seconds)
THICKNESS = "sphere.bsdf.layers.0.thickness"

SCENE = """<scene version="3.0.0">
  <default name="thickness" value="300"/>
  <default name="material" value="Au"/>
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="sphere" id="sphere">
    <bsdf type="thinfilm_conductor">
      <string name="material" value="$material"/>
      <string name="layers" value="SiO2 $thickness"/>
    </bsdf>
  </shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""


def read_manifest(out: Path) -> list[dict[str, str]]:
    with open(out / outputs.MANIFEST, newline="") as f:
        return list(csv.DictReader(f))
