"""The mesh hierarchy of Liu et al. 2001 (section 4): levels, fine-to-coarse maps, vertex splits.

Level ``0`` is the input; level ``i`` is level ``i - 1`` after one batch of half-edge collapses (section
4.1, the compiled loop of ``collapse.pyx``), so every vertex of a level sits at its input position;
:meth:`MeshHierarchy.refine` splits vertices back in by Kobbelt's step (section 4.2).
Docs: ``docs/algorithms/mesh_hierarchy.rst``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from .._o3d import new_mesh, read_mesh, template, tensor_format_of, warn_dropped_attributes
from ..core.connectivity import Connectivity, VertexRings
from ..core.operators import single_slots, umbrella_weights
from ..core.progress import Progress
from ..core.solve import solve_spd
from ..core.validate import as_bool, as_count, as_positions, as_positive_float, mesh_arrays

if TYPE_CHECKING:
    from .._types import AnyMesh

__all__ = ["MeshHierarchy", "build_hierarchy", "build_hierarchy_arrays"]

# Tuned constants of the volume-cost collapses (section 4.1), passed to the compiled loop; the levels'
# topology, volume, distances and time they give: benchmarks/results/hierarchy.md.
ALPHA = 1.0  # weight of the shortest incident edge in the cost: hierarchy.md, per-level cross-check
BETA = 0.01  # weight of the longest incident edge in the cost: hierarchy.md, per-level cross-check
MAX_NORMAL_ANGLE = 60.0  # degrees a surviving triangle may turn: hierarchy.md, per-level cross-check
MIN_QUALITY = 1e-3  # least 2 area / sum of squared edges after a move: hierarchy.md, per-level cross-check
MAX_TRIES = 3  # targets tried per vertex, least volume first: hierarchy.md, whole-hierarchy speed table
FILL_TIE = 1e-9  # split vertices' tie to their placeholders in the harmonic fill: a regularization, not tuned


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(map(_same, a, b))
    return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) else bool(a == b)


def _frozen(array: np.ndarray) -> np.ndarray:
    # a read-only view: the caller's own array (the input of build_hierarchy_arrays) stays writeable
    view = np.ascontiguousarray(array).view()
    view.flags.writeable = False
    return view


@dataclass(frozen=True, eq=False)
class MeshHierarchy:
    """Levels ``M_0, M_1, ..., M_L`` of decreasing size with the collapses between them (read-only arrays).

    Attributes
    ----------
    vertices : (n_0, 3) float64
        Input positions.
    triangles, representatives : tuple of (m_i, 3) and (n_i,) int64
        Each level's triangles (its own indices) and the input index of each of its vertices.
    parents : tuple of (n_{i-1},) int64
        ``parents[i]`` maps level ``i - 1`` vertices to level ``i`` (``parents[0]`` is empty).
    removed, targets, ring_offsets, rings : tuple of int64 arrays
        Per level, in level ``i - 1`` indices: the removed vertices, their targets, their CSR 1-rings.
    independent : bool
        Whether every level's removed vertices are pairwise non-adjacent (:func:`build_hierarchy`).
    method, mesh_kind : str
        ``"volume"`` or ``"fast_simplification"``; the kind :meth:`level` returns.
    tensor_format : tuple of str
        ``(device, position dtype, index dtype)`` of a tensor input, else empty.
    """

    vertices: np.ndarray
    triangles: tuple
    representatives: tuple
    parents: tuple
    removed: tuple
    targets: tuple
    ring_offsets: tuple
    rings: tuple
    independent: bool
    method: str
    mesh_kind: str
    tensor_format: tuple = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertices", _frozen(self.vertices))
        for name in [f.name for f in fields(self)][1:8]:  # the tuples of arrays
            object.__setattr__(self, name, tuple(_frozen(a) for a in getattr(self, name)))

    def __setstate__(self, state: dict) -> None:
        # pickle restores the arrays writeable: freeze them again, as construction does
        self.__dict__.update(state)
        self.__post_init__()

    def __len__(self) -> int:
        return len(self.triangles)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MeshHierarchy):
            return NotImplemented
        return all(_same(getattr(self, f.name), getattr(other, f.name)) for f in fields(self))

    __hash__ = None  # type: ignore[assignment]

    def _check_level(self, i: Any, *, minimum: int = 0) -> int:
        return as_count(i, name="i", minimum=minimum, maximum=len(self) - 1)

    def vertex_count(self, i: int) -> int:
        """Number of vertices of level ``i``."""
        return len(self.representatives[self._check_level(i)])

    def level_arrays(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices (n_i, 3) float64, triangles (m_i, 3) int64)`` of level ``i`` (copies)."""
        i = self._check_level(i)
        return self.vertices[self.representatives[i]], self.triangles[i].copy()

    def level(self, i: int) -> AnyMesh:
        """Level ``i`` as a mesh of the input's kind; positions are the input positions of its vertices."""
        vertices, triangles = self.level_arrays(i)
        return new_mesh(template(self.mesh_kind, self.tensor_format), vertices, triangles)

    def vertex_map(self, i: int) -> np.ndarray:
        """``(n_0,) int64``: the level-``i`` vertex that represents each input vertex."""
        i = self._check_level(i)
        mapping = np.arange(len(self.vertices), dtype=np.int64)
        for j in range(1, i + 1):
            mapping = self.parents[j][mapping]
        return mapping

    def collapses(self, i: int) -> dict[str, np.ndarray]:
        """Collapse records of level ``i >= 1`` in level ``i - 1`` indices: ``removed (r,)``, ``targets (r,)``,
        ``ring_offsets (r + 1,)``, ``ring`` (``removed[j]``'s 1-ring is ``ring[ring_offsets[j]:ring_offsets[j + 1]]``)."""
        i = self._check_level(i, minimum=1)
        return {
            "removed": self.removed[i],
            "targets": self.targets[i],
            "ring_offsets": self.ring_offsets[i],
            "ring": self.rings[i],
        }

    def refine(self, i: int, positions: Any) -> np.ndarray:
        """Positions ``(n_{i-1}, 3)`` of level ``i - 1`` from ``positions (n_i, 3)`` of level ``i >= 1``: split
        vertices at their 1-ring average, then one Kobbelt step (``docs/algorithms/mesh_hierarchy.rst``)."""
        i = self._check_level(i, minimum=1)
        positions = as_positions(positions, len(self.representatives[i]), name="positions")
        return self.refine_with_rings(
            i, positions, Connectivity(self.triangles[i - 1], len(self.parents[i])).rings
        )

    def refine_with_rings(self, i: int, positions: np.ndarray, rings: VertexRings) -> np.ndarray:
        """:meth:`refine` of checked positions with the :class:`~o3d_lsmesh.core.connectivity.VertexRings` of
        level ``i - 1`` (which multiresolution fairing reuses)."""
        out = positions[self.parents[i]]
        removed = self.removed[i]
        if len(removed) == 0:
            return out
        weights, scale, on_boundary = umbrella_weights(rings)
        rows = weights[removed]  # the split vertices' rows
        if self.independent:  # their neighbours are all kept
            out[removed] = rows @ out
        else:
            out[removed] = _harmonic_fill(weights, out, removed, on_boundary)
        umbrella = weights @ out
        umbrella -= out
        second = rows @ umbrella
        second -= umbrella[removed]
        # nu - 1 = sum_j w_ij w_ji with w_ji = scale_j where it is not zero: inside, the 1-ring's interior
        # vertices (a boundary vertex reads the curve only); on a boundary, the curve's two vertices
        if on_boundary is None:
            nu = rows @ scale
        else:
            nu = np.where(on_boundary[removed], rows @ scale, rows @ np.where(on_boundary, 0.0, scale))
        nu += 1.0
        out[removed] -= second / nu[:, None]
        return out


