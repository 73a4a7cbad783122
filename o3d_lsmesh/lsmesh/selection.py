"""Control-point selection for least-squares meshes and geometry-aware approximation.

Section 4 of Sorkine and Cohen-Or, *Least-squares Meshes* (SMI 2004): random, one-by-one greedy and
combined local-maxima selection; the greedy anchors of section IV of Sorkine et al., *Geometry-aware Bases
for Shape Approximation*, each added by a rank-1 update of the kept factor (section III). Every selection
starts with one vertex per connected component (the start set; docs: ``docs/algorithms/least_squares_meshes.rst``).
"""

from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import new_mesh, read_mesh
from ..core.arrays import concatenated_ranges
from ..core.connectivity import Connectivity
from ..core.errors import InputError, InputTypeError
from ..core.progress import Progress
from ..core.validate import as_bool, as_choice, as_count, as_positive_float
from .lsmesh import LSMeshSystem, solve_once

if TYPE_CHECKING:
    from .._types import AnyMesh, MeshT

__all__ = ["SELECTION_METHODS", "approximate", "control_point_selection", "select_control_points"]

SELECTION_METHODS = ("random", "greedy", "combined")
DEFAULT_BATCH = 31  # picks per solve of "combined": LS meshes figure 6 (benchmarks/results/selection.md)


def _rng(seed: Any) -> np.random.Generator:
    if seed is None or isinstance(seed, np.random.Generator):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise InputTypeError(
            f"seed must be None, an int or a numpy Generator, got {type(seed).__name__}", param="seed"
        )
    if int(seed) < 0:
        raise InputError(f"seed must be non-negative, got {int(seed)}", param="seed")
    return np.random.default_rng(int(seed))


def _first_per_label(labels: np.ndarray, order: np.ndarray, count: int) -> np.ndarray:
    """For each label, the first vertex of ``order`` that carries it, in label order."""
    first = np.full(count, len(order), dtype=np.int64)
    np.minimum.at(first, labels[order], np.arange(len(order)))
    return order[first]


def start_vertices(
    vertices: np.ndarray, triangles: np.ndarray, *, conn: Connectivity | None = None
) -> np.ndarray:
    """``(c,) int64``: per connected component, in component order, its vertex farthest from its centroid."""
    n = len(vertices)
    count, labels = (Connectivity(triangles, n) if conn is None else conn).components
    size = np.bincount(labels, minlength=count).astype(np.float64)
    sums = np.stack([np.bincount(labels, weights=vertices[:, a], minlength=count) for a in range(3)], axis=1)
    centroid = sums / size[:, None]
    distance = np.einsum("ij,ij->i", vertices - centroid[labels], vertices - centroid[labels])
    # farthest first within each component; ties go to the smaller index (stable sort)
    order = np.lexsort((np.arange(n), -distance))
    return _first_per_label(labels, order, count)


def _random(vertices: np.ndarray, conn: Connectivity, count: int, rng: np.random.Generator) -> np.ndarray:
    n = len(vertices)
    components, labels = conn.components
    order = rng.permutation(n)
    start = _first_per_label(labels, order, components)
    rest = np.ones(n, dtype=bool)
    rest[start] = False
    return np.concatenate([start, order[rest[order]]])[:count]  # the rest in the permutation's order


def forbid_around(
    indptr: np.ndarray, neighbours: np.ndarray, errors: np.ndarray, forbidden: np.ndarray, vertex: int
) -> None:
    """Forbid ``vertex`` and the region a breadth-first walk reaches from it while the error strictly
    decreases (already forbidden vertices stop it); one BFS layer per numpy step."""
    forbidden[vertex] = True
    frontier = np.array([vertex], dtype=np.int64)
    while frontier.size:
        begin, counts = indptr[frontier], indptr[frontier + 1] - indptr[frontier]
        source = np.repeat(frontier, counts)
        target = neighbours[concatenated_ranges(begin, counts)]
        reached = np.unique(target[~forbidden[target] & (errors[target] < errors[source])])
        forbidden[reached] = True
        frontier = reached


def _select(
    vertices: np.ndarray,
    conn: Connectivity,
    count: int,
    weight: float,
    batch: int,
    *,
    desc: str,
    progress: bool = False,
) -> tuple[np.ndarray, LSMeshSystem]:
    """Greedy (``batch=1``) or combined selection: one solve per ``batch`` picks, which join the kept factor
    by one rank-``batch`` update; the selection and the system holding all of it."""
    n = len(vertices)
    start = start_vertices(vertices, conn.triangles, conn=conn)
    # the per-component seeds are control points too: the bar starts at them and ends at count
    with Progress(progress, desc).bar(count, initial=len(start), unit="point") as bar:
        bar.set_postfix_str("factor")
        indptr = neighbours = np.zeros(0, dtype=np.int64)  # a batch of one forbids nothing
        if batch > 1:
            adjacency = conn.adjacency
            indptr, neighbours = adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64)
        solver = LSMeshSystem(vertices, conn.triangles, start, weights=weight, _conn=conn)
        selected = np.zeros(n, dtype=bool)
        selected[start] = True
        order = [start]
        done = len(start)
        bar.set_postfix_str("select")
        while done < count:
            residual = solver.solve(refine=False) - vertices
            errors = np.einsum("ij,ij->i", residual, residual)  # squared distance of each vertex
            forbidden = selected.copy()
            picks: list[int] = []
            size = min(batch, count - done)
            for _ in range(size):
                best = int(np.argmax(np.where(forbidden, -np.inf, errors)))
                if forbidden[best]:  # every vertex is selected or forbidden: solve again
                    break
                picks.append(best)
                if len(picks) < size:  # (the next solve starts afresh: the last pick forbids nothing)
                    forbid_around(indptr, neighbours, errors, forbidden, best)
            chosen = np.asarray(picks, dtype=np.int64)
            selected[chosen] = True
            solver.add_anchors(chosen, weights=weight)
            order.append(chosen)
            done += len(chosen)
            bar.update(len(chosen))
    return np.concatenate(order), solver


