"""Control-point selection for least-squares meshes and geometry-aware approximation.

Implements section 4 of Sorkine and Cohen-Or, *Least-squares Meshes* (SMI
2004): random, one-by-one greedy and combined local-maxima selection, and the
greedy anchor selection of section IV of Sorkine et al., *Geometry-aware Bases
for Shape Approximation*, where every greedy step adds one relaxed anchor by a
rank-1 update of the kept Cholesky factor (section III) instead of a new
factorization (without scikit-sparse, a low-rank correction of SciPy's LU:
:meth:`~o3d_lsmesh._solvers.SPDSolver.update`).

Start set
---------
An LS mesh needs a control point in every connected component (otherwise the
normal matrix ``L^T L + W^2`` is singular), so every selection starts with one
vertex per component, in increasing component order; unreferenced vertices
are components of their own. The greedy and combined methods start each
component at its vertex farthest from the component's centroid: with a single
anchor the LS mesh of a component collapses onto that anchor (``L 1 = 0``), so
this is the greedy choice for an "empty" selection that sits at the centroid,
and it is deterministic. The random method starts each component at a random
vertex drawn with ``seed``.
"""

from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import new_mesh, read_mesh
from .._progress import check_progress, progress_bar, stages
from .._ranges import concatenated_ranges
from .._validate import as_bool, as_choice, as_count, as_positive_float
from ..topology import adjacency_matrix, connected_components
from .lsmesh import LSMeshSystem

if TYPE_CHECKING:
    from .._types import AnyMesh, MeshT

__all__ = ["SELECTION_METHODS", "approximate", "control_point_selection", "select_control_points"]

SELECTION_METHODS = ("random", "greedy", "combined")
DEFAULT_BATCH = 31  # figure 6 of LS meshes: 31 solves of 31 picks for 1000 control points


def _rng(seed: Any) -> np.random.Generator:
    if seed is None or isinstance(seed, np.random.Generator):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed must be None, an int or a numpy Generator, got {type(seed).__name__}")
    if int(seed) < 0:
        raise ValueError(f"seed must be non-negative, got {int(seed)}")
    return np.random.default_rng(int(seed))


def _first_per_label(labels: np.ndarray, order: np.ndarray, count: int) -> np.ndarray:
    """For each label, the first vertex of ``order`` that carries it, in label order."""
    first = np.full(count, len(order), dtype=np.int64)
    np.minimum.at(first, labels[order], np.arange(len(order)))
    return order[first]