def boundary_degree(rings: VertexRings) -> np.ndarray:
    """``(n,) int64``: the edges of one triangle at every vertex (0 inside, 2 on a simple boundary)."""
    if not rings.boundary.any():  # no edge of one triangle (nor of more)
        return np.zeros(rings.n, dtype=np.int64)
    return np.add.reduceat(single_slots(rings), rings.indptr[:-1], dtype=np.int64)


def _harmonic_fill(
    weights: sp.csr_matrix, out: np.ndarray, removed: np.ndarray, on_boundary: np.ndarray | None
) -> np.ndarray:
    """Positions of ``removed`` equal to the ``weights`` average of their neighbours, the others fixed (the
    docs page's harmonic fill: boundary rows first, two SPD solves)."""
    x = out.copy()
    groups = (
        [removed] if on_boundary is None else [removed[on_boundary[removed]], removed[~on_boundary[removed]]]
    )
    for rows in groups:
        if len(rows) == 0:
            continue
        pattern = weights[rows]
        pattern.data = (pattern.data != 0).astype(np.float64)
        pattern.eliminate_zeros()
        degree = np.diff(pattern.indptr).astype(np.float64)
        degree[degree == 0] = 1.0  # (a vertex without neighbours keeps its placeholder, scaled as before)
        inside = np.zeros(len(x), dtype=bool)
        inside[rows] = True
        system = sp.diags(degree * (1.0 + FILL_TIE)) - pattern[:, rows]
        rhs = pattern[:, np.flatnonzero(~inside)] @ x[~inside] + (FILL_TIE * degree)[:, None] * x[rows]
        x[rows] = solve_spd(system.tocsc(), rhs)
    return x[removed]


