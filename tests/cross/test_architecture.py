"""The package's architecture is a contract (README, "Layout"), checked here.

* The layers: a module imports only from its own layer and the layers below it
  (``[tool.importlinter]`` in ``pyproject.toml``, run with import-linter's
  ``lint-imports``), and the parts of the render layer's stack only from the parts
  below them (a second contract). A deliberate bad import makes it fail (the last test).
* No private name crosses a module boundary: a name that another module needs is
  public (no leading underscore) and documented.
* No module is over :data:`MAX_LINES` lines, but for those in :data:`ALGORITHMS`,
  each one algorithm that reads best in one file.
* No function is over :data:`MAX_FUNCTION_LINES` lines (``def`` to its last line), but
  for those in :data:`LONG_FUNCTIONS`, each with the reason it is not split yet.
* ruff (pyflakes, pycodestyle, import order; ``[tool.ruff]`` in ``pyproject.toml``)
  finds nothing in the package, tests, benchmarks and scripts.
* Every module lists its public names in ``__all__`` (each one defined or imported
  there), but for the subpackages in :data:`ALL_PENDING`.
* No plugin module imports another plugin module: what plugins share lives in the
  layers below (``render.microfacet``, ``render.reader``), as Mitsuba's BSDFs share
  ``microfacet.h``; ``plugins/__init__`` registers them.
"""
from __future__ import annotations

import importlib
import shutil

from tests.support import ROOT

ROOT = ROOT
PACKAGE = ROOT / "thinfilm_mi"
MAX_LINES = 600
#: Modules allowed over MAX_LINES lines, each one algorithm (path -> why).
ALGORITHMS = {
    "optics/core.py": "the optics core: Fresnel terms, the Rouard recursion and its loop",
    "tabulate/band.py": "the band-limited table: its sheared axis, rows, their amplitudes, the build",
    "tabulate/diffuse.py": "the RGB/mono coated-diffuse colour tables: their levels, slices and refinement",
}

MAX_FUNCTION_LINES = 80
#: Functions allowed over MAX_FUNCTION_LINES lines ("path:qualified name" -> why). The
#: test fails when an entry is no longer needed, so the list cannot go stale.
LONG_FUNCTIONS = {
    "tabulate/factors.py:FactorTable.__init__":
        "to split: a constructor that runs a whole build (build in a function that returns it)",
}

#: Subpackages whose modules may still lack ``__all__`` (none: every module has one). The
#: test fails when an entry is no longer needed, so the list cannot go stale.
ALL_PENDING: tuple = ()


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "data" not in p.parts)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _lint_imports() -> str:
    return _tool("lint-imports")


def _tool(name: str) -> str | None:
    exe = Path(sys.executable).parent / name
    return str(exe) if exe.exists() else shutil.which(name)


