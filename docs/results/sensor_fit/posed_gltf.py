"""A skinned glTF character at a time of its animation, written as a z-up PLY: a pedestrian that walks instead of its T-pose.

    python docs/results/sensor_fit/posed_gltf.py SCENE.gltf OUT.ply [TIME_S] [ANIMATION]   (defaults: mid-animation, the first)

trimesh loads a skinned mesh in its bind pose (for the street meshes' `metadrive__pedestrian`, a T-pose with the arms
out, as wide as it is tall). This poses it as the file's own animation does at TIME_S: the joints' local
translation, rotation and scale sampled from the animation's channels (LINEAR: lerp, and slerp for rotations; STEP:
the key before), every node's global transform from the scene's hierarchy, and linear blend skinning
(glTF 2.0 specification, section 3.7.3, "Skins": v' = sum_k w_k G(joint_k) IBM_k v, with G the joint's global
transform and IBM its inverse bind matrix). The result is in the scene's frame (glTF: +y up), turned to z up.
Reads .gltf files with external or embedded (base64) buffers and .glb files; the first skinned mesh node is posed.
"""

import base64
import json
import struct
import sys
from pathlib import Path

import numpy as np
import trimesh

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.io.caps import MAX_MESH_FILE_BYTES
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.mesh.named_files import folder_resolver

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def read_gltf(path: Path) -> tuple[dict, list[bytes]]:
    """The JSON and the buffers of a .gltf (buffers beside it, or data URIs) or .glb file, read as the
    mesh loader reads them (regular files only, inside the file's folder: ``zbuf_occlude.io.regular_files`` and
    ``zbuf_occlude.mesh.named_files``)."""
    raw = read_regular_file(path, max_bytes=MAX_MESH_FILE_BYTES, error=MeshLoadError)
    if raw[:4] == b"glTF":
        n = struct.unpack_from("<I", raw, 12)[0]
        doc = json.loads(raw[20 : 20 + n])
        blob = raw[20 + n + 8 :]
        return doc, [blob]
    doc = json.loads(raw)
    resolver = folder_resolver(path)
    return doc, [base64.b64decode(b["uri"].split(",", 1)[1]) if b["uri"].startswith("data:") else resolver.get(b["uri"])
                 for b in doc["buffers"]]  # fmt: skip


def accessor(doc: dict, buffers: list[bytes], index: int) -> np.ndarray:
    """Accessor ``index`` as a (count, width) array (normalized integers scaled to [0, 1])."""
    a = doc["accessors"][index]
    view = doc["bufferViews"][a["bufferView"]]
    dtype = np.dtype(_COMPONENTS[a["componentType"]])
    width = _WIDTH[a["type"]]
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = view.get("byteStride", dtype.itemsize * width)
    data = buffers[view["buffer"]]
    rows = np.ndarray((a["count"], width), dtype=dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
    out = np.array(rows)
    if a.get("normalized"):
        out = out.astype(np.float64) / np.iinfo(dtype).max
    return out


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])  # fmt: skip


def _slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + t * (b - a)
        return q / np.linalg.norm(q)
    theta = np.arccos(d)
    return (np.sin((1 - t) * theta) * a + np.sin(t * theta) * b) / np.sin(theta)


def _sample(times: np.ndarray, values: np.ndarray, mode: str, path: str, t: float) -> np.ndarray:
    if mode == "CUBICSPLINE":  # in-tangent, value, out-tangent per key: keep the values
        values = values.reshape(len(times), 3, -1)[:, 1]
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    i = int(np.searchsorted(times, t, side="right")) - 1
    if mode == "STEP":
        return values[i]
    u = (t - times[i]) / (times[i + 1] - times[i])
    if path == "rotation":
        return _slerp(values[i], values[i + 1], u)
    return (1 - u) * values[i] + u * values[i + 1]


