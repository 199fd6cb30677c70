"""The labelled-cloud PLY codec: binary little-endian out, ascii or binary in.

One `vertex` element is encoded from a structured array whose field names are the PLY property
names; decoding returns such an array with the file's own fields, for the caller to check.
Hand-written because Open3D's PLY reader drops properties it does not know (label, cluster,
instance) and plyfile is not a dependency; the format is a 20-line header and a flat array.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from capture.errors import RecordingError

_TO_NUMPY: Final = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_TO_PLY: Final = {
    "i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort",
    "i4": "int", "u4": "uint", "f4": "float", "f8": "double",
}  # fmt: skip
_FORMATS: Final = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "ascii"}
_Elements = list[tuple[str, int, list[tuple[str, str]]]]


def encode(vertices: npt.NDArray[np.void], *, comment: str) -> bytes:
    """Encode a structured array as a binary little-endian PLY `vertex` element."""
    names = vertices.dtype.names or ()
    kinds = [vertices.dtype[n].str[1:] for n in names]  # "f4", "u1", ... without byte order
    little = vertices.astype([(n, "<" + k) for n, k in zip(names, kinds, strict=True)])
    header = ["ply", "format binary_little_endian 1.0", f"comment {comment}"]
    header.append(f"element vertex {len(vertices)}")
    header += [f"property {_TO_PLY[k]} {n}" for n, k in zip(names, kinds, strict=True)]
    header.append("end_header\n")
    return "\n".join(header).encode("ascii") + little.tobytes()


def decode(data: bytes, *, source: str) -> npt.NDArray[np.void]:
    """Decode PLY bytes (ascii or binary) into a structured array of the `vertex` element.

    Raises:
        RecordingError: not a PLY, an unsupported header, or fewer bytes than the header says.
    """
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise RecordingError(
            f"expected a PLY file ('ply' ... 'end_header'), found other bytes: {source}"
        )
    body = end + len(b"end_header")
    body += 2 if data[body : body + 2] == b"\r\n" else 1
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    fmt, elements = _header(lines, source)
    offset = body
    for name, count, fields in elements:
        if not fields:
            raise RecordingError(
                f"PLY element {name!r} has no properties; expected x y z ...: {source}"
            )
        dtype = np.dtype([(f, (fmt if fmt != "ascii" else "<") + t) for f, t in fields])
        if name == "vertex":
            if fmt == "ascii":
                return _ascii_vertices(data[offset:], count, dtype, source)
            if len(data) < offset + count * dtype.itemsize:
                raise RecordingError(
                    f"PLY says {count} vertices but the file ends early "
                    f"({len(data) - offset} bytes of {count * dtype.itemsize}): {source}"
                )
            return np.frombuffer(data, dtype=dtype, count=count, offset=offset)
        if fmt == "ascii":
            raise RecordingError(
                f"ascii PLY with element {name!r} before 'vertex' is not supported: {source}"
            )
        offset += count * dtype.itemsize
    raise RecordingError(f"expected a 'vertex' element in the PLY header, found none: {source}")


def _header(lines: list[str], source: str) -> tuple[str, _Elements]:
    fmt = ""
    elements: _Elements = []
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2 and words[1] in _FORMATS:
            fmt = _FORMATS[words[1]]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements and len(words) == 3 and words[1] in _TO_NUMPY:
            if any(name == words[2] for name, _ in elements[-1][2]):
                raise RecordingError(
                    f"PLY element {elements[-1][0]!r} declares property {words[2]!r} twice; "
                    f"expected each once: {source}"
                )
            elements[-1][2].append((words[2], _TO_NUMPY[words[1]]))
        else:
            raise RecordingError(
                f"unsupported PLY header line {line.strip()!r} (list properties?): {source}"
            )
    if not fmt:
        raise RecordingError(
            f"expected a PLY 'format' line (ascii or binary), found none: {source}"
        )
    return fmt, elements


def _ascii_vertices(
    body: bytes, count: int, dtype: np.dtype[np.void], source: str
) -> npt.NDArray[np.void]:
    rows = body.split(b"\n", count)[:count]
    try:
        table = np.array([r.split() for r in rows], dtype=np.float64)
    except ValueError as err:
        raise RecordingError(
            f"ascii PLY rows are not {len(dtype.names or ())} numbers each: {source}"
        ) from err
    if table.shape != (count, len(dtype.names or ())):
        raise RecordingError(f"ascii PLY says {count} vertices but has {len(rows)} rows: {source}")
    out = np.empty(count, dtype=dtype)
    for column, name in enumerate(dtype.names or ()):
        out[name] = table[:, column]
    return out
