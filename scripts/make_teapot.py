#!/usr/bin/env python3
"""Build scenes/meshes/teapot.ply from Newell's Bezier patches.

The Utah teapot is Martin Newell's 1975 set of 32 bicubic Bezier patches over
306 control points (public domain). The control data live in
``scenes/meshes/newell_teapot.txt``; this script

1. reads and checks them (counts, index range, and the mirror symmetry the
   design has: every control point's image under y -> -y is a control point,
   and so is its image under x -> -x for the rotational parts, which catches
   most transcription slips);
2. evaluates every patch and its partial derivatives on a regular
   (N+1) x (N+1) parameter grid (Bernstein form) and triangulates the grid;
3. orients every patch outwards: rays are cast at the pot from many
   directions outside it (with Mitsuba), and a patch whose front side is seen
   less often than its back is flipped;
4. welds the vertices shared along patch seams (so the mesh has no cracks and
   shading is continuous), drops the triangles that collapse at the two
   poles (knob top and bottom centre), and gives every vertex the analytic
   surface normal (averaged over the welded copies; area-weighted face
   normals where the patch is degenerate);
5. converts Newell's z-up frame to Mitsuba's y-up one ((x, y, z) ->
   (x, z, -y), a rotation), scales the pot to height 1, puts its bottom on
   the plane y = 0 and centres its bounding box in x and z;
6. writes a binary little-endian PLY with per-vertex normals.

Usage: python scripts/make_teapot.py [--resolution N] [--out scenes/meshes/teapot.ply]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "scenes" / "meshes" / "newell_teapot.txt"
OUT = ROOT / "scenes" / "meshes" / "teapot.ply"

#: patch groups of the data set (0-based patch numbers)
GROUPS = {
    "rim": range(0, 4), "body": range(4, 12), "handle": range(12, 16),
    "spout": range(16, 20), "lid": range(20, 28), "bottom": range(28, 32),
}
ROTATIONAL = [p for g in ("rim", "body", "lid", "bottom") for p in GROUPS[g]]


# --------------------------------------------------------------------------------------
# control data


def read_patches(path: Path = DATA) -> tuple[np.ndarray, np.ndarray]:
    """``(patches, points)``: (32, 4, 4) zero-based indices and (306, 3) z-up points."""
    lines = [l.strip() for l in path.read_text().splitlines()]
    lines = [l for l in lines if l and not l.startswith("#")]
    n_patches = int(lines[0])
    patches = np.array([[int(t) for t in l.split(",")] for l in lines[1:1 + n_patches]])
    n_points = int(lines[1 + n_patches])
    rows = lines[2 + n_patches:2 + n_patches + n_points]
    points = np.array([[float(t) for t in l.split(",")] for l in rows])
    if patches.shape != (n_patches, 16) or points.shape != (n_points, 3):
        raise ValueError(f"{path}: expected {n_patches} x 16 indices and {n_points} x 3 "
                         f"coordinates, got {patches.shape} and {points.shape}")
    if len(lines) != 2 + n_patches + n_points:
        raise ValueError(f"{path}: {len(lines) - 2 - n_patches - n_points} unexpected extra lines")
    if patches.min() < 1 or patches.max() > n_points:
        raise ValueError(f"{path}: patch indices must be in 1..{n_points}")
    return patches.reshape(n_patches, 4, 4) - 1, points


def check_symmetry(patches: np.ndarray, points: np.ndarray) -> None:
    """Newell's teapot is symmetric under y -> -y; rim, body, lid and bottom
    also under x -> -x. Raise if a control point's mirror image is missing."""
    def present(p, pool):
        return np.min(np.abs(pool - p).max(axis=1)) < 1e-9

    used = points[np.unique(patches)]
    for p in used:
        if not present(p * [1, -1, 1], used):
            raise ValueError(f"control point {p} has no mirror image under y -> -y")
    rot = points[np.unique(patches[ROTATIONAL])]
    for p in rot:
        if not present(p * [-1, 1, 1], rot):
            raise ValueError(f"control point {p} of a rotational part has no mirror under x -> -x")


# --------------------------------------------------------------------------------------
# evaluation


