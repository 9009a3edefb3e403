"""Built tables kept on disk between processes, as Dr.Jit keeps its compiled kernels.

A band-limited table of a 10- or 30-film stack takes 0.3-1 s to build
(:mod:`thinfilm_mi.tabulate.band`) and is then read in milliseconds: a script run
again, a CLI render, or a sweep's worker processes would otherwise rebuild the same
table in every process. :class:`TableStore` keeps each built table (and each stack
found not tabulable, with its build report) in one file per key under a directory:

* **where**: ``$THINFILM_MI_TABLE_CACHE`` if set (``off``, ``0`` or empty: no
  store), else ``$XDG_CACHE_HOME/thinfilm-mi/tables`` (``~/.cache/...``);
  :func:`default_store`;
* **which key**: the caller's key of the table's optics (the render layer's, which
  also keys this process's ``TableCache``: every index on the 1 nm grid, the
  thicknesses, the variant, the target...) hashed with :func:`code_fingerprint`:
  the source of this package and the versions of Mitsuba, Dr.Jit and NumPy, so a
  table built by other code is never read;
* **what is read back**: the float32 texture values exactly as built (with a
  band-limited table's shear, :class:`thinfilm_mi.tabulate.band.Shear`, and how they
  are interpolated: the spline's coefficients or its bilinear resampling,
  :data:`~thinfilm_mi.tabulate.base.INTERPOLATIONS`), or a
  coated-diffuse :class:`~thinfilm_mi.tabulate.factors.FactorTable`'s buffers and
  layout, so a table from the store gives the same image bit for bit as the one it
  stands for (``tests/tabulate/test_store.py``);
* **safety**: files are written under a temporary name and renamed (atomic on one
  file system: another process never reads half a file), read with
  ``allow_pickle=False`` and checked (shape, channels or layout, finite values); a file that
  fails is removed and the table rebuilt. A store that cannot be written (a
  read-only home) is skipped without error. The store is bounded
  (:data:`MAX_BYTES`): the least recently used files go first.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import threading
from pathlib import Path

import numpy as np

from thinfilm_mi.tabulate.axes import AXES, GHOST
from thinfilm_mi.tabulate.band import Shear
from thinfilm_mi.tabulate.base import CUBIC, INTERPOLATIONS, BuildReport, Table
from thinfilm_mi.tabulate.factors import FactorTable

__all__ = ["ENVIRONMENT", "MAX_BYTES", "TableStore", "code_fingerprint", "default_store"]

#: The environment variable naming the store's directory (``off``, ``0`` or empty: none).
ENVIRONMENT = "THINFILM_MI_TABLE_CACHE"
#: The store's bound: beyond it the least recently used files are removed until
#: three quarters remain (a 30-film table is 1.3 MiB, a polarized one 5 MiB).
MAX_BYTES = 256 << 20
_SUFFIX = ".npz"
#: One trimming at a time in this process (stores are made per call; other
#: processes may trim the same directory: every file operation tolerates a file
#: that has just gone).
_TRIM_LOCK = threading.Lock()


@functools.cache
def code_fingerprint() -> str:
    """A hash of every Python source file of this package and of the versions of
    Mitsuba, Dr.Jit and NumPy: any change to the code that builds or reads a table
    gives new keys."""
    import drjit
    import mitsuba

    h = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    h.update(repr((mitsuba.__version__, drjit.__version__, np.__version__)).encode())
    return h.hexdigest()


def _plain(value):
    """``value`` with tuples, NumPy scalars and arrays made JSON's lists and numbers."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


