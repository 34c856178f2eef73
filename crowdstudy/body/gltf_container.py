"""A small binary glTF 2.0 (.glb) writer and reader on numpy arrays (the container format
only: :mod:`crowdstudy.gltf.export` writes crowds with it, :mod:`crowdstudy.body.gltf_model`
reads characters). It sits in :mod:`crowdstudy.body`, the lowest of its two users, so that
the body models can read glTF characters without importing :mod:`crowdstudy.gltf`, which
imports the bodies.

Writer: :class:`GltfBuilder` collects the JSON document and one binary buffer; each
``accessor(...)`` call appends a 4-byte aligned buffer view. ``to_glb()`` gives the bytes
of a GLB container (12-byte header, JSON chunk padded with spaces, BIN chunk padded with
zeros); the same document gives the same bytes.

Reader: :func:`read_gltf` loads a .glb, or a .gltf whose buffers are data URIs or files
beside it, and :func:`read_accessor` returns an accessor as a numpy array (byte strides,
normalised integers and sparse accessors handled).
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["GltfBuilder", "GltfFile", "read_gltf", "read_accessor", "COMPONENT_TYPES", "TYPE_SIZES", "Z_UP_TO_Y_UP"]

#: (3, 3) rotation taking toolkit (Z-up, faces +y) coordinates to glTF (Y-up, faces +Z):
#: (x, y, z) -> (-x, z, y).
Z_UP_TO_Y_UP = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

#: glTF componentType -> numpy dtype.
COMPONENT_TYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_CODES = {np.dtype(v): k for k, v in COMPONENT_TYPES.items()}
#: glTF accessor type -> number of components.
TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TYPE_OF_WIDTH = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963


def _pad(data: bytes, fill: bytes = b"\x00") -> bytes:
    return data + fill * (-len(data) % 4)


class GltfBuilder:
    """Accumulates a glTF document and its binary buffer.

    Attributes:
        doc: the JSON document (dict); add nodes, meshes, skins... to its lists directly,
            or through :meth:`add`.
    """

    def __init__(self, generator: str = "crowdstudy"):
        self.doc: dict = {"asset": {"version": "2.0", "generator": generator}}
        self._bin = bytearray()

    def add(self, kind: str, item: dict) -> int:
        """Append ``item`` to ``doc[kind]`` and return its index."""
        items = self.doc.setdefault(kind, [])
        items.append(item)
        return len(items) - 1

    def buffer_view(self, data: bytes, target: int | None = None) -> int:
        """Append raw bytes (4-byte aligned) as a buffer view; returns its index."""
        offset = len(self._bin)
        self._bin += _pad(bytes(data))
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        return self.add("bufferViews", view)

    def accessor(
        self,
        array: np.ndarray,
        *,
        kind: str | None = None,
        target: int | None = None,
        normalized: bool = False,
        bounds: bool = False,
    ) -> int:
        """Append an array as an accessor; returns its index.

        Args:
            array: (count,) or (count, width) of int8/uint8/int16/uint16/uint32/float32
                (width 1, 2, 3, 4 or 16; (count, 4, 4) matrices are written column-major).
            kind: glTF type ("SCALAR", "VEC3", "MAT4"...); by default from the width.
            target: ARRAY_BUFFER / ELEMENT_ARRAY_BUFFER for vertex data and indices.
            bounds: write ``min``/``max`` (required for POSITION and animation inputs).
        """
        arr = np.asarray(array)
        if arr.ndim == 3 and arr.shape[1:] == (4, 4):
            arr = np.ascontiguousarray(arr.transpose(0, 2, 1)).reshape(len(arr), 16)
            kind = kind or "MAT4"
        if arr.dtype not in _CODES:
            raise InvalidInputError(f"accessor: unsupported dtype {arr.dtype} (expected one of glTF's component types)")
        width = 1 if arr.ndim == 1 else arr.shape[1]
        kind = kind or _TYPE_OF_WIDTH.get(width)
        if kind is None or TYPE_SIZES[kind] != width:
            raise InvalidInputError(f"accessor: array of shape {arr.shape} does not fit glTF type {kind!r}")
        acc = {
            "bufferView": self.buffer_view(np.ascontiguousarray(arr).tobytes(), target),
            "componentType": _CODES[arr.dtype],
            "count": int(len(arr)),
            "type": kind,
        }
        if normalized:
            acc["normalized"] = True
        if bounds:
            flat = arr.reshape(len(arr), -1)
            conv = float if arr.dtype.kind == "f" else int
            acc["min"] = [conv(v) for v in flat.min(axis=0)]
            acc["max"] = [conv(v) for v in flat.max(axis=0)]
        return self.add("accessors", acc)

    def image(self, data: bytes, mime: str = "image/png") -> int:
        """Append an encoded image; returns the index in ``doc["images"]``."""
        return self.add("images", {"bufferView": self.buffer_view(data), "mimeType": mime})

    def to_glb(self) -> bytes:
        """The GLB container bytes."""
        doc = dict(self.doc)
        if self._bin:
            doc["buffers"] = [{"byteLength": len(self._bin)}]
        text = json.dumps(doc, separators=(",", ":"), sort_keys=False).encode("utf-8")
        json_chunk = _pad(text, b" ")
        chunks = struct.pack("<II", len(json_chunk), CHUNK_JSON) + json_chunk
        if self._bin:
            bin_chunk = _pad(bytes(self._bin))
            chunks += struct.pack("<II", len(bin_chunk), CHUNK_BIN) + bin_chunk
        return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks

    def write(self, path: str | Path) -> Path:
        """Write the .glb (through a temporary file, so a crash leaves no half file)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_bytes(self.to_glb())
        tmp.replace(path)
        return path