def control_point_selection(
    vertices: np.ndarray,
    triangles: np.ndarray,
    count: Any,
    *,
    method: str = "greedy",
    batch: Any = None,
    weights: Any = 1.0,
    seed: Any = None,
    progress: bool = False,
) -> tuple[np.ndarray, LSMeshSystem | None]:
    """Array core of :func:`select_control_points` on validated arrays: ``(count,) int64`` indices and, for
    ``"greedy"`` and ``"combined"``, the :class:`~o3d_lsmesh.lsmesh.LSMeshSystem` holding them (else None)."""
    n = len(vertices)
    method = as_choice(method, SELECTION_METHODS, name="method")
    count = as_count(count, name="count", minimum=1, maximum=n)
    weight = as_positive_float(weights, name="weights")
    conn = Connectivity(triangles, n)  # one grouping of the mesh for the whole selection
    components, _ = conn.components
    if count < components:
        raise InputError(
            f"count must be at least the number of connected components ({components}, "
            f"unreferenced vertices included) so that every component gets a control point, got {count}",
            param="count",
        )
    if method == "combined":
        batch = DEFAULT_BATCH if batch is None else as_count(batch, name="batch", minimum=1)
    elif batch is not None:
        raise InputError(
            f"batch applies only to method='combined', got batch={batch!r} with method={method!r}",
            param="batch",
        )
    rng = _rng(seed)
    if method != "random" and seed is not None:  # greedy and combined draw nothing: a seed changes nothing
        raise InputError(
            f"seed applies only to method='random', got seed={seed!r} with method={method!r}", param="seed"
        )
    as_bool(progress, name="progress")
    if method == "random":  # instant: no progress bar
        return _random(vertices, conn, count, rng), None
    # greedy is the combined method with one pick per solve (batch is None for it)
    return _select(vertices, conn, count, weight, batch or 1, desc=f"{method} selection", progress=progress)


def select_control_points(
    mesh: AnyMesh,
    count: int,
    *,
    method: str = "greedy",
    batch: int | None = None,
    weights: float = 1.0,
    seed: Any = None,
    progress: bool = False,
) -> np.ndarray:
    """Choose ``count`` control points that make the LS mesh close to ``mesh`` (LS meshes section 4).

    ``"greedy"`` picks the vertex farthest from the current selection's LS mesh, ``"combined"`` ``batch``
    local maxima per solve, ``"random"`` a random order; each starts with one vertex per component.
    Returns ``(count,) int64`` indices in selection order (``docs/algorithms/least_squares_meshes.rst``).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Split vertices (UV seams) are welded; indices are returned in the mesh's layout.
    count : int
        From the number of connected components to ``n``.
    method : {"greedy", "combined", "random"}
    batch, weights, seed, progress
        Picks per solve of ``"combined"`` (default 31); the positive weight of the soft control points;
        the random state of ``"random"`` (int or Generator); a progress bar.

    Raises
    ------
    InputError
        An option out of range or of the wrong type (``InputTypeError``), or an invalid mesh.

    Examples
    --------
    >>> import open3d as o3d
    >>> select_control_points(o3d.geometry.TriangleMesh.create_box(), 8).shape
    (8,)
    """
    data = read_mesh(mesh, weld=True)
    options: dict[str, Any] = dict(method=method, batch=batch, weights=weights, seed=seed, progress=progress)
    return data.source_indices(control_point_selection(data.vertices, data.triangles, count, **options)[0])


def approximate(
    mesh: MeshT,
    count: int,
    *,
    method: str = "greedy",
    weights: float = 1.0,
    interpolate: bool = False,
    batch: int | None = None,
    seed: Any = None,
    progress: bool = False,
) -> tuple[MeshT, np.ndarray]:
    """Approximate ``mesh`` by the LS mesh of ``count`` control points from :func:`select_control_points`.

    The LS mesh (eq. 3) through the selection at its positions, or the interpolatory one with
    ``interpolate=True`` (bases paper II.B). Other options: see :func:`select_control_points`.

    Returns
    -------
    approximation : TriangleMesh
        Same kind, triangles and colors as ``mesh``.
    indices : (count,) int64
        The control points in selection order.

    Examples
    --------
    >>> import open3d as o3d
    >>> approximate(o3d.geometry.TriangleMesh.create_torus(), 60)[1].shape
    (60,)
    """
    interpolate = as_bool(interpolate, name="interpolate")
    data = read_mesh(mesh, weld=True)
    V, F = data.vertices, data.triangles
    indices, system = control_point_selection(
        V, F, count, method=method, batch=batch, weights=weights, seed=seed, progress=progress
    )
    if system is not None and not interpolate:
        return new_mesh(data, system.solve()), data.source_indices(indices)
    # a new factorization: the LS mesh of the selection, with ls_mesh's bar
    options: dict[str, Any] = dict(weights=weights, interpolate=bool(interpolate), progress=progress)
    vertices = solve_once("ls_mesh", progress, data, indices, **options)
    return new_mesh(data, vertices), data.source_indices(indices)