def bernstein(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Bernstein basis and its derivative at ``t``: two (len(t), 4) arrays."""
    s = 1.0 - t
    b = np.stack([s ** 3, 3 * s * s * t, 3 * s * t * t, t ** 3], axis=1)
    db = np.stack([-3 * s * s, 3 * s * s - 6 * s * t, 6 * s * t - 3 * t * t, 3 * t * t], axis=1)
    return b, db


def evaluate_patch(ctrl: np.ndarray, n: int):
    """Positions, d/du and d/dv of a (4, 4, 3) patch on an (n+1) x (n+1) grid."""
    t = np.linspace(0.0, 1.0, n + 1)
    b, db = bernstein(t)
    pos = np.einsum("ui,ijc,vj->uvc", b, ctrl, b)
    du = np.einsum("ui,ijc,vj->uvc", db, ctrl, b)
    dv = np.einsum("ui,ijc,vj->uvc", b, ctrl, db)
    return pos, du, dv


def grid_triangles(n: int, offset: int) -> np.ndarray:
    """Two triangles per grid cell, wound (u, v) counter-clockwise."""
    idx = np.arange((n + 1) * (n + 1)).reshape(n + 1, n + 1) + offset
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def tessellate(patches, points, n):
    """Per-patch vertices (unwelded): positions, analytic normals (unnormalised),
    triangles, and each triangle's patch number."""
    pos, nrm, tris, owner = [], [], [], []
    for k, patch in enumerate(patches):
        p, du, dv = evaluate_patch(points[patch], n)
        pos.append(p.reshape(-1, 3))
        nrm.append(np.cross(du, dv).reshape(-1, 3))
        t = grid_triangles(n, k * (n + 1) ** 2)
        tris.append(t)
        owner.append(np.full(len(t), k))
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(tris), np.concatenate(owner)


def face_normals(pos, tris):
    """Unnormalised face normals (length = twice the area)."""
    return np.cross(pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]])


# --------------------------------------------------------------------------------------
# orientation