def local_matrices(doc: dict, buffers: list[bytes], animation: int | None, t: float) -> list[np.ndarray]:
    """Every node's local 4x4 transform at time ``t`` of ``animation`` (None: the rest pose)."""
    trs = []
    for node in doc["nodes"]:
        trs.append({"translation": np.array(node.get("translation", [0.0, 0.0, 0.0])),
                    "rotation": np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0])),
                    "scale": np.array(node.get("scale", [1.0, 1.0, 1.0]))})  # fmt: skip
    if animation is not None:
        anim = doc["animations"][animation]
        for ch in anim["channels"]:
            path = ch["target"]["path"]
            if path not in ("translation", "rotation", "scale") or "node" not in ch["target"]:
                continue
            s = anim["samplers"][ch["sampler"]]
            times = accessor(doc, buffers, s["input"])[:, 0].astype(np.float64)
            values = accessor(doc, buffers, s["output"]).astype(np.float64)
            trs[ch["target"]["node"]][path] = _sample(times, values, s.get("interpolation", "LINEAR"), path, t)
    out = []
    for node, p in zip(doc["nodes"], trs):
        if "matrix" in node:
            out.append(np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T)  # column-major
            continue
        m = np.eye(4)
        m[:3, :3] = _quat_matrix(p["rotation"]) * p["scale"][None, :]
        m[:3, 3] = p["translation"]
        out.append(m)
    return out


def global_matrices(doc: dict, local: list[np.ndarray]) -> list[np.ndarray]:
    """Every node's transform to the scene's frame (the product of its ancestors' local transforms)."""
    parent = {c: i for i, n in enumerate(doc["nodes"]) for c in n.get("children", [])}
    out: dict[int, np.ndarray] = {}

    def walk(i: int) -> np.ndarray:
        if i not in out:
            out[i] = (walk(parent[i]) @ local[i]) if i in parent else local[i]
        return out[i]

    return [walk(i) for i in range(len(doc["nodes"]))]


def posed_mesh(path: Path, t: float | None = None, animation: int = 0) -> trimesh.Trimesh:
    """The first skinned mesh node of ``path`` posed at ``t`` seconds of ``animation`` (None: half its length), y up."""
    doc, buffers = read_gltf(path)
    node_i = next(i for i, n in enumerate(doc["nodes"]) if "mesh" in n and "skin" in n)
    node = doc["nodes"][node_i]
    skin = doc["skins"][node["skin"]]
    if t is None:
        anim = doc["animations"][animation]
        ends = [float(accessor(doc, buffers, s["input"]).max()) for s in anim["samplers"]]
        t = 0.5 * max(ends)
    g = global_matrices(doc, local_matrices(doc, buffers, animation, t))
    ibm = accessor(doc, buffers, skin["inverseBindMatrices"]).astype(np.float64).reshape(-1, 4, 4).transpose(0, 2, 1)
    joint = np.stack([g[j] @ ibm[k] for k, j in enumerate(skin["joints"])])  # (J, 4, 4)
    parts = []
    for prim in doc["meshes"][node["mesh"]]["primitives"]:
        att = prim["attributes"]
        v = accessor(doc, buffers, att["POSITION"]).astype(np.float64)
        joints = accessor(doc, buffers, att["JOINTS_0"]).astype(np.int64)
        weights = accessor(doc, buffers, att["WEIGHTS_0"]).astype(np.float64)
        weights /= np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
        vh = np.hstack([v, np.ones((len(v), 1))])
        per_joint = np.einsum("nkij,nj->nki", joint[joints], vh)  # (N, 4, 4): each influence's position
        posed = np.einsum("nk,nki->ni", weights, per_joint)[:, :3]
        faces = accessor(doc, buffers, prim["indices"]).reshape(-1, 3).astype(np.int64)
        parts.append(trimesh.Trimesh(posed, faces, process=False))
    return trimesh.util.concatenate(parts)


def main() -> None:
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    t = float(sys.argv[3]) if len(sys.argv) > 3 else None
    mesh = posed_mesh(src, t, int(sys.argv[4]) if len(sys.argv) > 4 else 0)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))  # y up -> z up
    mesh.export(out)
    print(out, np.round(mesh.extents, 3).tolist(), len(mesh.faces))


if __name__ == "__main__":
    main()
