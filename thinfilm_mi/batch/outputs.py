"""The files of a sweep in its output folder (:mod:`thinfilm_mi.batch.sweeps`):

- ``frames/<name>.exr`` and ``frames/<name>.png`` per frame (:func:`write_frame`,
  on the workers), each written to a hidden temporary name (``.<name>.part-*``,
  :func:`part_path`) and renamed when complete;
- ``manifest.csv``: one row per finished frame, in grid order
  (:func:`save_manifest`, :func:`read_manifest`), rewritten atomically;
- ``sweep.json``: the settings that are not grid axes (:func:`job_settings`),
  which decide whether an earlier run's frames count (:func:`previous_rows`);
- ``contact_sheet.png``: every frame, labelled with the parameters that vary
  (:func:`write_contact_sheet`; needs matplotlib, the ``[plot]`` extra).
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import secrets
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from thinfilm_mi.batch import exr
from thinfilm_mi.batch.grid import COLUMNS, Axis, Frame, Job, axis_label

__all__ = [
    "write_frame", "save_manifest", "read_manifest", "previous_rows", "job_settings",
    "write_contact_sheet", "write_atomic", "part_path", "remove_parts",
    "DEFAULT_OUT_DIR", "MANIFEST", "SETTINGS", "CONTACT_SHEET", "PART_MARK",
]

#: the output folder of a sweep when none is named
DEFAULT_OUT_DIR = "out/sweep"
MANIFEST = "manifest.csv"
SETTINGS = "sweep.json"
CONTACT_SHEET = "contact_sheet.png"
#: temporary outputs are named ``.<name>.part-<pid>-<random><suffix>``
PART_MARK = ".part-"


def part_path(path: Path) -> Path:
    """A hidden temporary name beside ``path``, same suffix (image writers go by it)."""
    return path.with_name(f".{path.stem}{PART_MARK}{os.getpid()}-{secrets.token_hex(4)}{path.suffix}")


def write_frame(job: Job, frame: Frame, image, channels, attributes) -> str:
    """Write the frame's EXR and PNG through temporary names; returns the PNG's
    relative path ('' when the film has no colour to preview)."""
    out = Path(job.out_dir)
    final_exr, final_png = out / frame.exr, out / frame.png
    parts = [part_path(final_exr), part_path(final_png)]
    try:
        exr.write_exr(parts[0], image, channels, attributes)
        wrote_png = exr.write_png(parts[1], image, channels) is not None
        if wrote_png:
            os.replace(parts[1], final_png)
        os.replace(parts[0], final_exr)
    finally:
        for p in parts:
            p.unlink(missing_ok=True)
    return frame.png if wrote_png else ""


def read_manifest(path: str | os.PathLike) -> list[dict[str, str]]:
    """The rows of a manifest (empty when missing or unreadable)."""
    try:
        with open(path, newline="") as f:
            return [dict(r) for r in csv.DictReader(f)]
    except (OSError, csv.Error, UnicodeDecodeError):
        return []


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary name: a reader sees the old
    file or the new one, never a part."""
    part = part_path(path)
    try:
        part.write_bytes(data)
        os.replace(part, path)
    finally:
        part.unlink(missing_ok=True)


