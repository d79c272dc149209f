"""A compact, lossy file for one surface frame's meshes: how a GPU hero shot's surfaces travel back
from the GPU machine (its returned files are capped at 16 MiB each) to be exported and rendered here.

A surface stage frame (`mpmfx.io.frames.SurfaceFrame`) of a grid-256 shot holds 1-3M vertices per
group and ~100 B per vertex with its level set; this keeps what the render needs:
- vertices quantised to 1/32 of the surface voxel (61 um at the hero shots' 1.95 mm voxel: far
  below a pixel), delta-coded along the mesher's own (block-coherent) vertex order;
- faces delta-coded (the first corner against the previous face's, the others against the first);
- vertex velocities (m/s, for motion blur) quantised to int8 of the frame's largest speed.
Normals are not stored: `decode` recomputes them (area-weighted face normals). The level set
leaves are not carried: the hero shots export without VDBs.

numpy + lzma only (it runs on the GPU machine too). Units: metres, m/s.
"""

from __future__ import annotations

import io
import lzma
from pathlib import Path

import numpy as np

STEPS_PER_VOXEL = 32
FORMAT = 1


def _pack(arrays: dict[str, np.ndarray], *, preset: int) -> bytes:
    """One container: every array compressed alone (in parallel threads: lzma frees the GIL),
    stored in an uncompressed npz with their dtypes and shapes."""
    import json
    from concurrent.futures import ThreadPoolExecutor

    names = list(arrays)
    raw = [np.ascontiguousarray(arrays[k]) for k in names]
    with ThreadPoolExecutor(max_workers=16) as pool:
        blobs = list(pool.map(lambda a: lzma.compress(a.tobytes(), preset=preset), raw))
    head = {k: [a.dtype.str, list(a.shape)] for k, a in zip(names, raw)}
    buf = io.BytesIO()
    np.savez(
        buf,
        _head=np.frombuffer(json.dumps(head).encode(), np.uint8),
        **{k: np.frombuffer(b, np.uint8) for k, b in zip(names, blobs)},
    )
    return buf.getvalue()


def _unpack(blob: bytes) -> dict[str, np.ndarray]:
    import json

    with np.load(io.BytesIO(blob), allow_pickle=False) as z:
        head = json.loads(z["_head"].tobytes())
        return {
            k: np.frombuffer(lzma.decompress(z[k].tobytes()), np.dtype(dt)).reshape(shape)
            for k, (dt, shape) in head.items()
        }


def encode_group(
    vertices: np.ndarray, faces: np.ndarray, velocities: np.ndarray | None, voxel: float, *, with_velocity: bool = True
) -> dict[str, np.ndarray]:
    """Arrays (small ints, deflate/lzma-friendly) for one mesh: (m,3) float m, (k,3) int, (m,3) m/s."""
    v = np.asarray(vertices, np.float64)
    lo = v.min(axis=0) if len(v) else np.zeros(3)
    step = voxel / STEPS_PER_VOXEL
    q = np.rint((v - lo) / step).astype(np.int64)
    if len(q) and q.max() >= 2**31:
        raise ValueError("mesh too large for the codec's int32 quantisation")
    dq = np.diff(q, axis=0, prepend=np.zeros((1, 3), np.int64)).astype(np.int32).T.copy()  # column-major
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    f0 = np.diff(f[:, 0], prepend=0).astype(np.int32)
    rel = (f[:, 1:] - f[:, :1]).astype(np.int32).T.copy()
    out = {"lo": lo, "step": np.float64(step), "dq": dq, "f0": f0, "rel": rel}
    if with_velocity and velocities is not None and len(v):
        vel = np.asarray(velocities, np.float32)
        vmax = float(np.abs(vel).max()) or 1.0
        out["vel"] = np.rint(vel / vmax * 127).astype(np.int8).T.copy()
        out["vmax"] = np.float64(vmax)
    return out


def decode_group(a: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (m,3) float32 m, faces (k,3) int32, normals (m,3) float32, velocities (m,3) float32 m/s)."""
    q = np.cumsum(a["dq"].T.astype(np.int64), axis=0)
    v = (a["lo"] + q * float(a["step"])).astype(np.float32)
    f0 = np.cumsum(a["f0"].astype(np.int64))
    f = np.column_stack([f0, f0 + a["rel"][0], f0 + a["rel"][1]]).astype(np.int32)
    vel = (a["vel"].T.astype(np.float32) * (float(a["vmax"]) / 127)) if "vel" in a else np.zeros_like(v)
    return v, f, vertex_normals(v, f), vel


def vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (m,3) float32, unit length (the mesher's outward winding)."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]).astype(np.float64)
    n = np.zeros((len(v), 3))
    for i in range(3):
        np.add.at(n, f[:, i], fn) if len(f) < 1000 else _add_at(n, f[:, i], fn)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    return n.astype(np.float32)


def _add_at(n: np.ndarray, idx: np.ndarray, vals: np.ndarray) -> None:
    for c in range(3):  # bincount is ~20x faster than np.add.at on millions of rows
        n[:, c] += np.bincount(idx, weights=vals[:, c], minlength=len(n))


def write(
    path: str | Path,
    groups: dict[str, dict],
    meta: dict | None = None,
    *,
    preset: int = 3,
    part_bytes: int = 15 * 2**20,
) -> list[Path]:
    """groups: name -> {vertices, faces, velocities, voxel[, with_velocity]}. Written as `path`,
    or split into `path.000`, `path.001`, ... of at most part_bytes each. Returns the files."""
    import json

    arrays = {
        "_format": np.int32(FORMAT),
        "_groups": np.frombuffer(json.dumps(list(groups)).encode(), np.uint8),
        "_meta": np.frombuffer(json.dumps(meta or {}).encode(), np.uint8),
    }
    for g, m in groups.items():
        enc = encode_group(
            m["vertices"], m["faces"], m.get("velocities"), m["voxel"], with_velocity=m.get("with_velocity", True)
        )
        arrays |= {f"{g}.{k}": np.asarray(x) for k, x in enc.items()}
    blob = _pack(arrays, preset=preset)
    path = Path(path)
    if len(blob) <= part_bytes:
        path.write_bytes(blob)
        return [path]
    parts = []
    for i in range(0, len(blob), part_bytes):
        parts.append(path.with_name(f"{path.name}.{i // part_bytes:03d}"))
        parts[-1].write_bytes(blob[i : i + part_bytes])
    return parts


def read(path: str | Path) -> tuple[dict[str, tuple], dict]:
    """name -> (vertices, faces, normals, velocities), and the meta dict. `path` may be split
    (`path.000`, `path.001`, ...)."""
    import json

    path = Path(path)
    parts = [path] if path.exists() else sorted(path.parent.glob(f"{path.name}.[0-9][0-9][0-9]"))
    if not parts:
        raise FileNotFoundError(path)
    a = _unpack(b"".join(p.read_bytes() for p in parts))
    if int(a["_format"]) != FORMAT:
        raise ValueError(f"{path}: hero mesh format {int(a['_format'])}, this reads {FORMAT}")
    out = {}
    for g in json.loads(a["_groups"].tobytes()):
        out[g] = decode_group({k.split(".", 1)[1]: x for k, x in a.items() if k.startswith(f"{g}.")})
    return out, json.loads(a["_meta"].tobytes())