def _warn_workers(workers: Any) -> None:
    if workers is not None:
        warnings.warn(
            "workers is deprecated and ignored: the hierarchy is built by one compiled sequential loop, "
            "which threads did not speed up; drop the argument",
            FutureWarning,
            stacklevel=3,
        )


def _options(alpha: Any, beta: Any, min_vertices: Any, max_levels: Any, progress: Any) -> dict[str, Any]:
    # the one check of build_hierarchy's options
    return dict(
        alpha=as_positive_float(alpha, name="alpha", allow_zero=True),
        beta=as_positive_float(beta, name="beta", allow_zero=True),
        min_vertices=as_count(min_vertices, name="min_vertices"),
        max_levels=None if max_levels is None else as_count(max_levels, name="max_levels"),
        progress=as_bool(progress, name="progress"),
    )


def build_hierarchy_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float = ALPHA,
    beta: float = BETA,
    min_vertices: int = 100,
    max_levels: int | None = None,
    progress: bool = False,
    workers: int | None = None,
) -> MeshHierarchy:
    """Array core of :func:`build_hierarchy` on ``(n, 3)`` vertices and ``(m, 3)`` triangles (checked and copied)."""
    _warn_workers(workers)
    options = _options(alpha, beta, min_vertices, max_levels, progress)
    return collapse_hierarchy(*mesh_arrays(vertices, triangles), **options)


def collapse_hierarchy(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float,
    beta: float,
    min_vertices: int,
    max_levels: int | None,
    progress: bool,
    mesh_kind: str = "arrays",
    tensor_format: tuple = (),
) -> MeshHierarchy:
    """:func:`build_hierarchy_arrays` of checked arrays and options (the arrays are kept)."""
    n0 = len(vertices)
    total = max(n0 - min_vertices, 0)  # at most: a level may find no valid collapse before
    with Progress(progress, "mesh hierarchy").bar(total, unit="vertex") as bar:
        from .collapse import collapse_levels

        tuned: dict[str, Any] = dict(
            alpha=alpha, beta=beta, max_normal_angle=MAX_NORMAL_ANGLE, max_tries=MAX_TRIES
        )
        tuned.update(
            min_quality=MIN_QUALITY, min_vertices=min_vertices, max_levels=max_levels, report=bar.update
        )
        _, levels = collapse_levels(vertices, triangles, **tuned)
        bar.update(total - bar.n)  # done: the bar ends at its total
    empty, no_ring = np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64)
    first = (empty, empty, no_ring, empty, empty, triangles, np.arange(n0, dtype=np.int64))  # level 0
    removed, targets, offsets, rings, parents, tris, reps = zip(first, *levels)
    records = (removed, targets, offsets, rings)
    return MeshHierarchy(vertices, tris, reps, parents, *records, True, "volume", mesh_kind, tensor_format)


def build_hierarchy(
    mesh: AnyMesh,
    *,
    alpha: float = ALPHA,
    beta: float = BETA,
    min_vertices: int = 100,
    max_levels: int | None = None,
    progress: bool = False,
    workers: int | None = None,
) -> MeshHierarchy:
    """Build the multiresolution hierarchy of Liu et al. 2001, section 4.1, by volume-cost half-edge collapses.

    Each level removes an independent set of vertices, each into its neighbour of least cone volume,
    keeping the topology; levels hold positions and triangles only (other attributes dropped with one
    warning). Rules: ``docs/algorithms/mesh_hierarchy.rst``.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    alpha, beta : float, keyword-only
        Non-negative weights of the shortest and longest incident edge in the cost.
    min_vertices, max_levels, progress, workers : keyword-only
        Stop at this many vertices or after this many levels; a progress bar; ``workers`` is deprecated
        and ignored (a ``FutureWarning``).

    Raises
    ------
    InputError
        Invalid mesh arrays or options (``InputTypeError`` for a wrong type).

    Examples
    --------
    >>> import open3d as o3d
    >>> h = build_hierarchy(o3d.geometry.TriangleMesh.create_sphere(resolution=20), min_vertices=50)
    >>> h.vertex_count(0), h.refine(1, h.level_arrays(1)[0]).shape
    (762, (762, 3))
    """
    _warn_workers(workers)
    data = read_mesh(mesh)  # any mesh: non-manifold, unreferenced vertices
    warn_dropped_attributes(data, "hierarchy levels have new connectivity", normals=True)
    options = _options(alpha, beta, min_vertices, max_levels, progress)
    return collapse_hierarchy(
        data.vertices, data.triangles, mesh_kind=data.kind, tensor_format=tensor_format_of(data), **options
    )
