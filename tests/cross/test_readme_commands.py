"""Every shell command the README and the documentation print runs, exactly as printed
(issues 30 and 41).

The commands are read from README.md and from the Markdown pages of the documentation
site (``docs/**/*.md``; not the files they ``{include}``, such as benchmarks/README.md,
whose benchmark runs take minutes): their shell code blocks (indented blocks
and ``sh``/``bash``/``console`` fences whose first line is a command; a line
``$ CMD`` is a command whose printed output follows it). Each one is either
run here, by ``bash -c`` on its printed text (comment and all), and its outputs
checked (:data:`CHECKS`), or named in :data:`NOT_RUN` with the reason it cannot
be; a command in neither fails :func:`test_every_readme_command_is_run_or_listed`,
so a command added to the README or the docs must come with its test. A command
printed in several places (the same text and printed output) runs once.

The commands run in a temporary copy of what they read (``scenes/``, the
Makefile, ``pyproject.toml``, ``scripts/``, ``examples/``, ``docs/`` and the
``benchmarks/README.md`` it includes, and ``.venv`` as a link), so their
``out/`` folder is not the checkout's. ``thinfilm-render`` is the console script
of the interpreter running the tests and ``python`` that interpreter (both put
first on ``PATH``), as in the activated virtual environment the README assumes.
"""
from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OpenEXR")

from tests.support import ROOT
from thinfilm_mi import Stack  # noqa: E402
from thinfilm_mi.batch.exr import read_exr  # noqa: E402

REPO = ROOT
README = REPO / "README.md"
DOCS = REPO / "docs"
#: the documentation's Markdown pages (not its build, nor the generated plugin pages and
#: benchmark tables: the tables quote the command that wrote them, a benchmark run of minutes)
DOC_PAGES = sorted(p for p in DOCS.rglob("*.md") if not {"_build", "_generated"} & set(p.relative_to(DOCS).parts))
TIMEOUT = 600  # seconds, per command (they take 1-20 s)

#: a line of a code block is a shell command when it starts like one
COMMAND_START = re.compile(r"^(\w+=\S*\s+)*(make|thinfilm-render|python3?|dask|pip3?|pytest|jupyter|"
                           r"git|cd|bash|sh|\./\S+|\S+\.(py|sh))(\s|$)")
SHELL_FENCES = {"", "sh", "bash", "shell", "console"}


@dataclass(frozen=True)
class Command:
    text: str                       # as printed, continuation lines joined
    line: int                       # in its source
    output: tuple[str, ...] = ()    # the output printed under a `$ CMD` line
    source: str = "README.md"       # the file that prints it, relative to the repository

    @property
    def key(self) -> str:
        """The command without its trailing comment and with single spaces."""
        return " ".join(strip_comment(self.text).split())


def strip_comment(text: str) -> str:
    """``text`` up to an unquoted ``#`` that starts a word (a shell comment)."""
    quote = None
    for i, c in enumerate(text):
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or text[i - 1].isspace()):
            return text[:i].rstrip()
    return text.rstrip()


def _blocks(lines: list[str]):
    """``(first line number, lines)`` of each code block that may hold commands:
    fences of :data:`SHELL_FENCES` and indented blocks (unindented by 4)."""
    i, after_blank = 0, True
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            if line[3:].strip() in SHELL_FENCES:
                yield i + 2, lines[i + 1:j]
            i, after_blank = j + 1, False
            continue
        if line.startswith("    ") and line.strip() and after_blank:
            j = i
            while j < len(lines) and (lines[j].startswith("    ") or not lines[j].strip()):
                j += 1
            yield i + 1, [x[4:] for x in lines[i:j]]
            i, after_blank = j, True
            continue
        after_blank = not line.strip()
        i += 1


def readme_commands(text: str, source: str = "README.md") -> list[Command]:
    """The shell commands of a README or a docs page (see the module docstring)."""
    commands: list[Command] = []
    for start, block in _blocks(text.splitlines()):
        body = [x for x in block if x.strip()]
        if not body or not COMMAND_START.match(body[0].removeprefix("$ ")):
            continue
        prompt = any(x.startswith("$ ") for x in body)
        i = 0
        while i < len(block):
            line, number = block[i], start + i
            i += 1
            if not line.strip():
                continue
            text = line.removeprefix("$ ").rstrip()
            while strip_comment(text).endswith("\\") and i < len(block):
                text = strip_comment(text)[:-1].rstrip() + " " + block[i].strip()
                i += 1
            output = []
            if prompt:
                while i < len(block) and block[i].strip() and not block[i].startswith("$ "):
                    output.append(block[i].rstrip())
                    i += 1
            commands.append(Command(text, number, tuple(output), source))
    return commands


