"""Faired hole filling: Liepa's triangulate-refine-fair pipeline with least-squares-mesh fairing.

Each chosen hole is found (:mod:`.find`), triangulated and refined (:mod:`.triangulate`), faired
(:mod:`.fair`) and checked for crossings (:mod:`.crossings`); what still crosses is left open and
reported (:class:`FillReport`). P. Liepa, Filling Holes in Meshes, SGP 2003; O. Sorkine and D. Cohen-Or,
Least-squares Meshes, SMI 2004. See docs/algorithms/hole_filling.rst.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import new_mesh, read_mesh
from ..core.boundary import boundary_curves
from ..core.connectivity import Connectivity
from ..core.errors import InputError, warn
from ..core.validate import as_bool, as_choice, as_count, as_positive_float, mesh_arrays
from .crossings import _crossings, _TriangleIndex
from .fair import fair_patches
from .find import Hole, find_holes
from .triangulate import closable, triangulate_holes
from .tuning import DENSITY_MAX

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = ["FillReport", "FilledHoles", "HoleFiller", "HoleOutcome", "fill_holes", "fill_holes_arrays"]


@dataclass(frozen=True)
class HoleOutcome:
    """What :func:`fill_holes` did with one boundary loop.

    Attributes
    ----------
    id : int
        The loop's index in :func:`find_holes` (and :attr:`HoleFiller.holes`) of the input.
    edges : int
        Its number of boundary edges.
    diameter : float
        Largest distance between two of its vertices.
    filled : bool
        Whether it was closed.
    how : str
        How it was filled (``"continuity 2"`` ... ``"continuity 0"``, ``"refined, unfaired"``,
        ``"minimum-weight triangulation"``: each a simpler retry where the one before crossed the
        surface), or why it was left open.
    """

    id: int
    edges: int
    diameter: float
    filled: bool
    how: str


@dataclass(frozen=True)
class FillReport:
    """Every boundary loop :func:`fill_holes` filled or left open, and how or why
    (``fill_holes(..., return_report=True)``; :attr:`FilledHoles.report`).

    Attributes
    ----------
    holes : tuple of HoleOutcome
        One per loop, by id.
    stray_edges : int
        Boundary edges on no closed loop (a rim that runs into a fin or a repeated triangle): left open.

    Examples
    --------
    >>> pyramid = (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float),
    ...            np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]))
    >>> [(h.id, h.edges, h.filled, h.how) for h in fill_holes(pyramid, fill_border=True, return_report=True)[1].holes]
    [(0, 4, True, 'minimum-weight triangulation')]
    """

    holes: tuple[HoleOutcome, ...]
    stray_edges: int = 0

    @property
    def filled(self) -> list[HoleOutcome]:
        return [hole for hole in self.holes if hole.filled]

    @property
    def skipped(self) -> list[HoleOutcome]:
        return [hole for hole in self.holes if not hole.filled]

    def describe(self, limit: int | None = None) -> str:
        """The loops left open, one clause each (the first ``limit`` of them)."""
        left = self.skipped
        shown = "; ".join(
            f"loop {h.id} ({h.edges} edges, diameter {h.diameter:.4g}): {h.how}" for h in left[:limit]
        )
        shown += f"; and {len(left) - limit} more" if limit is not None and len(left) > limit else ""
        stray = f"{self.stray_edges} boundary edges on no closed loop (a fin or a repeated triangle at a rim)"
        return "; ".join(part for part in (shown, stray if self.stray_edges else "") if part)


@dataclass(frozen=True)
class FilledHoles:
    """The result of :func:`fill_holes_arrays`.

    Attributes
    ----------
    vertices : (n + p, 3) float64
        The input vertices, unchanged, then the ``p`` new ones.
    triangles : (m + q, 3) int64
        The input triangles, unchanged and in order, then the ``q`` new ones.
    holes : list of Hole
        The holes that were filled.
    skipped : list of Hole
        Loops left open (outer borders, beyond the size limits, or every fill crossing the mesh).
    continuity : (len(holes),) int64
        The continuity each hole was faired with: the asked one, or a lower one where the asked one
        made the patch cross the mesh (-1: left as refined, unfaired; -2: the minimum-weight
        triangulation alone, no new vertex).
    report : FillReport
        Every loop, filled or left open, and how or why.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    holes: list
    skipped: list
    continuity: np.ndarray
    report: FillReport


