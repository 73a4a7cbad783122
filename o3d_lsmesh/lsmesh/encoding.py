"""Compact geometry encoding with geometry-aware bases (Sorkine et al., section V).

A mesh's geometry, for a decoder that has its connectivity, is the indices of ``k`` anchors in greedy
selection order and their quantized positions (the relaxed basis' coefficients, section II.C). The
decoder solves eq. 1, ``min ||L x||^2 + sum_i omega^2 |x_{a_i} - c_i|^2`` with ``omega = 10 n`` by
default; progressive decoding adds anchors by rank-k updates (section III). The stream layout and its
checks: ``docs/algorithms/encoding.rst``.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import MeshData, new_mesh, read_mesh
from ..core.arrays import dequantize, quantize
from ..core.connectivity import Connectivity
from ..core.errors import InputError, InputTypeError
from ..core.operators import uniform_laplacian
from ..core.progress import Progress
from ..core.solve import check_weight_pins_components
from ..core.validate import as_bool, as_choice, as_count, as_positive_float
from .lsmesh import LSMeshSystem, solve_once
from .selection import SELECTION_METHODS, control_point_selection

if TYPE_CHECKING:
    from .._types import AnyMesh, MeshT

__all__ = ["decode_geometry", "encode_geometry", "iter_decode_geometry"]

MAGIC = b"LSMG"
VERSION = 1
HEADER = struct.Struct("<4sBBBBIIId3d3d")
_CRC = struct.Struct("<I")
MAX_BITS = 31


def index_width(n: int) -> int:
    return max(1, math.ceil(math.log2(n))) if n > 1 else 1


def connectivity_checksum(triangles: np.ndarray, n: int) -> int:
    """CRC-32 of the sorted unique edges: the graph that the uniform Laplacian depends on."""
    edges = Connectivity(triangles, n).edges
    return zlib.crc32(np.ascontiguousarray(edges, dtype="<i8").tobytes()) & 0xFFFFFFFF


def to_bits(values: np.ndarray, width: int) -> np.ndarray:
    """``(len(values) * width,) uint8`` bits of ``values``, MSB first."""
    shifts = np.arange(width - 1, -1, -1, dtype=np.uint64)
    return ((values.astype(np.uint64)[:, None] >> shifts) & np.uint64(1)).astype(np.uint8).ravel()


def from_bits(bits: np.ndarray, width: int) -> np.ndarray:
    """Inverse of :func:`to_bits`: ``(len(bits) // width,) int64``."""
    weights = np.uint64(1) << np.arange(width - 1, -1, -1, dtype=np.uint64)
    return (bits.reshape(-1, width).astype(np.uint64) * weights).sum(axis=1).astype(np.int64)


def assemble_stream(
    *,
    n: int,
    indices: np.ndarray,
    quantized: np.ndarray,
    bits: int,
    index_bits: int,
    edges_crc: int,
    omega: float,
    lower: np.ndarray,
    upper: np.ndarray,
    version: int = VERSION,
    reserved: int = 0,
    magic: bytes = MAGIC,
) -> bytes:
    """Write a stream from its fields (no validation: tests build malformed streams with it)."""
    header = HEADER.pack(
        magic, version, bits, index_bits, reserved, n, len(indices), edges_crc, omega, *lower, *upper
    )
    payload_bits = np.concatenate([to_bits(indices, index_bits), to_bits(quantized.ravel(), bits)])
    payload = np.packbits(payload_bits).tobytes()
    body = header + payload
    return body + _CRC.pack(zlib.crc32(body) & 0xFFFFFFFF)


def encode_geometry(
    mesh: AnyMesh,
    count: int,
    *,
    bits: int = 12,
    method: str = "greedy",
    weight: float | None = None,
    progress: bool = False,
) -> bytes:
    """Encode the geometry of ``mesh`` as ``count`` quantized anchors (geometry-aware bases, section V).

    Anchors from :func:`~o3d_lsmesh.select_control_points` at the decoder's weight (section IV), stored in
    about ``count * (log2 n + 3 bits)`` bits plus an 80-byte header and checksum.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    count, bits : int
        Anchors (from the number of components to ``n``); bits per coordinate, 1 to 31 (paper: 10 to 12).
    method : {"greedy", "combined", "random"}
    weight : float, optional
        Anchor weight ``omega``; default ``10 n`` as in the paper.
    progress : bool

    Raises
    ------
    InputError
        An option out of range, more than ``2**32 - 1`` vertices, an invalid mesh.

    Examples
    --------
    >>> import open3d as o3d
    >>> len(encode_geometry(o3d.geometry.TriangleMesh.create_sphere(resolution=10), 20, bits=10))
    175
    """
    data = read_mesh(mesh, weld=True)
    n = len(data.vertices)
    if n > 0xFFFFFFFF:
        raise InputError(f"mesh must have fewer than 2**32 vertices to be encoded, got {n}", param="mesh")
    bits = as_count(bits, name="bits", minimum=1, maximum=MAX_BITS)
    method = as_choice(method, SELECTION_METHODS, name="method")
    omega = 10.0 * n if weight is None else as_positive_float(weight, name="weight")
    if weight is not None:  # a weight too small to pin the anchors decodes to a drifted mesh
        check_weight_pins_components(uniform_laplacian(Connectivity(data.triangles, n)), omega, name="weight")
    indices, _ = control_point_selection(
        data.vertices,
        data.triangles,
        count,
        method=method,
        weights=omega,
        seed=0 if method == "random" else None,  # a file encoded twice is the same file
        progress=progress,
    )
    positions = data.vertices[indices]
    lower, upper = positions.min(axis=0), positions.max(axis=0)
    fields: dict[str, Any] = dict(n=n, indices=indices, bits=bits, index_bits=index_width(n), omega=omega)
    fields.update(quantized=quantize(positions, lower, upper, bits), lower=lower, upper=upper)
    return assemble_stream(edges_crc=connectivity_checksum(data.triangles, n), **fields)


def _bad(message: str) -> InputError:
    return InputError(message, param="data")


def _parse(data: Any, mesh_data: MeshData) -> tuple[np.ndarray, np.ndarray, float]:
    """Validate ``data`` against the mesh; return ``(indices, positions, omega)``."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise InputTypeError(
            f"data must be bytes from encode_geometry, got {type(data).__name__}", param="data"
        )
    raw = bytes(data)
    if raw[: len(MAGIC)] != MAGIC:
        raise _bad(
            f"data must start with the magic {MAGIC!r} of an o3d_lsmesh geometry stream, got {raw[: len(MAGIC)]!r}"
        )
    if len(raw) < HEADER.size + _CRC.size:
        raise _bad(
            f"data must hold at least {HEADER.size + _CRC.size} bytes (header and checksum), got {len(raw)}: truncated stream"
        )
    (_magic, version, bits, index_bits, reserved, n, k, edges_crc, omega, *box) = HEADER.unpack_from(raw)
    if version != VERSION:
        raise _bad(f"data must be a version {VERSION} stream, got version {version}")
    body, (crc,) = raw[: -_CRC.size], _CRC.unpack_from(raw, len(raw) - _CRC.size)
    if not 1 <= bits <= MAX_BITS:
        raise _bad(f"data header bits must lie in [1, {MAX_BITS}], got {bits}: corrupted stream")
    payload_bytes = (k * (index_bits + 3 * bits) + 7) // 8
    expected = HEADER.size + payload_bytes + _CRC.size
    if len(raw) != expected:
        raise _bad(
            f"data must be {expected} bytes long for {k} anchors, got {len(raw)}: truncated or padded stream"
        )
    actual = zlib.crc32(body) & 0xFFFFFFFF
    if crc != actual:
        raise _bad(
            f"data checksum must match its content, got {crc:#010x} stored and {actual:#010x} computed: corrupted stream"
        )
    # from here on the stream is intact: errors are streams written inconsistently, or the wrong mesh
    if reserved != 0:
        raise _bad(f"data header reserved byte must be 0, got {reserved}")
    if n < 1 or index_bits != index_width(n):
        raise _bad(
            f"data header index_bits must be ceil(log2 n) = {index_width(max(n, 1))} for n = {n}, got {index_bits}"
        )
    if not 1 <= k <= n:
        raise _bad(f"data header anchor count must lie in [1, {n}], got {k}")
    lower, upper = np.array(box[:3]), np.array(box[3:])
    if not (np.isfinite(omega) and omega > 0):
        raise _bad(f"data header omega must be positive and finite, got {omega}")
    if not (np.isfinite(lower).all() and np.isfinite(upper).all() and (lower <= upper).all()):
        raise _bad(
            f"data header bounding box must be finite with min <= max, got {lower.tolist()} and {upper.tolist()}"
        )
    vertex_count = len(mesh_data.vertices)
    if vertex_count != n:
        raise InputError(
            f"mesh must have the {n} vertices the stream was encoded for, got {vertex_count} (vertices at "
            "equal positions count once, as when encoding: a mesh split at UV seams needs its own positions "
            "there, or the welded mesh)",
            param="mesh",
        )
    if connectivity_checksum(mesh_data.triangles, n) != edges_crc:
        raise InputError(
            "mesh must have the connectivity the stream was encoded for, got a mesh whose edges differ "
            "(connectivity checksum mismatch)",
            param="mesh",
        )
    bit_stream = np.unpackbits(np.frombuffer(raw, dtype=np.uint8, offset=HEADER.size, count=payload_bytes))
    used = k * (index_bits + 3 * bits)
    if bit_stream[used:].any():
        raise _bad("data padding bits must be zero, got non-zero padding")
    indices = from_bits(bit_stream[: k * index_bits], index_bits)
    quantized = from_bits(bit_stream[k * index_bits : used], bits).reshape(k, 3)
    if (indices >= n).any():
        bad = int(np.flatnonzero(indices >= n)[0])
        raise _bad(f"data anchor indices must lie in [0, {n}), got {int(indices[bad])} at anchor {bad}")
    ordered = np.sort(indices)
    repeated = ordered[1:] == ordered[:-1]
    if repeated.any():
        raise _bad(f"data anchor indices must not repeat, got {int(ordered[1:][repeated][0])} more than once")
    return indices, dequantize(quantized, lower, upper, bits), float(omega)


def decode_geometry(mesh: MeshT, data: Any, *, anchors: int | None = None, progress: bool = False) -> MeshT:
    """Reconstruct the geometry encoded by :func:`encode_geometry` on the connectivity of ``mesh``.

    Solves eq. 1 of the bases paper (relaxed anchors of the stream's ``omega``, uniform Laplacian);
    ``anchors`` uses the first ones only (progressive decoding, section III).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Supplies the connectivity; its positions serve only to merge vertices at equal positions, as
        :func:`encode_geometry` did (a mesh split at UV seams: give it its own positions there).
    data : bytes
        A stream of :func:`encode_geometry` for this connectivity.
    anchors, progress
        Number of leading anchors to use, ``1..k`` (default all); a progress bar.

    Raises
    ------
    InputError
        Bad ``data`` (``InputTypeError`` if not bytes), a stream for another mesh, ``anchors`` out of
        range, a prefix missing a component (``SingularSystemError``).

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> len(decode_geometry(box, encode_geometry(box, 8)).vertices)
    8
    """
    as_bool(progress, name="progress")
    mesh_data = read_mesh(mesh, weld=True)
    indices, positions, omega = _parse(data, mesh_data)
    k = len(indices)
    m = k if anchors is None else as_count(anchors, name="anchors", minimum=1, maximum=k)
    # SingularSystemError if the prefix misses a component
    vertices = solve_once("decode_geometry", progress, mesh_data, indices[:m], positions[:m], weights=omega)
    return new_mesh(mesh_data, vertices)


def iter_decode_geometry(
    mesh: MeshT, data: Any, *, step: int | None = None, progress: bool = False
) -> Iterator[MeshT]:
    """Yield successively refined reconstructions as anchors arrive (progressive scheme, section III).

    The first mesh uses the first ``step`` anchors; each next one adds ``step`` more by a rank-``step``
    update of the kept factor. The last equals :func:`decode_geometry` up to round-off.

    Parameters
    ----------
    mesh, data, progress
        As :func:`decode_geometry`.
    step : int, optional
        Anchors per refinement; default ``ceil(k / 10)``, or the number of connected components if larger.

    Raises
    ------
    InputError
        As :func:`decode_geometry`, or ``step`` below 1 or the number of components (at the call).

    Examples
    --------
    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> len(list(iter_decode_geometry(sphere, encode_geometry(sphere, 30), step=10)))
    3
    """
    progress = as_bool(progress, name="progress")
    mesh_data = read_mesh(mesh, weld=True)
    indices, positions, omega = _parse(data, mesh_data)
    k = len(indices)
    if step is None:
        # the first mesh needs an anchor in every component (the selection puts those first): on a
        # raw scan with many small components a tenth of the anchors may not cover them
        components = Connectivity(mesh_data.triangles, len(mesh_data.vertices)).components[0]
        step = max(1, math.ceil(k / 10), min(k, components))
    else:
        step = as_count(step, name="step", minimum=1)
    first = min(step, k)
    # factor now, so that a bad prefix raises at the call and not at the first next()
    solver = LSMeshSystem(mesh_data.vertices, mesh_data.triangles, indices[:first], weights=omega)

    def refinements() -> Iterator[Any]:
        # the bar counts the anchors in the mesh about to be yielded; it closes when the
        # caller stops iterating too (GeneratorExit runs the finally)
        with Progress(progress, "progressive decoding").bar(k, unit="anchor") as bar:
            for begin in [0, *range(first, k, step)]:
                end = min(begin + step, k) if begin else first
                if begin:
                    solver.add_anchors(indices[begin:end], positions[begin:end], weights=omega)
                # pass every position: the solver's defaults for the first anchors are the decoder
                # mesh's own (meaningless) coordinates; after updates the solver refines once
                mesh = new_mesh(mesh_data, solver.solve(positions[:end]))
                bar.update(end - begin)
                yield mesh

    return refinements()