class GltfFile:
    """A loaded glTF asset: ``doc`` (the JSON dict), ``buffers`` (list of bytes), ``path``."""

    def __init__(self, doc: dict, buffers: list[bytes], path: Path):
        self.doc, self.buffers, self.path = doc, buffers, path

    def accessor(self, index: int) -> np.ndarray:
        return read_accessor(self, index)

    def view_bytes(self, index: int) -> bytes:
        view = self.doc["bufferViews"][index]
        data = self.buffers[view["buffer"]]
        start = view.get("byteOffset", 0)
        return data[start : start + view["byteLength"]]

    def image_bytes(self, index: int) -> bytes:
        """Encoded bytes of ``doc["images"][index]`` (buffer view, data URI or file)."""
        img = self.doc["images"][index]
        if "bufferView" in img:
            return self.view_bytes(img["bufferView"])
        return _uri_bytes(img.get("uri", ""), self.path, f"images[{index}]")


def _uri_bytes(uri: str, base: Path, what: str) -> bytes:
    if uri.startswith("data:"):
        head, _, payload = uri.partition(",")
        return base64.b64decode(payload) if head.endswith(";base64") else unquote(payload).encode()
    target = base.parent / unquote(uri)
    if not target.is_file():
        raise InvalidInputError(f"{base}: {what} refers to {uri!r}, which is not a file beside it")
    return target.read_bytes()


