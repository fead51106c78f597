"""Fixtures of the export tests: the Khronos glTF validator and an independent glTF decoder."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest

REPO = Path(__file__).resolve().parents[2]
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
               5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
VALIDATOR = REPO / ".venv" / "node" / "node_modules" / "gltf-validator"
THREE = REPO / ".venv" / "node" / "node_modules" / "three"


@pytest.fixture
def khronos():
    """``khronos(path) -> issues``: the Khronos glTF validator's report of a GLB.

    The npm package is installed by ``make test`` into ``.venv/node``; without
    node or npm the tests that use it skip with that reason (the strict
    accessor reads of the tests still run).
    """
    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip("Khronos glTF validator not installed (make test installs it with npm)")

    def validate(path: Path) -> dict:
        script = ("const v=require(process.argv[1]);const fs=require('fs');"
                  "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))"
                  ".then(r=>console.log(JSON.stringify(r.issues)))"
                  ".catch(e=>{console.error(String(e));process.exit(2)});")
        proc = subprocess.run([node, "-e", script, str(VALIDATOR), str(path)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return json.loads(proc.stdout)

    return validate


@pytest.fixture
def threejs():
    """``threejs(path, times) -> frames``: what three.js shows of a GLB at ``times``.

    three.js's GLTFLoader and AnimationMixer (npm package ``three``, installed by
    ``make test`` into ``.venv/node``) run in node (``threejs_frames.mjs``); each
    frame maps a mesh name to its ``color`` and world ``position`` arrays.
    """
    node = shutil.which("node")
    if node is None or not THREE.is_dir():
        pytest.skip("three.js not installed (make test installs it with npm)")
    script = Path(__file__).with_name("threejs_frames.mjs")

    def frames(path: Path, times) -> list[dict]:
        proc = subprocess.run([node, str(script), str(THREE), str(path),
                               *(f"{t:.9g}" for t in times)],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        return [{"time": f["time"], "meshes": {
            name: {k: np.asarray(v) for k, v in m.items()} for name, m in f["meshes"].items()}}
            for f in json.loads(proc.stdout)]

    return frames


# ------------------------------------------------------------------ a glTF decoder
# Written from the glTF 2.0 text alone, so the exports are read back independently
# of the exporter's own code.
def _read(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    """An accessor as float64 rows (normalised integers decoded, sparse applied)."""
    acc = gltf.accessors[index]
    blob = gltf.binary_blob()
    width = _WIDTH[acc.type]
    dtype = np.dtype(_COMPONENTS[acc.componentType])

    def rows(view_index, offset, count, dt, w):
        view = gltf.bufferViews[view_index]
        stride = view.byteStride or dt.itemsize * w
        start = view.byteOffset + (offset or 0)
        assert start + stride * (count - 1) + dt.itemsize * w <= view.byteOffset + view.byteLength
        assert view.byteOffset + view.byteLength <= len(blob)
        return np.ndarray((count, w), dtype=dt, buffer=blob, offset=start,
                          strides=(stride, dt.itemsize))

    if acc.bufferView is None:
        data = np.zeros((acc.count, width))
    else:
        data = rows(acc.bufferView, acc.byteOffset, acc.count, dtype, width).astype(np.float64)
    if acc.sparse is not None:
        sp = acc.sparse
        idx = rows(sp.indices.bufferView, sp.indices.byteOffset, sp.count,
                   np.dtype(_COMPONENTS[sp.indices.componentType]), 1)[:, 0]
        assert np.all(np.diff(idx.astype(np.int64)) > 0)  # the spec: strictly increasing
        data[idx] = rows(sp.values.bufferView, sp.values.byteOffset, sp.count, dtype,
                         width).astype(np.float64)
    if acc.normalized:  # glTF 2.0, "Animations": c / (2^(b-1) - 1), clamped at -1
        data = np.maximum(data / np.iinfo(dtype).max, -1.0)
    return data


def _step(gltf, sampler, time: float) -> np.ndarray:
    """A STEP sampler's output at ``time`` (the last key at or before it)."""
    assert sampler.interpolation == "STEP"
    keys = _read(gltf, sampler.input)[:, 0]
    out = _read(gltf, sampler.output).reshape(len(keys), -1)
    return out[np.searchsorted(keys, time + 1e-6, side="right") - 1]


def _quat_matrix(q) -> np.ndarray:
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _frame(gltf, node_index: int, time: float):
    """World positions and linear colours of one node's mesh at ``time``."""
    node = gltf.nodes[node_index]
    prim = gltf.meshes[node.mesh].primitives[0]
    channels = {c.target.path: gltf.animations[0].samplers[c.sampler]
                for c in (gltf.animations[0].channels if gltf.animations else [])
                if c.target.node == node_index}
    pos, col = _read(gltf, prim.attributes.POSITION), _read(gltf, prim.attributes.COLOR_0)
    if "weights" in channels:
        weights = _step(gltf, channels["weights"], time)
        assert len(weights) == len(prim.targets)
        for w, target in zip(weights, prim.targets, strict=True):
            col = col + w * _read(gltf, target["COLOR_0"])
            if "POSITION" in target:
                pos = pos + w * _read(gltf, target["POSITION"])
    rot = _quat_matrix(_step(gltf, channels["rotation"], time)) if "rotation" in channels \
        else _quat_matrix(np.array(node.rotation or [0, 0, 0, 1.0]))
    move = _step(gltf, channels["translation"], time) if "translation" in channels \
        else np.array(node.translation or [0.0, 0, 0])
    return pos @ rot.T + move, col


@pytest.fixture
def glb():
    """``glb.read(gltf, accessor)``, ``glb.step(gltf, sampler, time)``,
    ``glb.frame(gltf, node, time)`` -> (world positions, linear colours)."""
    import types

    return types.SimpleNamespace(read=_read, step=_step, frame=_frame)
