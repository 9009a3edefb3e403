"""Child process of tests/cross/test_parallel_load.py: one parallel scene load in a fresh
process, with the race's window widened. Prints ``ok`` or ``FAIL <error>``.

Every thin-film plugin type (with many constant-index films: each index was a
nested ``mi.load_dict`` before the fix, and each swapped the global FileResolver)
is mixed with C++ plugins that resolve file names (``bitmap``, ``ply``,
``hdrfilm``, and the first loading of each plugin library) on Mitsuba's loader
threads. Three hundred non-existent folders in front of the resolver make each
resolution ~300 ``exists`` calls long, the window in which a freed resolver copy
is read.
"""
import os
import sys

import mitsuba as mi

mi.set_variant(sys.argv[2] if len(sys.argv) > 2 else "llvm_ad_spectral")
mi.set_log_level(mi.LogLevel.Error)
import thinfilm_mi  # noqa: E402,F401  (registers the plugins)

ROOT = sys.argv[1]
resolver = mi.file_resolver()
for i in range(300):
    resolver.prepend(f"/nonexistent/thinfilm_race_{i}")
resolver.append(os.path.join(ROOT, "scenes"))

films = "; ".join(f"{1.3 + 0.01 * i:.2f} {10 + i}" for i in range(20))
bsdfs = [
    f'<bsdf type="thinfilm_conductor"><string name="material" value="Au"/>'
    f'<string name="tabulate" value="false"/><string name="layers" value="{films}"/></bsdf>',
    f'<bsdf type="thinfilm_dielectric"><string name="layers" value="{films}"/></bsdf>',
    f'<bsdf type="thinfilm_diffuse"><string name="layers" value="{films}"/></bsdf>',
    f'<bsdf type="thinfilm_roughconductor"><string name="material" value="Cu"/>'
    f'<float name="alpha" value="0.2"/><string name="layers" value="{films}"/></bsdf>',
    f'<bsdf type="thinfilm_roughdielectric"><float name="alpha" value="0.2"/>'
    f'<string name="layers" value="{films}"/></bsdf>',
]
parts = []
for j in range(8):
    parts.append(f'<shape type="sphere"><point name="center" value="{j}, 0, 0"/>{bsdfs[j % 5]}</shape>')
    parts.append('<shape type="ply"><string name="filename" value="meshes/teapot.ply"/>'
                 '<bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
                 '<string name="filename" value="textures/soap_film.exr"/>'
                 '<boolean name="raw" value="true"/></texture></bsdf></shape>')
xml = ('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">'
       '<integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>'
       + "".join(parts) + "</scene>")
try:
    scene = mi.load_string(xml, parallel=True)
except Exception as e:  # noqa: BLE001 - the failure is the message
    print("FAIL", str(e)[:300], flush=True)
    sys.exit(1)
kinds = sorted({type(s.bsdf()).__name__ for s in scene.shapes()})
print("ok", " ".join(kinds), flush=True)