def test_ruff_finds_nothing():
    exe = _tool("ruff")
    assert exe, "ruff is part of the test extra (pip install -e '.[test]')"
    res = subprocess.run([exe, "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]


def test_layers_contract_is_kept():
    exe = _lint_imports()
    assert exe, "import-linter is part of the test extra (pip install -e '.[test]')"
    res = subprocess.run([exe, str(ROOT / "pyproject.toml")], cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-2000:]
    contracts = (ROOT / "pyproject.toml").read_text(encoding="utf-8").count("[[tool.importlinter.contracts]]")
    assert contracts == 2 and f"{contracts} kept, 0 broken" in res.stdout


def _private(name: str) -> bool:
    """``_x`` is private; a dunder such as ``__version__`` is not."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def test_no_private_name_is_imported_across_modules():
    offenders = []
    for path in _modules():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        here = _module_name(path)
        modules = {}   # local alias -> module imported as a module
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 \
                    and node.module.startswith("thinfilm_mi"):
                for alias in node.names:
                    target = f"{node.module}.{alias.name}"
                    if (ROOT / (target.replace(".", "/") + ".py")).exists() or \
                            (ROOT / target.replace(".", "/")).is_dir():
                        modules[alias.asname or alias.name] = target
                    elif _private(alias.name) and node.module != here:
                        offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: "
                                         f"{alias.name} from {node.module}")
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("thinfilm_mi") and alias.asname:
                        modules[alias.asname] = alias.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in modules and _private(node.attr)):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: "
                                 f"{node.value.id}.{node.attr} ({modules[node.value.id]})")
    assert not offenders, "\n".join(offenders)


def test_modules_are_short_or_one_algorithm():
    long = []
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES and rel not in ALGORITHMS:
            long.append(f"{rel}: {n} lines")
    assert not long, "\n".join(long)


def _function_lengths(source: str) -> dict[str, int]:
    """``{qualified name: lines}`` of every function in ``source``, nested ones and
    methods included (``Class.method``, ``outer.inner``), from ``def`` to its last line."""
    lengths = {}

    def visit(node, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lengths[prefix + child.name] = child.end_lineno - child.lineno + 1
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)
    visit(ast.parse(source), "")
    return lengths


def test_functions_are_short():
    lengths = {}
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        for name, n in _function_lengths(path.read_text(encoding="utf-8")).items():
            lengths[f"{rel}:{name}"] = n
    long = [f"{key}: {n} lines" for key, n in lengths.items()
            if n > MAX_FUNCTION_LINES and key not in LONG_FUNCTIONS]
    stale = [key for key in LONG_FUNCTIONS if lengths.get(key, 0) <= MAX_FUNCTION_LINES]
    assert not long, "split along the algorithm's steps:\n" + "\n".join(long)
    assert not stale, f"no longer over {MAX_FUNCTION_LINES} lines: drop from LONG_FUNCTIONS: {stale}"


def test_the_function_length_count_is_not_vacuous():
    """Methods and nested functions are counted, from ``def`` to the last line."""
    body = "".join(f"        x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    source = f"class A:\n    def long(self):\n{body}\n    def short(self):\n        def inner():\n" \
        "            return 1\n        return inner\n"
    lengths = _function_lengths(source)
    assert lengths == {"A.long": MAX_FUNCTION_LINES + 1, "A.short": 4, "A.short.inner": 2}


def test_a_lower_layer_importing_a_higher_one_breaks_the_contract(tmp_path):
    """The contract is not vacuous: a copy of the package in which a module of the
    optics layer imports the render layer fails ``lint-imports``. (Every layer is a
    whole subpackage: this module, ``optics.incoherent``, escaped a contract that
    named ``optics.core`` alone.)"""
    exe = _lint_imports()
    copy = tmp_path / "repo"
    shutil.copytree(PACKAGE, copy / "thinfilm_mi",
                    ignore=shutil.ignore_patterns("__pycache__", "data"))
    shutil.copy(ROOT / "pyproject.toml", copy / "pyproject.toml")
    low = copy / "thinfilm_mi" / "optics" / "incoherent.py"
    low.write_text(low.read_text(encoding="utf-8")
                   + "\nfrom thinfilm_mi.render import kernel as _bad  # noqa\n")
    res = subprocess.run([exe, str(copy / "pyproject.toml")], cwd=copy,
                         capture_output=True, text=True,
                         env={"PYTHONPATH": str(copy), "PATH": "/usr/bin:/bin"})
    assert res.returncode != 0
    assert "thinfilm_mi.optics is not allowed to import thinfilm_mi.render" in res.stdout
    assert "thinfilm_mi.optics.incoherent -> thinfilm_mi.render.kernel" in res.stdout


def _top_level_names(tree: ast.Module) -> set:
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
            names.update(e.id for t in targets if isinstance(t, ast.Tuple)
                         for e in t.elts if isinstance(e, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
    return names


def _dunder_all(tree: ast.Module):
    """The value of the module's top-level ``__all__`` (a list of strings), or ``None``."""
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
            return ast.literal_eval(node.value)
    return None


def test_every_module_lists_its_public_names():
    missing, unknown, pending = [], [], set()
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = _dunder_all(tree)
        if names is None:
            if rel.split("/")[0] in ALL_PENDING:
                pending.add(rel.split("/")[0])
            else:
                missing.append(rel)
            continue
        defined = _top_level_names(tree)
        lazy = [n for n in names if n not in defined]
        if lazy and "__getattr__" in defined:          # names the module imports on first use
            module = importlib.import_module(_module_name(path))
            lazy = [n for n in lazy if not hasattr(module, n)]
        unknown += [f"{rel}: {n}" for n in lazy]
    assert not missing, "modules without __all__:\n" + "\n".join(missing)
    assert not unknown, "names in __all__ that the module does not define:\n" + "\n".join(unknown)
    assert pending == set(ALL_PENDING), \
        f"every module of {sorted(set(ALL_PENDING) - pending)} has __all__ now: take it off ALL_PENDING"


def _imported_modules(path: Path, root: Path = ROOT) -> set:
    """Every ``thinfilm_mi`` module or package the module at ``path`` imports, at any
    depth (in functions too), relative imports resolved, ``from P import x`` as both
    ``P`` and ``P.x``."""
    package = ".".join(path.relative_to(root).parts[:-1])
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return {m for m in found if m == "thinfilm_mi" or m.startswith("thinfilm_mi.")}


def _plugin_to_plugin(path: Path, root: Path = ROOT) -> list[str]:
    """The modules of :mod:`thinfilm_mi.plugins` (the package included) that the
    plugin module at ``path`` imports."""
    return sorted(m for m in _imported_modules(path, root)
                  if m == "thinfilm_mi.plugins" or m.startswith("thinfilm_mi.plugins."))


def test_no_plugin_module_imports_another():
    plugins = sorted(p for p in (PACKAGE / "plugins").glob("*.py") if p.name != "__init__.py")
    assert len(plugins) >= 6
    offenders = [f"{p.relative_to(ROOT)} imports {m}" for p in plugins for m in _plugin_to_plugin(p)]
    assert not offenders, "\n".join(offenders) + "\n(move what they share to thinfilm_mi.render)"


def test_the_plugin_import_check_is_not_vacuous(tmp_path):
    """A plugin module importing another (absolute, relative, or in a function) is caught."""
    plugin = tmp_path / "thinfilm_mi" / "plugins" / "thinfilm_new.py"
    plugin.parent.mkdir(parents=True)
    cases = ("from thinfilm_mi.plugins.thinfilm_conductor import NAME\n",
             "from thinfilm_mi.plugins import thinfilm_conductor\n",
             "from .thinfilm_conductor import NAME\n",
             "def f():\n    import thinfilm_mi.plugins.thinfilm_conductor\n")
    for text in cases:
        plugin.write_text("from thinfilm_mi.render import modes\n" + text, encoding="utf-8")
        assert "thinfilm_mi.plugins.thinfilm_conductor" in _plugin_to_plugin(plugin, tmp_path), text


import ast
import subprocess
import sys
from pathlib import Path

from tests.support.design import REPO


def test_importing_thinfilm_mi_imports_neither_design_nor_scipy():
    code = ("import sys, thinfilm_mi; print('thinfilm_mi.design' in sys.modules, 'scipy' in sys.modules); "
            "thinfilm_mi.design; print('thinfilm_mi.design' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["False", "False", "True"], out.stderr


def test_design_imports_only_lower_layers_and_public_names():
    """design/ needs no renderer: it imports the optics, materials, colour and error
    layers of the package (public names only), never the render layer, Mitsuba or
    Dr.Jit (tests/cross/test_architecture.py checks the layers of the whole package)."""
    allowed = {"optics", "materials", "colour", "errors", "design"}
    for path in sorted((REPO / "thinfilm_mi" / "design").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                top = node.module.split(".")
                assert top[0] not in ("mitsuba", "drjit"), (path.name, node.module)
                if top[0] == "thinfilm_mi":
                    layer = top[1] if len(top) > 1 else node.names[0].name
                    assert layer in allowed, (path.name, node.module)
                    assert not any(a.name.startswith("_") for a in node.names), (path.name, node.module)
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] in ("mitsuba", "drjit") for a in node.names)

