"""``o3d-lsmesh approximate``, ``reconstruct``, ``encode`` and ``decode``: least-squares meshes."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._batch_ops import resolve_count
from ._common import CLIError, Run, add_command, positive_int
from ._files import check_output, read_input, write_output

_SELECTION = ("greedy", "random", "combined")


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    files = {"input": "mesh file", "output": "mesh file to write"}
    p = add_command(sub, common, approximate, files)
    p.add_argument("--count", type=positive_int, required=True, help="number of control points")
    p.add_argument("--method", choices=_SELECTION, default="greedy", help="how the control points are chosen")
    p.add_argument("--interpolate", action="store_true", help="interpolate the control points exactly")
    p.add_argument("--seed", type=int, default=0, help="random seed of --method random/combined")
    p.add_argument(
        "--indices",
        metavar="FILE",
        help="also write the control indices, .npy or .txt (default: not written)",
    )

    p = add_command(sub, common, reconstruct, files)
    p.add_argument(
        "--unknown",
        required=True,
        metavar="SPEC",
        help="index file (.npy or text) or list of indices and a:b ranges, e.g. '0:100,250'",
    )
    p.add_argument(
        "--soft", action="store_true", help="known vertices as soft constraints (whole mesh re-solved)"
    )

    p = add_command(sub, common, encode, {"input": "mesh file", "output": "file for the encoded bytes"})
    p.add_argument("--count", type=positive_int, help="anchors (default: 2%% of the vertices)")
    p.add_argument("--bits", type=positive_int, default=12, help="quantization bits per coordinate")
    p.add_argument("--method", choices=_SELECTION, default="greedy", help="how the anchors are chosen")

    positionals = {"mesh": "mesh file the data was encoded on", "data": "file written by encode"}
    p = add_command(sub, common, decode, {**positionals, "output": files["output"]})
    p.add_argument("--anchors", type=positive_int, help="use only the first K anchors (default: all)")


def approximate(args: argparse.Namespace, run: Run) -> int:
    """LS-mesh approximation from N control points.

    Rebuild the geometry from the connectivity and N control points chosen on the mesh
    (least-squares meshes, Sorkine and Cohen-Or 2004).

    example: bunny.ply approx.ply --count 400 --indices controls.npy
    """
    check_output(args.output, [args.input], force=args.force)
    if args.indices:
        check_output(args.indices, [args.input], force=args.force, suffixes=(".npy", ".txt"))
    mesh = read_input(args.input)
    from ..metrics import vertex_error
    from ..selection import approximate as approximate_mesh

    start = time.perf_counter()
    out, indices = approximate_mesh(
        mesh,
        args.count,
        method=args.method,
        interpolate=args.interpolate,
        seed=args.seed,
        progress=run.progress,
    )
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    indices = np.asarray(indices, dtype=np.int64)
    if args.indices:
        if args.indices.endswith(".npy"):
            np.save(args.indices, indices)
        else:
            np.savetxt(args.indices, indices, fmt="%d")
    error = vertex_error(out, mesh)
    run.say(
        f"approximated {args.input} from {len(indices)} control points in {seconds:.2f} s -> {args.output}; "
        f"L-inf error {error['linf']:.4g}, RMS {error['rms']:.4g}"
    )
    return run.finish(
        mesh,
        count=len(indices),
        method=args.method,
        seconds=seconds,
        error_linf=error["linf"],
        error_rms=error["rms"],
    )


def parse_index_spec(spec: str, n: int) -> np.ndarray:
    """Vertex indices from a file (``.npy``, or integers separated by spaces, commas or newlines) or a list like ``0:100,250,300:310``.

    ``a:b`` is the half-open range ``a, ..., b-1`` (Python slicing, without
    negative indices). Overlapping items name a vertex once: the union is meant.

    >>> parse_index_spec("0:3,5,2", 10)
    array([0, 1, 2, 5])
    """
    if os.path.exists(spec):
        return _index_file(spec, n)
    parts = []
    for item in (item.strip() for item in spec.split(",")):
        if not item:
            continue
        try:
            start_text, colon, stop_text = item.partition(":")
            start = int(start_text) if start_text or not colon else 0
            stop = (int(stop_text) if stop_text else n) if colon else start + 1
        except ValueError:
            raise CLIError(
                f"--unknown must be an existing index file or a list like '0:100,250', got {spec!r}"
            ) from None
        if start < 0 or stop > n or stop < start:
            # checked before any array is made: '0:99999999999' must not allocate 800 GB
            what = f"range {item!r}" if colon else f"index {item!r}"
            raise CLIError(
                f"--unknown must name vertices in 0..{n - 1} (the mesh has {n} vertices), got {what}"
            )
        parts.append(np.arange(start, stop, dtype=np.int64))
    if not parts:
        raise CLIError(f"--unknown must name at least one vertex, got {spec!r}")
    return np.unique(np.concatenate(parts))


def _index_file(path: str, n: int) -> np.ndarray:
    try:
        if path.endswith(".npy"):
            values = np.asarray(np.load(path, allow_pickle=False)).ravel()
        else:
            values = np.array(
                [int(t) for t in Path(path).read_text().replace(",", " ").split()], dtype=np.int64
            )
    except (ValueError, OSError) as error:
        raise CLIError(f"--unknown file {path!r} must hold integer vertex indices ({error})") from None
    if values.size and not np.issubdtype(values.dtype, np.integer):
        raise CLIError(f"--unknown file {path!r} must hold integer vertex indices, got dtype {values.dtype}")
    if values.size == 0:
        raise CLIError(f"--unknown file {path!r} must name at least one vertex, got none")
    bad = (values < 0) | (values >= n)
    if bad.any():
        raise CLIError(
            f"--unknown file {path!r} must hold vertex indices in 0..{n - 1} (the mesh has {n} "
            f"vertices), got {int(values[bad][0])}"
        )
    return np.unique(values.astype(np.int64))


def reconstruct(args: argparse.Namespace, run: Run) -> int:
    """Rebuild the geometry of unknown vertices.

    Replace the positions of the --unknown vertices by the least-squares mesh of the known ones
    (LS meshes, figures 5 and 8); known vertices stay as they are unless --soft.

    example: scan.ply filled.ply --unknown 0:100,250
    """
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    unknown = parse_index_spec(args.unknown, len(mesh.vertices))
    from ..lsmesh import reconstruct_geometry

    start = time.perf_counter()
    out = reconstruct_geometry(mesh, unknown, interpolate=not args.soft, progress=run.progress)
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    moved = np.linalg.norm(np.asarray(out.vertices)[unknown] - np.asarray(mesh.vertices)[unknown], axis=1)
    run.say(
        f"reconstructed {len(unknown)} vertices of {args.input} in {seconds:.2f} s -> {args.output}; "
        f"mean distance to the file's positions {moved.mean():.4g}"
    )
    return run.finish(
        mesh,
        unknown=len(unknown),
        seconds=seconds,
        distance_to_input_mean=float(moved.mean()),
        distance_to_input_max=float(moved.max()),
    )


def encode(args: argparse.Namespace, run: Run) -> int:
    """Encode the geometry as quantized LS-mesh anchors.

    Store the geometry as the quantized positions of a few anchors; decode rebuilds it from the
    connectivity (geometry-aware bases, Sorkine et al.).

    example: bunny.ply bunny.lsm --count 500 --bits 12
    """
    check_output(args.output, [args.input], force=args.force, suffixes=None)
    mesh = read_input(args.input)
    n = len(mesh.vertices)
    count = resolve_count(0.02 if args.count is None else args.count, n)  # batch's default: 2%
    from ..encoding import decode_geometry, encode_geometry
    from ..metrics import vertex_error

    start = time.perf_counter()
    data = encode_geometry(mesh, count, bits=args.bits, method=args.method, progress=run.progress)
    seconds = time.perf_counter() - start
    Path(args.output).write_bytes(data)
    error = vertex_error(decode_geometry(mesh, data, progress=run.progress), mesh)
    run.say(
        f"encoded {args.input}: {count} anchors at {args.bits} bits -> {len(data)} bytes "
        f"({8.0 * len(data) / n:.3f} bits/vertex) in {seconds:.2f} s; decoded L-inf error {error['linf']:.4g}"
    )
    return run.finish(
        mesh,
        anchors=count,
        bits=args.bits,
        bytes=len(data),
        bits_per_vertex=8.0 * len(data) / n,
        seconds=seconds,
        decoded_error_linf=error["linf"],
        decoded_error_rms=error["rms"],
    )


def decode(args: argparse.Namespace, run: Run) -> int:
    """Decode geometry onto a mesh's connectivity.

    Rebuild the geometry stored by encode on the connectivity of MESH, from all its anchors or
    the first K (progressive decoding).

    example: bunny.ply bunny.lsm decoded.ply --anchors 200
    """
    check_output(args.output, [args.mesh, args.data], force=args.force)
    mesh = read_input(args.mesh, what="MESH")
    if not os.path.exists(args.data):
        raise CLIError(f"DATA {args.data!r} does not exist")
    data = Path(args.data).read_bytes()
    from ..encoding import decode_geometry

    start = time.perf_counter()
    out = decode_geometry(mesh, data, anchors=args.anchors, progress=run.progress)
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    run.say(f"decoded {args.data} on the connectivity of {args.mesh} in {seconds:.2f} s -> {args.output}")
    return run.finish(mesh, anchors=args.anchors, seconds=seconds)