def printed_commands() -> list[Command]:
    """The commands of README.md and of every docs page, each (text and output) once."""
    found: dict[tuple, Command] = {}
    for path in [README, *DOC_PAGES]:
        for c in readme_commands(path.read_text(encoding="utf-8"), str(path.relative_to(REPO))):
            found.setdefault((c.key, c.output), c)
    return list(found.values())


COMMANDS = printed_commands()

#: README commands that a test cannot run, and why
NOT_RUN = {
    "make test": "runs this test suite, this file included: it would recurse",
    "dask scheduler": "starts a cluster's scheduler, which serves until it is killed",
    "dask worker tcp://HEAD:8786 --nworkers 8 --nthreads 1":
        "HEAD stands for the head node's address (no cluster here)",
    "thinfilm-render sweep scenes/demo.xml -D sio2=100:800:5 --scheduler tcp://HEAD:8786 "
    "--threads 4 --out-dir /shared/out/sweep":
        "HEAD stands for the head node's address and /shared for a cluster's shared "
        "filesystem; the same sweep on a local cluster is run (the README's sweeps above)",
}


# --------------------------------------------------------------------------------------
# where the commands run


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """A copy of what the commands read (see the module docstring)."""
    root = tmp_path_factory.mktemp("readme")
    shutil.copytree(REPO / "scenes", root / "scenes")
    shutil.copytree(REPO / "scripts", root / "scripts")
    shutil.copytree(REPO / "examples", root / "examples")
    shutil.copytree(REPO / "notebooks", root / "notebooks")   # docs/notebooks links to them
    shutil.copytree(DOCS, root / "docs", symlinks=True, ignore=lambda folder, names: [
        n for n in names if n == "_build" or (Path(folder).name == "plugins" and n.endswith(".rst"))])
    (root / "benchmarks").mkdir()
    shutil.copy2(REPO / "benchmarks" / "README.md", root / "benchmarks" / "README.md")
    for name in ("Makefile", "pyproject.toml"):
        shutil.copy2(REPO / name, root / name)  # mtimes kept: make compares them
    if (REPO / ".venv").is_dir():
        (root / ".venv").symlink_to(REPO / ".venv")
    return root


@pytest.fixture(scope="module")
def env(tmp_path_factory) -> dict[str, str]:
    """``python`` is this interpreter; ``thinfilm-render`` its console script."""
    bin_dir = tmp_path_factory.mktemp("bin")
    # a script, not a link: a virtual environment's python knows it is one by its path
    (bin_dir / "python").write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    (bin_dir / "python").chmod(0o755)
    scripts = sysconfig.get_path("scripts")
    path = os.pathsep.join([str(bin_dir), scripts, os.environ.get("PATH", "")])
    return {**os.environ, "PATH": path}