def start_vertices(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """One vertex per connected component: the one farthest from its component's centroid.

    Returns ``(c,) int64`` in component order (see the module docstring).
    """
    n = len(vertices)
    count, labels = connected_components(triangles, n)
    size = np.bincount(labels, minlength=count).astype(np.float64)
    sums = np.stack([np.bincount(labels, weights=vertices[:, a], minlength=count) for a in range(3)], axis=1)
    centroid = sums / size[:, None]
    distance = np.einsum("ij,ij->i", vertices - centroid[labels], vertices - centroid[labels])
    # farthest first within each component; ties go to the smaller index (stable sort)
    order = np.lexsort((np.arange(n), -distance))
    return _first_per_label(labels, order, count)


def _random(vertices: np.ndarray, triangles: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    n = len(vertices)
    components, labels = connected_components(triangles, n)
    order = rng.permutation(n)
    start = _first_per_label(labels, order, components)
    rest = np.ones(n, dtype=bool)
    rest[start] = False
    return np.concatenate([start, order[rest[order]]])[:count]  # the rest in the permutation's order


def forbid_around(
    indptr: np.ndarray, neighbours: np.ndarray, errors: np.ndarray, forbidden: np.ndarray, vertex: int
) -> None:
    """Mark ``vertex`` and the region reached from it by a breadth-first walk while the error decreases.

    A vertex joins when it is adjacent to a vertex already reached by this walk
    and has a strictly smaller error than it; vertices already forbidden stop
    the walk. Expands a whole BFS layer per numpy step.
    """
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
    triangles: np.ndarray,
    count: int,
    weight: float,
    batch: int,
    *,
    desc: str,
    progress: bool = False,
) -> tuple[np.ndarray, LSMeshSystem]:
    """Greedy (``batch=1``) or combined local-maxima selection (LS meshes section 4, bases paper section IV).

    One solve per ``batch`` picks, whose anchors join the kept factor by one
    rank-``batch`` update. Returns the selection and the system holding all of
    it (for one last solve).
    """
    n = len(vertices)
    start = start_vertices(vertices, triangles)
    # the per-component seeds are control points too: the bar starts at them and ends at count
    with progress_bar(progress, total=count, initial=len(start), desc=desc, unit="point") as bar:
        bar.set_postfix_str("factor")
        indptr = neighbours = np.zeros(0, dtype=np.int64)  # a batch of one forbids nothing
        if batch > 1:
            adjacency = adjacency_matrix(triangles, n)
            indptr, neighbours = adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64)
        solver = LSMeshSystem(vertices, triangles, start, weights=weight)
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
    """Array core of :func:`select_control_points` on validated arrays: the indices and their system.

    ``vertices (n, 3) float64`` and ``triangles (m, 3) int64`` as
    :func:`~o3d_lsmesh._validate.mesh_arrays` returns them (the callers read
    them once); the options are checked here. Returns the ``(count,) int64``
    selection and, for ``"greedy"`` and ``"combined"``, the
    :class:`~o3d_lsmesh.lsmesh.LSMeshSystem` whose factor holds every
    selected control point at weight ``weights`` (None for ``"random"``).

    Examples
    --------
    >>> from o3d_lsmesh._validate import mesh_arrays
    >>> V, F = mesh_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]], [[0, 1, 2], [1, 3, 2]])
    >>> indices, system = control_point_selection(V, F, 2)
    >>> indices.shape, system.solve().shape
    ((2,), (4, 3))
    """
    n = len(vertices)
    method = as_choice(method, SELECTION_METHODS, name="method")
    count = as_count(count, name="count", minimum=1, maximum=n)
    weight = as_positive_float(weights, name="weights")
    components, _ = connected_components(triangles, n)
    if count < components:
        raise ValueError(
            f"count must be at least the number of connected components ({components}, "
            f"unreferenced vertices included) so that every component gets a control point, got {count}"
        )
    if method == "combined":
        batch = DEFAULT_BATCH if batch is None else as_count(batch, name="batch", minimum=1)
    elif batch is not None:
        raise ValueError(
            f"batch applies only to method='combined', got batch={batch!r} with method={method!r}"
        )
    rng = _rng(seed)
    check_progress(progress)
    if method == "random":  # instant: no progress bar
        return _random(vertices, triangles, count, rng), None
    # greedy is the combined method with one pick per solve (batch is None for it)
    return _select(
        vertices, triangles, count, weight, batch or 1, desc=f"{method} selection", progress=progress
    )


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

    The error of a vertex is the 3D distance between its position in the LS
    mesh of the current selection (eq. 3 of Least-squares Meshes with soft
    constraints of weight ``weights``, uniform Laplacian) and its original
    position.

    * ``"random"``: a uniformly random order, reproducible with ``seed``.
    * ``"greedy"``: one vertex at a time, the one with the largest error; a
      step is a rank-1 update of the kept factor plus one back-substitution.
    * ``"combined"``: the local-maxima method. The LS mesh is solved once per
      ``batch`` picks; within a batch each pick is the largest error among the
      vertices not forbidden, after which the vertices reached from it by a
      breadth-first walk along which the error strictly decreases are forbidden
      until the next solve. The picks of a batch join the factor by one rank-``batch``
      update.

    Every selection starts with one vertex per connected component so that the
    system is never singular (see the module docstring for which one).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Vertices at exactly equal coordinates (the copies a file reader makes
        at UV seams) are welded and selected once; the indices returned are
        in the mesh's own layout (the first copy of a split vertex).
    count : int
        Number of control points, from the number of connected components to
        ``n`` (``n`` counts a split vertex once).
    method : {"greedy", "combined", "random"}
    batch : int, optional
        Picks per solve for ``"combined"`` (default 31, as in figure 6 of the
        paper); must be None for the other methods.
    weights : float
        Positive weight of every soft control point while selecting.
    seed : int or numpy.random.Generator, optional
        Random state of ``"random"``; the other methods are deterministic.
    progress : bool
        Show a tqdm bar over the control points, ending at ``count``: it
        starts at the per-component seeds and shows the first factorization
        as its ``factor`` stage. ``"random"`` shows none (instant).

    Returns
    -------
    indices : (count,) int64
        Vertex indices in selection order, without repetition.

    Raises
    ------
    ValueError
        ``count`` outside ``[components, n]``, unknown ``method``, ``batch`` not
        positive or given for a method other than ``"combined"``, non-positive
        ``weights``, negative ``seed``, or an invalid mesh.
    TypeError
        ``count``, ``batch``, ``weights``, ``seed`` or ``progress`` of the wrong type.

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> select_control_points(box, 8, method="greedy").shape
    (8,)
    >>> a = select_control_points(box, 5, method="random", seed=1)
    >>> bool((a == select_control_points(box, 5, method="random", seed=1)).all())
    True
    """
    data = read_mesh(mesh, weld=True)
    V, F = data.vertices, data.triangles
    indices, _ = control_point_selection(
        V, F, count, method=method, batch=batch, weights=weights, seed=seed, progress=progress
    )
    return data.source_indices(indices)


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
    """Approximate ``mesh`` by the LS mesh of ``count`` selected control points.

    Selects the control points with :func:`select_control_points` and returns
    the LS mesh (eq. 3 of Least-squares Meshes, weights of section 6) through
    them at their original positions; ``interpolate=True`` gives the
    interpolatory scheme (geometry-aware bases II.B) instead. For the greedy and
    combined methods without ``interpolate`` the factor kept by the selection
    already holds every control point, so the result costs one more
    back-substitution.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Split vertices are welded as in :func:`select_control_points`; the
        result has the mesh's own layout, each copy at its vertex's position.
    count, method, weights, batch, seed, progress
        See :func:`select_control_points`. When the result needs a new
        factorization (``interpolate`` or ``"random"``), ``progress`` also
        shows its stages (factor, solve).
    interpolate : bool
        Hit the control points exactly.

    Returns
    -------
    approximation : TriangleMesh
        Same kind, triangles and colors as ``mesh``.
    indices : (count,) int64
        The control points in selection order.

    Raises
    ------
    ValueError, TypeError
        As :func:`select_control_points`.

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> torus = o3d.geometry.TriangleMesh.create_torus()
    >>> approx, idx = approximate(torus, 60)
    >>> np.asarray(approx.vertices).shape == np.asarray(torus.vertices).shape
    True
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
    with stages(progress, "ls_mesh", ("factor", "solve")) as begin:
        begin("factor")
        system = LSMeshSystem(
            V, F, indices, weights=weights, interpolate=bool(interpolate), progress=progress
        )
        begin("solve")
        vertices = system.solve()
    return new_mesh(data, vertices), data.source_indices(indices)