def save_manifest(out: Path, job: Job, names: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> None:
    """Write ``manifest.csv`` (the parameters ``names``, then :data:`~thinfilm_mi.batch.grid.COLUMNS`)
    and then ``sweep.json`` into ``out``, each atomically. Manifest first: a crash in between
    leaves old settings, which make the next run render everything again rather than
    trust rows wrongly."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=[*names, *COLUMNS], extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({**row, "seconds": f"{float(row.get('seconds') or 0.0):.3f}"})
    write_atomic(out / MANIFEST, buf.getvalue().encode())
    write_atomic(out / SETTINGS, (json.dumps(job_settings(job), indent=1) + "\n").encode())


def remove_parts(folder: Path) -> None:
    """Remove temporary outputs (``.<name>.part-*``) left by killed workers."""
    for p in folder.glob(f".*{PART_MARK}*"):
        p.unlink(missing_ok=True)


def write_contact_sheet(path: Path, out_dir: Path, axes: Sequence[Axis],
                        rows: Sequence[Mapping[str, Any]], thumb_px: int = 160) -> Path:
    """A PNG of every frame, labelled with the values of the axes that vary;
    failed frames as grey tiles saying so. Uses matplotlib's Agg canvas (no pyplot)."""
    import matplotlib.image as mpimg
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    varying = [a for a in axes if len(a.values) > 1]
    n = len(rows)
    previews = [out_dir / r["png"] for r in rows
                if r.get("status") == "ok" and r.get("png") and (out_dir / r["png"]).is_file()]
    images = {p: mpimg.imread(str(p)) for p in previews}
    aspect = (lambda im: im.shape[0] / im.shape[1])(next(iter(images.values()))) if images else 0.75
    if len(varying) >= 2 and len(varying[-1].values) <= 12:
        cols = len(varying[-1].values)
    else:
        cols = min(n, max(1, math.ceil(math.sqrt(n))), 12) if n else 1
    rows_n = max(1, math.ceil(n / cols))
    dpi = 100
    w_in = thumb_px / dpi
    fig = Figure(figsize=(cols * w_in, rows_n * (w_in * aspect + 0.1 + 0.1 * max(1, len(varying)))),
                 dpi=dpi)
    FigureCanvasAgg(fig)
    for i, row in enumerate(rows):
        ax = fig.add_subplot(rows_n, cols, i + 1)
        ax.set_xticks([])
        ax.set_yticks([])
        label = "\n".join(f"{axis_label(a.name)}={row.get(a.name, '')}" for a in varying) or "frame"
        png = out_dir / row["png"] if row.get("png") else None
        if png in images:
            ax.imshow(images[png])
        else:
            ax.set_facecolor("0.8")
            ax.text(0.5, 0.5, "failed" if row.get("status") == "failed" else "no preview",
                    ha="center", va="center", transform=ax.transAxes, fontsize=8)
        ax.set_title(label, fontsize=6)
    fig.tight_layout(pad=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    write_atomic(path, buf.getvalue())
    return path


def job_settings(job: Job) -> dict[str, Any]:
    """The settings recorded in ``sweep.json``: those of the job that are not grid axes."""
    return {"scene": job.scene, "variant": job.variant, "size": list(job.size) if job.size else None,
            "spp": job.spp, "seed": job.seed, "sensor": job.sensor,
            "max_pass_samples": job.max_pass_samples}


def previous_rows(out: Path, job: Job, frames: Sequence[Frame], names: Sequence[str],
                  log: Callable[[str], None]) -> dict[int, dict[str, Any]]:
    """Frames complete from an earlier run: an ``ok`` manifest row with the same
    parameters (and settings) whose files exist."""
    manifest = out / MANIFEST
    if not manifest.exists():
        return {}
    try:
        previous = json.loads((out / SETTINGS).read_text())
    except (OSError, ValueError):
        previous = None
    if previous != job_settings(job):
        log(f"{out} holds a sweep with other settings (or none recorded): rendering every frame")
        return {}
    by_params: dict[tuple, dict[str, str]] = {}
    for row in read_manifest(manifest):
        if row.get("status") == "ok" and all(row.get(n) is not None for n in names):
            by_params[tuple(row[n] for n in names)] = row
    done = {}
    for f in frames:
        row = by_params.get(tuple(f.params[n] for n in names))
        if row is None or not row.get("exr") or not (out / row["exr"]).is_file():
            continue
        if row.get("png") and not (out / row["png"]).is_file():
            continue
        try:
            seconds = float(row.get("seconds") or 0.0)
        except ValueError:
            seconds = 0.0
        done[f.index] = {**f.params, "exr": row["exr"], "png": row.get("png") or "",
                         "seconds": seconds, "status": "ok", "error": "", "rendered": False}
    return done