def outside_votes(pos, tris, owner, n_patches, n_dirs=400, res=96, seed=1):
    """Per patch: how many rays from outside hit its front (+) or back (-)
    side first. Uses Mitsuba's ray tracer (llvm_ad_rgb variant)."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    mesh = mi.Mesh("teapot", len(pos), len(tris))
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.TensorXf(pos.astype(np.float32)))
    params["faces"] = dr.ravel(mi.TensorXu(tris.astype(np.uint32)))
    params.update()
    scene = mi.load_dict({"type": "scene", "teapot": mesh})

    centre = 0.5 * (pos.min(0) + pos.max(0))
    radius = 0.6 * np.linalg.norm(pos.max(0) - pos.min(0))
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(n_dirs, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    # for every direction d, a res x res bundle of parallel rays travelling along -d
    g = (np.arange(res) + 0.5) / res * 2 - 1
    gu, gv = [a.ravel() for a in np.meshgrid(g, g)]
    helper = np.where(np.abs(dirs[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(dirs, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(dirs, e1)
    o = (centre + 2 * radius * dirs[:, None, :]
         + radius * (gu[None, :, None] * e1[:, None, :] + gv[None, :, None] * e2[:, None, :]))
    d = np.broadcast_to(-dirs[:, None, :], o.shape)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    ray = mi.Ray3f(mi.Point3f(*[o[:, i].astype(np.float32) for i in range(3)]),
                   mi.Vector3f(*[d[:, i].astype(np.float32) for i in range(3)]))
    si = scene.ray_intersect_preliminary(ray)
    hit = np.array(si.is_valid())
    prim = np.array(si.prim_index)[hit]
    fn = face_normals(pos, tris)[prim]
    front = np.einsum("ij,ij->i", fn, d[hit]) < 0
    votes = np.zeros(n_patches)
    np.add.at(votes, owner[prim], np.where(front, 1, -1))
    return votes


def orient(pos, nrm, tris, owner, n_patches, verbose=True):
    """Flip the patches that face inwards (triangle winding and normals)."""
    votes = outside_votes(pos, tris, owner, n_patches)
    flip = votes < 0
    if verbose:
        names = {p: g for g, r in GROUPS.items() for p in r}
        flipped = [f"{k + 1} ({names.get(k, '?')})" for k in np.flatnonzero(flip)]
        print(f"make_teapot: votes per patch {votes.astype(int).tolist()}", file=sys.stderr)
        print(f"make_teapot: flipped patches: {', '.join(flipped) or 'none'}", file=sys.stderr)
    if np.any(votes == 0):
        raise RuntimeError(f"patches {np.flatnonzero(votes == 0) + 1} were not seen from outside")
    tri_flip = flip[owner]
    tris = tris.copy()
    tris[tri_flip] = tris[tri_flip][:, ::-1]
    per_vertex_patch = np.repeat(np.arange(n_patches), len(pos) // n_patches)
    nrm = np.where(flip[per_vertex_patch][:, None], -nrm, nrm)
    # within each patch the analytic normal must agree with the winding
    fn = face_normals(pos, tris)
    vn = nrm[tris].sum(axis=1)
    ok = np.einsum("ij,ij->i", fn, vn)
    big = np.linalg.norm(fn, axis=1) > 1e-12
    if np.any(ok[big] < 0):
        raise RuntimeError("analytic normals disagree with the triangle winding")
    return nrm, tris


# --------------------------------------------------------------------------------------
# welding and normals


def weld(pos, nrm, tris, patch_of_vertex, crease_deg=30.0, tol=1e-7):
    """Merge the vertices that patches share along their seams.

    Copies closer than ``tol`` become one vertex whose normal is the mean of
    their analytic normals, unless those normals differ by more than
    ``crease_deg`` (a crease such as the neck of the knob): then each patch
    keeps its own vertex and normal at the same position, so the mesh stays
    watertight and the crease stays sharp. Triangles that collapse at the
    poles are removed; where the patch has no analytic normal (the poles)
    the area-weighted face normals are used. Returns positions, normals,
    triangles, the largest angle (deg) between normals merged into one vertex,
    the number of crease vertices and of face-normal vertices."""
    key = np.round(pos / tol).astype(np.int64)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()

    length = np.linalg.norm(nrm, axis=1)
    good = length > 1e-6 * np.median(length)
    unit = np.zeros_like(nrm)
    unit[good] = nrm[good] / length[good, None]
    acc = np.zeros((len(first), 3))
    np.add.at(acc, group, unit)
    mean = acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-300)
    cosines = np.where(good, np.einsum("ij,ij->i", unit, mean[group]), 1.0)
    worst = np.ones(len(first))
    np.minimum.at(worst, group, cosines)
    crease = worst < np.cos(np.radians(crease_deg))

    # final vertex key: the position group, split by patch at creases
    sub = np.where(crease[group], patch_of_vertex, -1)
    _, vfirst, vid = np.unique(np.stack([group, sub], 1), axis=0, return_index=True,
                               return_inverse=True)
    vid = vid.ravel()
    new_pos = pos[first[group[vfirst]]]  # one representative position per group: watertight
    acc = np.zeros((len(vfirst), 3))
    np.add.at(acc, vid, unit)
    count = np.zeros(len(vfirst))
    np.add.at(count, vid, good.astype(float))
    merged_cos = np.einsum("ij,ij->i", unit, acc[vid] / np.maximum(
        np.linalg.norm(acc[vid], axis=1, keepdims=True), 1e-300))
    spread = float(np.degrees(np.arccos(np.clip(merged_cos[good].min(), -1, 1))))

    tris = vid[tris]
    # a triangle collapses when two corners share a position (not just a vertex)
    pos_group = group[vfirst]
    tg = pos_group[tris]
    keep = (tg[:, 0] != tg[:, 1]) & (tg[:, 1] != tg[:, 2]) & (tg[:, 0] != tg[:, 2])
    tris = tris[keep]
    fn = face_normals(new_pos, tris)
    keep = np.linalg.norm(fn, axis=1) > 1e-14
    tris, fn = tris[keep], fn[keep]

    face_acc = np.zeros_like(new_pos)
    for j in range(3):
        np.add.at(face_acc, tris[:, j], fn)
    fallback = (count == 0) | (np.linalg.norm(acc, axis=1) < 0.5 * np.maximum(count, 1))
    normals = np.where(fallback[:, None], face_acc, acc)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)

    used = np.zeros(len(new_pos), bool)
    used[tris.ravel()] = True
    remap = np.cumsum(used) - 1
    n_crease = int((crease[pos_group] & used).sum())
    return (new_pos[used], normals[used], remap[tris], spread, n_crease,
            int((fallback & used).sum()))


def boundary_loops(tris) -> int:
    """Number of closed loops of edges used by one triangle only."""
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    border = uniq[counts == 1]
    if len(border) == 0:
        return 0
    parent = {}

    def find(a):
        while parent.setdefault(a, a) != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in border:
        parent[find(a)] = find(b)
    return len({find(a) for a in border.ravel()})


# --------------------------------------------------------------------------------------
# output


def to_mitsuba_frame(pos, nrm, height=1.0):
    """z-up -> y-up rotation, height ``height``, bottom on y = 0, bounding box
    centred in x and z. Returns positions, normals and the transform applied to
    Newell's z axis (its x, z position after the transform)."""
    rot = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # (x, y, z) -> (x, z, -y)
    p = pos @ rot.T
    nn = nrm @ rot.T
    scale = height / (p[:, 1].max() - p[:, 1].min())
    p = p * scale
    lo, hi = p.min(0), p.max(0)
    shift = np.array([-(lo[0] + hi[0]) / 2, -lo[1], -(lo[2] + hi[2]) / 2])
    p = p + shift
    return p, nn, scale, shift