def read_gltf(path: str | Path) -> GltfFile:
    """Load a .glb or .gltf file. Raises InvalidInputError naming the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"glTF file {path}: not found")
    raw = path.read_bytes()
    buffers: list[bytes] = []
    if raw[:4] == b"glTF":
        if len(raw) < 20:
            raise InvalidInputError(f"glTF file {path}: truncated GLB header")
        magic, version, length = struct.unpack_from("<III", raw, 0)
        if version != 2:
            raise InvalidInputError(f"glTF file {path}: GLB version {version}, expected 2")
        if length > len(raw):
            raise InvalidInputError(f"glTF file {path}: GLB header says {length} bytes, file has {len(raw)}")
        pos, doc, glb_bin = 12, None, None
        while pos + 8 <= length:
            size, kind = struct.unpack_from("<II", raw, pos)
            body = raw[pos + 8 : pos + 8 + size]
            if kind == CHUNK_JSON and doc is None:
                doc = _parse_json(body, path)
            elif kind == CHUNK_BIN and glb_bin is None:
                glb_bin = bytes(body)
            pos += 8 + size
        if doc is None:
            raise InvalidInputError(f"glTF file {path}: GLB without a JSON chunk")
    else:
        doc, glb_bin = _parse_json(raw, path), None
    version = str(doc.get("asset", {}).get("version", ""))
    if not version.startswith("2."):
        raise InvalidInputError(f"glTF file {path}: asset.version {version!r}, expected 2.x")
    for i, buf in enumerate(doc.get("buffers", [])):
        if "uri" in buf:
            buffers.append(_uri_bytes(buf["uri"], path, f"buffers[{i}]"))
        elif glb_bin is not None and i == 0:
            buffers.append(glb_bin)
        else:
            raise InvalidInputError(f"glTF file {path}: buffers[{i}] has no data")
    return GltfFile(doc, buffers, path)


def _parse_json(data: bytes, path: Path) -> dict:
    try:
        doc = json.loads(data.decode("utf-8").rstrip(" \x00"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidInputError(f"glTF file {path}: invalid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise InvalidInputError(f"glTF file {path}: the JSON document is not an object")
    return doc


def read_accessor(gltf: GltfFile, index: int) -> np.ndarray:
    """Accessor ``index`` as an array: (count,) for SCALAR, (count, n) for vectors,
    (count, 4, 4) for MAT4 (row-major, i.e. ``m @ v``); normalised integers become float32
    in [0, 1] (or [-1, 1])."""
    try:
        acc = gltf.doc["accessors"][index]
    except (KeyError, IndexError, TypeError):
        raise InvalidInputError(f"glTF file {gltf.path}: accessor {index} does not exist") from None
    dtype = np.dtype(COMPONENT_TYPES[acc["componentType"]]).newbyteorder("<")
    width = TYPE_SIZES[acc["type"]]
    count = int(acc["count"])
    if "bufferView" in acc:
        view = gltf.doc["bufferViews"][acc["bufferView"]]
        data = gltf.buffers[view["buffer"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        elem = dtype.itemsize * width
        stride = view.get("byteStride", elem)
        if count and start + stride * (count - 1) + elem > len(data):
            raise InvalidInputError(f"glTF file {gltf.path}: accessor {index} runs past its buffer")
        arr = np.ndarray(
            (count, width), dtype=dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize)
        ).copy()
    else:
        arr = np.zeros((count, width), dtype=dtype)
    sparse = acc.get("sparse")
    if sparse:
        n = int(sparse["count"])
        idx_acc = {
            "bufferView": sparse["indices"]["bufferView"],
            "byteOffset": sparse["indices"].get("byteOffset", 0),
            "componentType": sparse["indices"]["componentType"],
            "count": n,
            "type": "SCALAR",
        }
        val_acc = {
            "bufferView": sparse["values"]["bufferView"],
            "byteOffset": sparse["values"].get("byteOffset", 0),
            "componentType": acc["componentType"],
            "count": n,
            "type": acc["type"],
        }
        tmp = GltfFile(
            {"accessors": [idx_acc, val_acc], "bufferViews": gltf.doc["bufferViews"]}, gltf.buffers, gltf.path
        )
        arr[read_accessor(tmp, 0).astype(np.int64)] = read_accessor(tmp, 1).reshape(n, width)
    if acc.get("normalized") and dtype.kind in "iu":
        info = np.iinfo(dtype)
        arr = np.maximum(arr.astype(np.float32) / info.max, -1.0)
    if acc["type"] == "MAT4":
        return arr.reshape(count, 4, 4).transpose(0, 2, 1).copy()
    if acc["type"] == "MAT3":
        return arr.reshape(count, 3, 3).transpose(0, 2, 1).copy()
    return arr[:, 0] if width == 1 else arr