def fill_holes_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    max_hole_edges: int | None = None,
    max_hole_diameter: float | None = None,
    continuity: int = 2,
    density: float = 1.0,
    weights: str = "cotangent",
    fill_border: bool = False,
    progress: bool = False,
) -> FilledHoles:
    """Fill the holes of ``(vertices, triangles)``: the array core of :func:`fill_holes`.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64
    max_hole_edges, max_hole_diameter, continuity, density, weights, fill_border, progress
        As in :func:`fill_holes`.

    Returns
    -------
    FilledHoles

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float)
    >>> out = fill_holes_arrays(square, np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]), fill_border=True)
    >>> len(out.triangles), len(out.holes)
    (6, 1)
    """
    return HoleFiller(vertices, triangles, index_triangles=False).fill(
        max_hole_edges=max_hole_edges,
        max_hole_diameter=max_hole_diameter,
        continuity=continuity,
        density=density,
        weights=weights,
        fill_border=fill_border,
        progress=progress,
    )


class HoleFiller:
    """The whole-mesh analysis of a mesh's holes, done once; :meth:`fill` then does only per-hole work.

    Like CGAL's prebuilt half-edge structure: the loops (:func:`find_holes`), each vertex's mean edge
    length (Liepa's scale) and triangles, and grids of the triangles' bounding spheres (for the
    crossing check). The state is read-only: it pickles, and :meth:`fill` may run from several threads.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64
    index_triangles : bool, keyword-only
        Build the grids (they pay off over several fills); ``False`` makes each fill query only
        the triangles in the box of its new triangles, faster for a single fill.

    Attributes
    ----------
    holes : list of Hole
        Every boundary loop, as :func:`find_holes` gives them.

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float)
    >>> filler = HoleFiller(square, np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]))
    >>> [hole.edges for hole in filler.holes], len(filler.fill(fill_border=True).triangles)
    ([4], 6)
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, *, index_triangles: bool = True) -> None:
        index_triangles = bool(as_bool(index_triangles, name="index_triangles"))
        vertices, triangles = mesh_arrays(vertices, triangles)  # copies: the state must not change under it
        for array in (vertices, triangles):
            array.setflags(write=False)
        self._build(vertices, triangles, index_triangles)

    @classmethod
    def _from_valid(cls, vertices: np.ndarray, triangles: np.ndarray) -> HoleFiller:
        """A filler of arrays :func:`~o3d_lsmesh.core.validate.mesh_arrays` gave (no second check), for one fill."""
        filler = cls.__new__(cls)
        filler._build(vertices, triangles, False)
        return filler

    def _build(self, vertices: np.ndarray, triangles: np.ndarray, index_triangles: bool) -> None:
        n = len(vertices)
        self.vertices, self.triangles = vertices, triangles
        conn = Connectivity(triangles, n)  # the one whole-mesh grouping
        es = conn.edge_structure
        edges = es.edges.astype(np.int64)
        self.holes = find_holes(vertices, triangles, _conn=conn)
        # a rim that runs into a fin or a repeated triangle is on no closed loop: its edges (a lone fin's two
        # free edges are no hole)
        chains = boundary_curves(triangles, n, conn=conn).chains
        self.stray_edges = sum(len(chain) - 1 for chain in chains if len(chain) > 3)
        length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
        degree = np.maximum(np.bincount(edges.ravel(), minlength=n), 1)
        self.sigma = np.bincount(edges.ravel(), weights=np.repeat(length, 2), minlength=n) / degree
        self.vertex_triangles = tuple(a.astype(np.int64) for a in conn.vertex_triangles)
        self.index = _TriangleIndex(vertices, triangles) if index_triangles else None

    def fill(
        self,
        *,
        max_hole_edges: int | None = None,
        max_hole_diameter: float | None = None,
        continuity: int = 2,
        density: float = 1.0,
        weights: str = "cotangent",
        fill_border: bool = False,
        progress: bool = False,
    ) -> FilledHoles:
        """Fill the chosen holes: the options and result of :func:`fill_holes_arrays`."""
        if max_hole_edges is not None:
            max_hole_edges = as_count(max_hole_edges, name="max_hole_edges", minimum=3)
        if max_hole_diameter is not None:
            max_hole_diameter = as_positive_float(max_hole_diameter, name="max_hole_diameter")
        continuity = as_count(continuity, name="continuity", minimum=0, maximum=2)
        density = as_positive_float(density, name="density", allow_zero=True)
        if density > DENSITY_MAX:
            raise InputError(
                f"density must be at most {DENSITY_MAX:g} (DENSITY_MAX), got {density:g}", param="density"
            )
        weights = as_choice(weights, ("uniform", "cotangent"), name="weights")
        fill_border = bool(as_bool(fill_border, name="fill_border"))
        as_bool(progress, name="progress")
        m = len(self.triangles)
        holes: list[Hole] = []
        why: dict[int, str] = {}  # id(hole) -> why it is left open
        for hole in self.holes:
            # the three edges of one triangle are the rim of a flap (a triangle hanging by a vertex,
            # common in raw scans), not a hole: "filling" it would add that triangle's reverse
            if hole.edges == 3 and len(np.unique(np.asarray(hole.rows) % m)) == 1:
                why[id(hole)] = "the rim of one triangle hanging by a vertex (a flap, not a hole)"
            elif not closable(hole.vertices, self.vertices[hole.vertices]):
                why[id(hole)] = (
                    "a zero-width crack: the loop runs along coincident vertices (merge them to close it)"
                )
            elif max_hole_edges is not None and hole.edges > max_hole_edges:
                why[id(hole)] = f"more than max_hole_edges={max_hole_edges} edges"
            elif max_hole_diameter is not None and hole.diameter > max_hole_diameter:
                why[id(hole)] = f"wider than max_hole_diameter={max_hole_diameter:g}"
            elif hole.border and not fill_border:
                why[id(hole)] = "taken as the outer border of an open surface (fill_border=False)"
            else:
                holes.append(hole)
        # the crossing checks' grids: prebuilt, or built once here for several holes (a single one queries
        # the triangles in the box of its patch)
        index = self.index
        if index is None and len(holes) > 1:
            index = _TriangleIndex(self.vertices, self.triangles)
        cot = weights == "cotangent"
        vertices, triangles, filled, stuck, used, own = self._fill_pass(
            holes, continuity, density, cot, progress, index
        )
        if stuck and density > 0:
            # simpler forms: the bare minimum-weight triangulation (no new vertex), checked against the
            # mesh, the fills kept so far and each other; what still crosses is given up
            _, retry, retry_owner = triangulate_holes(self, stuck, 0.0, False)
            again = np.concatenate([triangles, retry])
            crossing = _crossings(vertices, again, m, index, np.concatenate([own, len(filled) + retry_owner]))
            bad = np.bincount(retry_owner, weights=crossing[len(own) :], minlength=len(stuck)) > 0
            triangles = np.concatenate([triangles, retry[~bad[retry_owner]]])
            filled = filled + [hole for hole, b in zip(stuck, bad) if not b]
            used = np.concatenate([used, np.full(int((~bad).sum()), -2, dtype=np.int64)])
            stuck = [hole for hole, b in zip(stuck, bad) if b]
        for hole in stuck:
            why[id(hole)] = "every fill crosses the surface (folded or overlapping triangles next to it)"
        # every loop is filled (at a continuity, FilledHoles.continuity) or left open (why)
        named = {-1: "refined, unfaired", -2: "minimum-weight triangulation"}
        how = {**why, **{id(hole): named.get(int(c), f"continuity {c}") for hole, c in zip(filled, used)}}
        report = FillReport(
            tuple(
                HoleOutcome(i, h.edges, h.diameter, id(h) not in why, how[id(h)])
                for i, h in enumerate(self.holes)
            ),
            self.stray_edges,
        )
        # said: every loop left open but those the size limits exclude and flaps (no holes)
        said = FillReport(
            tuple(h for h in report.skipped if h.how.startswith(("every", "taken", "a zero-width"))),
            self.stray_edges,
        )
        if said.holes or said.stray_edges:
            warn(
                f"fill_holes: {len(said.holes)} of {len(self.holes)} loops left open: {said.describe(10)}"
                " (every loop, filled or not: fill_holes(..., return_report=True), a FillReport)"
            )
        number = {id(hole): i for i, hole in enumerate(self.holes)}
        order = np.argsort([number[id(hole)] for hole in filled], kind="stable").astype(np.int64)
        skipped = [hole for hole in self.holes if id(hole) in why]
        return FilledHoles(vertices, triangles, [filled[i] for i in order], skipped, used[order], report)

    def _fill_pass(
        self,
        holes: list,
        continuity: int,
        density: float,
        cot: bool,
        progress: bool,
        index: Any,
    ) -> tuple:
        """Fill ``holes``: the vertices and triangles (the input's, then the new ones), the holes filled,
        those whose every fill crosses (left open), the continuity of each filled one and the filled
        hole (index in the list) of each new triangle.
        ``index``: the crossing checks' (:func:`_crossings`)."""
        n, m = len(self.vertices), len(self.triangles)
        if not holes:
            empty = np.zeros(0, dtype=np.int64)
            return self.vertices.copy(), self.triangles.copy(), [], [], empty, empty
        fresh_points, new_tris, owner = triangulate_holes(self, holes, density, progress)
        vertices = np.concatenate([self.vertices, fresh_points])
        triangles = np.concatenate([self.triangles, new_tris])
        vertex_owner = np.zeros(len(fresh_points), dtype=np.int64)  # the hole of each new vertex
        corners = new_tris.ravel()
        vertex_owner[corners[corners >= n] - n] = np.repeat(owner, 3)[corners >= n]
        # a new triangle on three loop vertices is the same in every candidate: one crossing the mesh (or
        # another such) makes its hole's every candidate cross, so that hole is not faired (a scan's
        # silhouette: a patch as large as the scan, faired five times over, to be left open). Tested with
        # those triangles first among the new ones, in place (no copy of the mesh), then put back
        fixed = (new_tris < n).all(axis=1)
        order, count = np.argsort(~fixed, kind="stable"), int(fixed.sum())
        triangles[m:] = new_tris[order]
        crossing = _crossings(vertices, triangles[: m + count], m, index, owner[order][:count])
        triangles[m:] = new_tris
        gone = np.bincount(owner[order][:count], weights=crossing, minlength=len(holes)) > 0
        kept = np.flatnonzero(~gone)
        if gone.any():  # the others faired without them (a candidate meeting a patch given up is no crossing)
            vertices, triangles, owner, vertex_owner = _without(
                gone, n, m, vertices, triangles, owner, vertex_owner
            )
        used = np.full(len(kept), -2, dtype=np.int64)  # no new vertex: the bare programme
        if len(vertex_owner):
            faired = [holes[i] for i in kept]
            used, stuck = fair_patches(
                self, vertices, triangles, faired, continuity, cot, owner, vertex_owner, index
            )
            used[np.bincount(vertex_owner, minlength=len(kept)) == 0] = -2
            if len(stuck):
                left = np.isin(np.arange(len(kept)), stuck)
                vertices, triangles, owner, _ = _without(left, n, m, vertices, triangles, owner, vertex_owner)
                gone[kept[left]] = True
                kept, used = kept[~left], used[~left]
        return (
            vertices,
            triangles,
            [holes[i] for i in kept],
            [hole for hole, out in zip(holes, gone) if out],
            used,
            owner,
        )


def _without(gone, n: int, m: int, vertices, triangles, owner, vertex_owner) -> tuple:
    """The vertices, triangles, each new triangle's hole and each new vertex's without the holes ``gone``
    (a mask over the holes; the input's ``n`` vertices and ``m`` triangles first), renumbered."""
    keep_vertex, keep_triangle, renumber = ~gone[vertex_owner], ~gone[owner], np.cumsum(~gone) - 1
    remap = np.concatenate([np.arange(n), n + np.cumsum(keep_vertex) - 1])
    return (
        np.concatenate([vertices[:n], vertices[n:][keep_vertex]]),
        np.concatenate([triangles[:m], remap[triangles[m:][keep_triangle]]]),
        renumber[owner[keep_triangle]],
        renumber[vertex_owner[keep_vertex]],
    )


def fill_holes(
    mesh: MeshT,
    *,
    max_hole_edges: int | None = None,
    max_hole_diameter: float | None = None,
    continuity: int = 2,
    density: float = 1.0,
    weights: str = "cotangent",
    fill_border: bool = False,
    progress: bool = False,
    return_report: bool = False,
) -> Any:
    """Close the mesh's holes with patches faired as least-squares meshes; a new mesh.

    Each chosen hole (a closed loop of boundary edges) is triangulated by Liepa's minimum-weight
    dynamic programme (largest dihedral angle, then area), refined to the density of the edges around
    it with Delaunay flips, and its new vertices are placed by minimizing, with the surrounding mesh
    fixed (Sorkine and Cohen-Or 2004, section 6, interpolated anchors):

    * ``continuity=0``: ``sum |x_i - x_j|^2`` over edges (harmonic, a membrane);
    * ``continuity=1``: ``||L x||^2``, the LS-mesh energy (eq. 3), bi-Laplacian;
    * ``continuity=2``: ``(L x)^T K (L x)``, tri-Laplacian: the Laplacian itself varies smoothly, so
      curvature continues across the loop,

    with ``L = I - D^-1 A`` (eq. 1) and ``K = D - A``, ``continuity + 1`` rings of the input fixed around
    each loop; ``weights="cotangent"`` then solves again with the cotangent weights of that solution.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Any triangle mesh: non-manifold edges and vertices, several components, pinched boundaries and
        holes touching at a vertex are handled (a loop through a vertex twice is filled in pieces).
    max_hole_edges : int >= 3, optional
        Fill only holes with at most this many boundary edges.
    max_hole_diameter : float > 0, optional
        Fill only holes whose diameter (largest distance between two loop vertices) is at most this.
    continuity : {0, 1, 2}
        Smoothness across the loop, see above. Default 2.
    density : float in [0, DENSITY_MAX]
        New vertices are spaced like the surrounding edges divided by ``density``; ``0`` adds none
        (the minimum-weight triangulation alone). The work is bounded: at most about what density 2
        adds to a patch of even scale, and no split at a corner of 64 triangles.
    weights : {"cotangent", "uniform"}
        ``"uniform"``: the uniform solve alone; ``"cotangent"``: then one re-weighted solve (see above).
    fill_border : bool
        Also fill each open component's outer border (see :data:`BORDER_FACING_AWAY`): a scan's silhouette,
        a lone island's rim. Default ``False``: left open.
    progress : bool
        Show a tqdm bar over the holes.
    return_report : bool
        Also return the :class:`FillReport`: every loop filled or left open, how or why.

    Returns
    -------
    Mesh of the kind given, or ``(mesh, FillReport)`` if ``return_report``
        The input's vertices and triangles unchanged and in order, then the new ones, wound like their
        neighbours; holes of the welded surface (a UV seam is not one); every attribute kept and
        extended to the new elements (the rules: docs/algorithms/hole_filling.rst).

    Raises
    ------
    InputTypeError
        ``mesh`` not a mesh; an option of the wrong type.
    InputError
        An empty or invalid mesh, an option out of range (``InputError.param`` names it).

    See Also
    --------
    fill_holes_arrays, HoleFiller, reconstruct_geometry

    Notes
    -----
    A patch that crosses the mesh is faired again with simpler settings, then filled by the bare
    triangulation; what still crosses is left open, and every loop left open is named in an
    :class:`O3DLSMeshWarning` (the rules: docs/algorithms/hole_filling.rst).

    References
    ----------
    P. Liepa, Filling Holes in Meshes, SGP 2003. O. Sorkine and D. Cohen-Or, Least-squares Meshes,
    SMI 2004.

    Examples
    --------
    >>> import open3d as o3d
    >>> holed = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    >>> holed.remove_triangles_by_index(list(range(30)))
    >>> fill_holes(holed).is_watertight()
    True
    """
    data = read_mesh(mesh, weld=True)  # the welded surface's holes: a UV seam is not one; validated once
    result = HoleFiller._from_valid(data.vertices, data.triangles).fill(
        max_hole_edges=max_hole_edges,
        max_hole_diameter=max_hole_diameter,
        continuity=continuity,
        density=density,
        weights=weights,
        fill_border=fill_border,
        progress=progress,
    )
    out = new_mesh(data, result.vertices, result.triangles if result.holes else None, appended=True)
    return (out, result.report) if as_bool(return_report, name="return_report") else out