def write_ply(path: Path, pos, nrm, tris, comments=()):
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {c}" for c in comments]
    header += [f"element vertex {len(pos)}", "property float x", "property float y",
               "property float z", "property float nx", "property float ny", "property float nz",
               f"element face {len(tris)}", "property list uchar int vertex_indices",
               "end_header"]
    vert = np.empty(len(pos), dtype=[("p", "<f4", 3), ("n", "<f4", 3)])
    vert["p"], vert["n"] = pos, nrm
    face = np.empty(len(tris), dtype=[("k", "u1"), ("i", "<i4", 3)])
    face["k"], face["i"] = 3, tris
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vert.tobytes())
        f.write(face.tobytes())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolution", type=int, default=20,
                    help="grid cells per patch side (default 20)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if args.resolution < 2:
        ap.error("--resolution must be >= 2")

    patches, points = read_patches()
    check_symmetry(patches, points)
    pos, nrm, tris, owner = tessellate(patches, points, args.resolution)
    nrm, tris = orient(pos, nrm, tris, owner, len(patches))
    patch_of_vertex = np.repeat(np.arange(len(patches)), (args.resolution + 1) ** 2)
    pos, nrm, tris, spread, n_crease, n_fallback = weld(pos, nrm, tris, patch_of_vertex)
    pos, nrm, scale, shift = to_mitsuba_frame(pos, nrm)

    fn = face_normals(pos, tris)
    agree = np.einsum("ij,ij->i", fn, nrm[tris].sum(axis=1)) > 0
    _, geometric = np.unique(pos, axis=0, return_inverse=True)  # crease copies share positions
    loops = boundary_loops(geometric.ravel()[tris])
    comments = [
        "Utah teapot: Martin Newell's 32 Bezier patches (public domain),",
        f"tessellated {args.resolution}x{args.resolution} per patch by scripts/make_teapot.py;",
        "y-up, height 1, bottom on y=0, bounding box centred in x and z;",
        f"Newell's axis (x=0,y=0) is at x={shift[0] + 0.0:.6f} z={shift[2] + 0.0:.6f}, scale {scale:.6f}",
    ]
    write_ply(args.out, pos, nrm, tris, comments)
    size = args.out.stat().st_size
    print(f"make_teapot: wrote {args.out} ({len(pos)} vertices, {len(tris)} triangles, "
          f"{size / 1e6:.2f} MB); bbox {np.round(pos.min(0), 4).tolist()} .. "
          f"{np.round(pos.max(0), 4).tolist()}; {loops} open boundary loops; "
          f"{(~agree).sum()} triangles whose vertex normals oppose their winding; "
          f"largest angle between merged patch normals {spread:.1f} deg; "
          f"{n_crease} vertices on creases (kept sharp); "
          f"{n_fallback} vertices with face-averaged normals", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