def run(command: Command, workdir: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    proc = subprocess.run(["bash", "-c", command.text], cwd=workdir, env=env, capture_output=True,
                          text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, (f"{command.source} line {command.line}: `{command.text}` exited "
                                  f"{proc.returncode}:\n{proc.stderr[-4000:]}")
    return proc


# --------------------------------------------------------------------------------------
# what each command must produce


def _render(exr: Path, size: tuple[int, int], spp: int, variant: str = "llvm_ad_spectral",
            parameters: str = "") -> dict[str, np.ndarray]:
    """The checks of one ``thinfilm-render`` output; returns its channels."""
    channels, header = read_exr(exr)
    image = np.stack([channels[c] for c in "RGB"], -1)
    assert image.shape == (size[1], size[0], 3), (exr, image.shape)
    assert np.all(np.isfinite(image)) and image.mean() > 1e-3, exr
    assert (header["variant"], header["spp"], header["parameters"]) == (variant, spp, parameters)
    assert exr.with_suffix(".png").is_file()
    return channels


def check_make_demo(proc, root, command):
    # "`make demo` renders at the scene's size (400×266) with 64 samples per pixel"
    _render(root / "out" / "demo.exr", (400, 266), 64)


def check_make_docs(proc, root, command):
    # the site, built with warnings as errors: a page per plugin, generated from its doc
    # block, with an anchor for every parameter the block lists (docs/_ext/thinfilm_plugins.py)
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import thinfilm_plugins as ext
    finally:
        sys.path.pop(0)
    html = root / "docs" / "_build" / "html"
    gallery = json.loads(ext.GALLERY_MANIFEST.read_text(encoding="utf-8"))
    for path in ext.plugin_files():
        page = (html / "plugins" / f"{path.stem}.html").read_text(encoding="utf-8")
        for name in ext.documented_parameters(ext.doc_block(path)):
            assert f'id="{path.stem}-{name}"'.replace("_", "-") in page, (path.stem, name)
        assert "XML (scene file)" in page and "Python (dictionary for mi.load_dict)" in page, path.stem
        # its gallery row (scripts/make_gallery.py), every picture copied beside the page
        for entry in gallery[path.stem]:
            assert f'src="../_images/{entry["png"]}"' in page, entry["png"]
            assert (html / "_images" / entry["png"]).is_file(), entry["png"]
    api = (html / "api.html").read_text(encoding="utf-8")
    for name in ("thinfilm_mi.Stack", "thinfilm_mi.resolve_material", "thinfilm_mi.colour.report.colour_report",
                 "thinfilm_mi.design.design", "thinfilm_mi.design.fit", "thinfilm_mi.batch.sweeps.sweep"):
        assert f'id="{name}"' in api, name
    for page in ("getting-started", "limitations", "physics", "benchmarks", "upstream_gc_during_symbolic_call"):
        assert (html / f"{page}.html").is_file(), page
    # every notebook is a page, showing the figures stored in it (myst-nb, not executed)
    for path in sorted((REPO / "notebooks").glob("*.ipynb")):
        cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
        figures = sum("image/png" in o.get("data", {}) for c in cells if c["cell_type"] == "code"
                      for o in c.get("outputs", []))
        page = (html / "notebooks" / f"{path.stem}.html").read_text(encoding="utf-8")
        assert page.count("<img ") >= figures, (path.stem, figures)


def check_fig8a(proc, root, command):
    _render(root / "out" / "fig8a_si_sio2.exr", (400, 266), 16, parameters="thickness=480")


def check_all_scenes(proc, root, command):
    scenes = sorted((root / "scenes").glob("*.xml"))
    assert len(scenes) > 10
    for scene in scenes:
        polarized = 'type="stokes"' in scene.read_text()
        channels = _render(root / "out" / "all" / f"{scene.stem}.exr", (200, 133), 4,
                           "llvm_ad_spectral_polarized" if polarized else "llvm_ad_spectral")
        assert ("S3.G" in channels) == polarized, scene
    # the scene that needs a polarized variant says so, in one line
    assert proc.stderr.count("which needs a polarized variant") == 1, proc.stderr


def _table(stdout: str) -> tuple[list[str], np.ndarray]:
    rows = [line.split() for line in stdout.splitlines() if line.strip() and not line.startswith("#")]
    return rows[0], np.array(rows[1:], dtype=float)


def check_spectrum(proc, root, command):
    # the R and T of the printed stack at the printed angles, on the default grid
    header, table = _table(proc.stdout)
    assert header == ["wl_nm", "R@0", "T@0", "R@45", "T@45", "R@70", "T@70"]
    stack = Stack("SiO2 500; Au 20", substrate=1.6)
    for j, angle in enumerate((0.0, 45.0, 70.0)):
        res = stack.rt(table[:, 0], np.radians(angle))
        np.testing.assert_allclose(table[:, 1 + 2 * j], res.R, atol=1e-6)  # 6 printed decimals
        np.testing.assert_allclose(table[:, 2 + 2 * j], res.T, atol=1e-6)


def _colour_rows(stdout: str) -> list[list[str]]:
    lines = [line.split() for line in stdout.splitlines() if line.strip() and line[0] != "#"]
    assert lines[0][:2] == ["angle", "qty"], stdout
    return lines[1:]


def check_colour_mgf2(proc, root, command):
    rows = _colour_rows(proc.stdout)
    assert [(r[0], r[1]) for r in rows] == [(str(a), q) for a in range(0, 81, 10) for q in "RT"]


def check_materials(proc, root, command):
    names = {line.split()[0] for line in proc.stdout.splitlines() if line.strip()}
    assert {"Au", "SiO2", "TiO2", "BK7"} <= names, proc.stdout[:2000]


def check_colour_table(proc, root, command):
    # the printed output is the head of the real one (up to its "..."), digit for digit
    shown = list(command.output)
    assert shown[-1].strip() == "..." and len(shown) > 2
    assert proc.stdout.splitlines()[:len(shown) - 1] == shown[:-1], proc.stdout


def _sweep(root: Path, columns: dict[str, list[str]], size: tuple[int, int], spp: list[int]):
    """The checks of ``out/sweep`` after a sweep over ``columns`` (the grid, in order)."""
    out = root / "out" / "sweep"
    with open(out / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    names = list(columns)
    grid = [dict(zip(names, values)) for values in np.array(
        np.meshgrid(*columns.values(), indexing="ij")).reshape(len(names), -1).T]
    assert [{k: r[k] for k in names} for r in rows] == grid
    assert all(r["status"] == "ok" for r in rows), rows
    for row, frame_spp in zip(rows, spp):
        _render(out / row["exr"], size, frame_spp,
                parameters=" ".join(f"{k}={row[k]}" for k in names))
    assert (out / "contact_sheet.png").is_file() and (out / "sweep.json").is_file()


def check_sweep(proc, root, command):
    _sweep(root, {"sio2": ["200", "400", "600", "800"], "spp": ["16"]}, (160, 106), [16] * 4)


def check_sweep_workers(proc, root, command):
    _sweep(root, {"sio2": ["200", "500", "800"], "spp": ["4", "16"]}, (160, 106), [4, 16] * 3)
    assert "with 2 worker(s)" in proc.stderr, proc.stderr


def _ar_reflectance(layers: str) -> np.ndarray:
    """R at normal incidence over 420-680 nm of a designed AR stack on n = 1.52, by tmm."""
    import tmm

    films = [f.split() for f in layers.split(";")]
    n = [1.0] + [float(m) for m, _ in films] + [1.52]
    d = [np.inf] + [float(t) for _, t in films] + [np.inf]
    return np.array([tmm.coh_tmm("s", n, d, 0.0, lam)["R"] for lam in range(420, 681, 5)])


def check_design_ar(proc, root, command):
    layers = next(line for line in proc.stdout.splitlines() if line.startswith("layers:"))
    R = _ar_reflectance(layers.split(":", 1)[1])
    # the targets, R_avg <= 0.15 % and R_max <= 0.35 %, checked by tmm
    assert R.mean() <= 0.0015 and R.max() <= 0.0035, (R.mean(), R.max())


def check_design_ar_json(proc, root, command):
    out = json.loads(proc.stdout)
    assert {"layers", "merit", "seconds", "targets", "tolerance"} <= set(out)
    assert _ar_reflectance(out["layers"]).max() <= 0.0035
    assert out["tolerance"]


def check_design_decorative(proc, root, command):
    assert (root / "out" / "decorative_design.png").stat().st_size > 0
    assert (root / "out" / "decorative.png").stat().st_size > 0


def check_fit(proc, root, command):
    # the stack as built (examples/fit/make_data.py): each fitted value within 3 standard errors
    truth = {"d[0]": 14.2, "d[1]": 33.5, "d[2]": 118.0, "d[3]": 93.7, "H.A": 2.25, "H.B": 0.03,
             "data[2].scale": 0.98}
    rows = {}
    for line in proc.stdout.splitlines():              # the parameter table comes before the correlations
        if line.strip() and line.split()[0] in truth:
            rows.setdefault(line.split()[0], line.split()[1:3])
    assert set(rows) == set(truth), proc.stdout
    for name, value in truth.items():
        fitted, se = map(float, rows[name])
        assert abs(fitted - value) <= 3 * se, (name, fitted, se, value)
    assert (root / "out" / "fit_spectra.png").stat().st_size > 0
    assert (root / "out" / "fit.png").stat().st_size > 0 and (root / "out" / "fit_H.csv").is_file()


#: README command -> the check of what it produced, ``check(proc, workdir, command)``
CHECKS = {
    "make demo": check_make_demo,
    "make docs": check_make_docs,
    "thinfilm-render scenes/fig8a_si_sio2.xml --spp 16 --size 400x266 -D thickness=480": check_fig8a,
    "thinfilm-render scenes/*.xml --size 200x133 --spp 4 --out-dir out/all": check_all_scenes,
    'python -m thinfilm_mi spectrum --layers "SiO2 500; Au 20" --substrate 1.6 --angles 0,45,70':
        check_spectrum,
    'python -m thinfilm_mi colour --layers "MgF2 99.6" --substrate 1.52 --angles 0:80:10':
        check_colour_mgf2,
    "python -m thinfilm_mi materials": check_materials,
    'python -m thinfilm_mi colour --layers "1.38 99.6" --substrate 1.52 --angles 0:60:30':
        check_colour_table,
    "thinfilm-render sweep scenes/demo.xml -D sio2=200:800:200 -D spp=16 --size 160x106 "
    "--out-dir out/sweep": check_sweep,
    "thinfilm-render sweep scenes/demo.xml -D sio2=200:800:300 -D spp=4,16 --workers 2 "
    "--size 160x106": check_sweep_workers,
    "python -m thinfilm_mi design examples/design/ar.yml": check_design_ar,
    "python -m thinfilm_mi design examples/design/ar.yml --tolerance 1%:200 --json":
        check_design_ar_json,
    "python -m thinfilm_mi design examples/design/decorative.yml --plot "
    "out/decorative_design.png --render out/decorative.png --size 160x106 --spp 8":
        check_design_decorative,
    "python -m thinfilm_mi fit examples/fit/measurements.yml --plot out/fit_spectra.png --render out/fit.png "
    "--size 160x106 --spp 8": check_fit,
}


# --------------------------------------------------------------------------------------
# tests


def test_every_readme_command_is_run_or_listed():
    keys = [c.key for c in COMMANDS]
    unknown = [f"{c.source} line {c.line}: {c.key}" for c in COMMANDS if c.key not in CHECKS and c.key not in NOT_RUN]
    assert not unknown, ("README/docs commands with no test: add each to CHECKS (with a check of "
                         "its output) or, if a test cannot run it, to NOT_RUN with the reason:\n"
                         + "\n".join(unknown))
    stale = sorted((set(CHECKS) | set(NOT_RUN)) - set(keys))
    assert not stale, f"no longer in the README or the docs: {stale}"
    assert not set(CHECKS) & set(NOT_RUN)


def test_commands_are_read_as_printed():
    # the reader itself, on a README-like text: prompts, outputs, comments,
    # continuation lines, and blocks that are not shell
    text = ("Intro\n\n    make demo    # a comment\n    make test\n\n```python\nimport x\n```\n\n"
            "    $ python -m thinfilm_mi colour --layers \"1.38 99.6\"\n     angle qty\n"
            "         0   R\n        ...\n\nText.\n\n    dask worker tcp://HEAD:8786 \\\n"
            "        --nthreads 1                # per node\n\nA table:\n\n    not a command\n\n"
            "```sh\nthinfilm-render a.xml  # one\n```\n")
    commands = readme_commands(text)
    assert [c.key for c in commands] == [
        "make demo", "make test", 'python -m thinfilm_mi colour --layers "1.38 99.6"',
        "dask worker tcp://HEAD:8786 --nthreads 1", "thinfilm-render a.xml"]
    assert commands[0].text == "make demo    # a comment" and commands[0].line == 3
    assert commands[2].output == (" angle qty", "     0   R", "    ...")
    assert strip_comment('python -c "print(1)  # not a comment"') == 'python -c "print(1)  # not a comment"'


@pytest.mark.parametrize("command", [c for c in COMMANDS if c.key in CHECKS], ids=lambda c: c.key)
def test_readme_command(command, workdir, env):
    if command.key.startswith("make "):
        if shutil.which("make") is None:
            pytest.skip("no make on this machine")
        # `make demo` first (re)creates .venv when its stamp is older than
        # pyproject.toml or missing: pip, minutes, network; this needs the venv built
        stamp = subprocess.run(["make", "-q", ".venv/.installed-stamp"], cwd=workdir, env=env)
        if stamp.returncode != 0:
            pytest.skip("the checkout's .venv is not built and current (`make venv`)")
    CHECKS[command.key](run(command, workdir, env), workdir, command)