class TableStore:
    """Tables on disk under ``directory`` (see the module). Thread- and
    process-safe: several plugin constructors, or processes, may read and write at
    once (each file is written whole under a name of its own, then renamed)."""

    def __init__(self, directory: str | os.PathLike, max_bytes: int = MAX_BYTES):
        self.directory = Path(directory)
        self.max_bytes = max_bytes

    def _path(self, key: str) -> Path:
        name = hashlib.sha256((key + code_fingerprint()).encode()).hexdigest()[:40]
        return self.directory / (name + _SUFFIX)

    def get(self, key: str):
        """``(True, table, report)`` for a stored key (``table``: a
        :class:`~thinfilm_mi.tabulate.base.Table` or a
        :class:`~thinfilm_mi.tabulate.factors.FactorTable`, as stored; ``None`` for a stack
        the build found not tabulable; ``report`` the build's
        :class:`~thinfilm_mi.tabulate.base.BuildReport`), else ``(False, None, None)``."""
        path = self._path(key)
        try:
            with np.load(path, allow_pickle=False) as f:
                meta = json.loads(bytes(f["meta"]).decode())
                factors = meta["table"] and meta.get("factors") is not None
                names = FactorTable.BUFFERS if factors else ("values",) if meta["table"] else ()
                values = {name: np.array(f[name]) for name in names}
        except FileNotFoundError:
            return False, None, None
        except Exception:     # noqa: BLE001 -- any damaged file is a miss, and removed
            self._remove(path)
            return False, None, None
        if factors:
            table = FactorTable.restore(meta["factors"], values, meta.get("report") or {})
        else:
            table = self._table(values["values"], meta) if meta.get("table") else None
        if meta.get("table") and table is None:
            self._remove(path)
            return False, None, None
        try:
            os.utime(path)      # recently used
        except OSError:
            pass
        return True, table, BuildReport(meta.get("report") or {})

    @staticmethod
    def _table(values, meta) -> Table | None:
        """The table of stored ``values`` if they are what ``meta`` says, else ``None``."""
        try:
            axis, channels = AXES.get(meta["kind"]), int(meta["channels"])
            error, resolution = float(meta["error"]), float(meta["resolution"])
            shear = Shear.from_plain(meta["shear"]) if meta.get("shear") is not None else None
        except (KeyError, TypeError, ValueError):
            return None
        try:
            interpolation = INTERPOLATIONS[meta.get("interpolation", CUBIC.name)]
            factors = tuple(int(f) for f in meta.get("resampling", (1, 1)))
        except (KeyError, TypeError, ValueError):
            return None
        if (axis is None or values.dtype != np.float32 or values.ndim != 3
                or values.shape[2] != channels or len(factors) != 2 or min(factors) < 1
                or not np.all(np.isfinite(values)) or not np.isfinite(error)):
            return None
        nu, nv = interpolation.nodes(values.shape, axis, factors)
        if min(nu // axis.segments, nv) < 2 or (interpolation is CUBIC and min(
                values.shape[:2]) <= 4 * GHOST) or (interpolation is not CUBIC and (
                values.shape[1] % axis.segments
                or (values.shape[1] // axis.segments - 1) % factors[0]
                or (values.shape[0] - 1) % factors[1])):
            return None
        return Table(values, axis, error, channels, resolution, shear=shear,
                     interpolation=interpolation, factors=factors)

    def put(self, key: str, table: Table | FactorTable | None, report: dict | None) -> None:
        """Keep ``table`` (``None``: not tabulable) and its build ``report`` under ``key``;
        nothing happens where the directory cannot be written."""
        path = self._path(key)
        meta = {"table": table is not None, "report": _plain(dict(report or {}))}
        arrays = {}
        if isinstance(table, FactorTable):
            meta["factors"] = _plain(table.layout())
            arrays.update(table.arrays())
        elif table is not None:
            meta.update(kind=table.axis.name, channels
=table.channels, error=float(table.error),
                        resolution=float(table.resolution),
                        shear=table.shear.to_plain() if table.shear is not None else None,
                        interpolation=table.interpolation.name, resampling=list(table.factors))
            arrays["values"] = table.values()
        arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.{threading.get_ident()}.tmp")
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
            os.replace(tmp, path)
        except OSError:
            self._remove(tmp)
            return
        self._trim()

    def _trim(self) -> None:
        """Remove the least recently used files while the store exceeds its bound."""
        with _TRIM_LOCK:
            try:
                files = [(p.stat(), p) for p in self.directory.glob("*" + _SUFFIX)]
            except OSError:
                return
            total = sum(s.st_size for s, _ in files)
            if total <= self.max_bytes:
                return
            for s, p in sorted(files, key=lambda sp: sp[0].st_mtime):
                if total <= 0.75 * self.max_bytes:
                    break
                self._remove(p)
                total -= s.st_size

    @staticmethod
    def _remove(path: Path) -> None:
        try:
            path.unlink()
        except OSError:
            pass

    def clear(self) -> None:
        """Remove every stored table."""
        for p in self.directory.glob("*" + _SUFFIX):
            self._remove(p)


def default_store() -> TableStore | None:
    """The store the environment names (read at every call: a process may turn it
    off): ``$THINFILM_MI_TABLE_CACHE``, or ``$XDG_CACHE_HOME/thinfilm-mi/tables``
    (``~/.cache`` without it); ``None`` where it is ``off``, ``0`` or empty."""
    setting = os.environ.get(ENVIRONMENT)
    if setting is not None:
        if setting.strip().lower() in ("", "0", "off", "false", "no"):
            return None
        return TableStore(setting)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return TableStore(os.path.join(base, "thinfilm-mi", "tables"))
