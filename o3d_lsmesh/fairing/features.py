"""Feature-preserving denoising (``method="features"``): guided normal filtering alternated with Sun's update.

Each pass filters the face normals once (Zhang et al. 2015, guided; ``guided=False``:
Zheng et al. 2011, bilateral) and takes ``VERTEX_STEPS`` of Sun et al. 2007's vertex update
towards the planes of the faces. The passes stop when the filtered normals stop concentrating
(:meth:`FeatureRun.concentrated`), at most ``MAX_PASSES``; where they stop before the cap, at pass k (a
curved surface), the result is the scan energy's followed by k // 2 bilateral passes
(:meth:`FeatureRun.finish`). All weights are dimensionless. Docs page: ``docs/algorithms/features.rst``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from .._o3d import read_mesh
from ..core.arrays import face_normals, kernel_index
from ..core.connectivity import Connectivity, FaceAdjacency
from ..core.errors import InputError
from ..core.progress import Progress
from ..core.validate import as_iterations, as_positive_float, mesh_arrays
from .scan_fairing import relax_rim, scan_denoise
from .scan_measure import measured_noise
from .tuning import (
    CONCENTRATION,
    CREASE_ANGLE,
    MAX_PASSES,
    SIGMA_R,
    VERTEX_STEPS,
)

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = [
    "FeatureRun",
    "detect_creases",
    "detect_creases_arrays",
    "feature_denoise",
    "filter_pass",
    "median_angle",
    "normal_steps",
]


def _unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.maximum(np.linalg.norm(vectors, axis=1, keepdims=True), np.finfo(float).tiny)


def _patch_edges(adjacency: FaceAdjacency) -> sp.csr_matrix:
    """``(m, p)`` pattern: the edge-adjacent pairs with both faces in each face's patch (its ring), in the
    ring's order of their first faces (:func:`.patch_pairs`)."""
    from .._feature_kernel import patch_pairs  # compiled by the package's build

    m, p, ring = adjacency.ring.shape[0], len(adjacency.pairs), adjacency.ring
    first = sp.csr_matrix((np.ones(p), (adjacency.pairs[:, 0], np.arange(p))), shape=(m, p))
    index = ring.indices.dtype  # one index type in the compiled loop
    second = np.ascontiguousarray(adjacency.pairs[:, 1], dtype=np.int64)
    parts = (first.indptr.astype(index), first.indices.astype(index), second)
    indptr, pairs = patch_pairs(ring.indptr, ring.indices, *parts)
    # only the pattern is read: one byte a value
    return sp.csr_matrix((np.ones(len(pairs), dtype=np.int8), pairs, indptr), shape=(m, p))


def _guidance(normals, area, adjacency, patch_edges):
    """Zhang et al.'s guidance: the mean normal of the most consistent patch (least ``H = D R``, docs
    page) containing each face."""
    from .._block_kernel import block_product  # compiled by the package's build
    from .._feature_kernel import least_dot, pair_jumps, patch_saliency, ring_least

    ring, pairs = adjacency.ring, adjacency.pairs
    if patch_edges.shape != (len(normals), len(pairs)):  # the compiled loop reads jump at its columns
        expected = f"_patch_edges(adjacency) of shape {(len(normals), len(pairs))}"
        raise InputError(
            f"patch_edges must be {expected}, got shape {patch_edges.shape}", param="patch_edges"
        )
    jump = pair_jumps(np.ascontiguousarray(pairs, dtype=np.int64), normals)  # |n_a - n_b| per pair
    saliency = patch_saliency(patch_edges.indptr, patch_edges.indices, jump)
    mean = np.empty((len(normals), 3))
    block_product(ring.indptr, ring.indices, ring.data, area[:, None] * normals, mean)
    mean = _unit(mean)
    # |n_j - m_i|^2 = 2 - 2 n_j . m_i for unit normals: the largest deviation is the least dot product
    least = least_dot(ring.indptr, ring.indices, mean, normals)
    score = np.sqrt(np.maximum(2.0 - 2.0 * least, 0.0)) * saliency
    # per face, the first patch of least score among those containing it (the ring is symmetric)
    return mean[ring_least(ring.indptr, ring.indices, score)]


def filter_pass(
    vertices: np.ndarray,
    triangles: np.ndarray,
    adjacency: FaceAdjacency,
    patch_edges: sp.csr_matrix | None,
    *,
    sigma_r: float = SIGMA_R,
    guided: bool = True,
) -> np.ndarray:
    """One pass of the guided (``guided=False``: bilateral) normal filter over the face normals, ``(m, 3)``:
    ``n_i <- normalize(sum_j a_j K_s(|c_i - c_j|) K_r(|g_i - g_j|) n_j)`` (docs page)."""
    from .._block_kernel import triangle_normals  # compiled by the package's build
    from .._feature_kernel import filtered_normals, ring_spacing

    # the normals, areas and centroids (the incidence's (a + b + c) / 3) in one pass over the triangles
    normals, area, centroid = triangle_normals(
        np.ascontiguousarray(vertices, dtype=np.float64), kernel_index(triangles, 3), True
    )
    ring = adjacency.ring
    # the mean distance between distinct faces of a ring: each row holds its own face once, at distance 0
    others = len(ring.indices) - len(triangles)
    spacing = ring_spacing(ring.indptr, ring.indices, centroid) / others if others else 1.0
    guide = _guidance(normals, area, adjacency, patch_edges) if guided else normals
    # each ring entry's weight exp((g_i . g_j - 1) / sigma_r^2 - |c_i - c_j|^2 / (2 spacing^2)) a_j in
    # registers, summed into its row at once: no array with one value per entry (fresh memory faults)
    out = np.empty((len(triangles), 3))
    space = 2.0 * max(spacing, np.finfo(float).tiny) ** 2
    filtered_normals(ring.indptr, ring.indices, centroid, guide, area, normals, sigma_r**2, space, out)
    return _unit(out)


def normal_steps(
    vertices: np.ndarray,
    triangles: np.ndarray,
    normals: np.ndarray,
    *,
    incidence: sp.csr_matrix,
    iterations: int = VERTEX_STEPS,
    grouping: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Sun et al. 2007's vertex update, ``(n, 3)``: ``iterations`` steps of
    ``x_i += 1/|F_i| sum_(f in F_i) n_f (n_f . (c_f - x_i))`` (per-vertex ``3 x 3`` sums formed once;
    ``incidence`` the face adjacency's triangle-vertex incidence). ``grouping``: :func:`_vertex_grouping`
    of ``incidence``, when the caller keeps it across passes."""
    from .._feature_kernel import plane_steps  # compiled by the package's build

    corners, indptr, faces = _vertex_grouping(incidence) if grouping is None else grouping
    x = np.array(vertices, dtype=np.float64, order="C")
    plane_steps(corners, indptr, faces, np.ascontiguousarray(normals), x, iterations)
    return x


def _vertex_grouping(incidence: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(corners (3m,), indptr (n + 1,), faces (3m,))``, one index dtype: the faces' vertices and each
    vertex's faces, increasing (the order in which the transposed product summed them), the incidence's CSC."""
    by_vertex = incidence.tocsc()
    corners = incidence.indices.astype(by_vertex.indices.dtype, copy=False)
    return corners, by_vertex.indptr.astype(by_vertex.indices.dtype, copy=False), by_vertex.indices


def median_angle(normals: np.ndarray, pairs: np.ndarray) -> float:
    """Median angle (radians) between the unit ``normals[pairs[:, 0]]`` and ``normals[pairs[:, 1]]``; 0
    without pairs. ``np.median`` of the angles, taken as the angles of the middle cosines (the arc cosine
    is decreasing): two arc cosines a pass, not one a pair.

    >>> median_angle(np.array([[0.0, 0, 1], [0, 0, 1], [0, 1, 0]]), np.array([[0, 1], [1, 2], [0, 2]]))
    1.5707963267948966
    """
    cosine = pair_cosines(normals, pairs)
    if not len(cosine):
        return 0.0
    middle = [(len(cosine) - 1) // 2, len(cosine) // 2]  # one index twice for an odd count
    return float(np.arccos(np.clip(np.partition(cosine, middle)[middle], -1.0, 1.0)).mean())


def pair_cosines(normals: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """``normals[a] . normals[b]`` of each pair ``(a, b)`` of ``pairs`` ``(p, 2)``, ``(p,)``: the cosines of
    the dihedral angles the stop and the crease test read."""
    return np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])


class FeatureRun:
    """The feature mode's passes on one mesh, taken one at a time (:meth:`step`); :meth:`finish` takes the
    rest and reads the result. ``feature_denoise`` takes them all; ``method="auto"`` takes them to the
    measured stop (:meth:`reaches_cap`) and goes on where it came at the cap. ``scan_start``: ``vertices``
    are the scan energy's result, the passes are bilateral (no guidance: the surface is curved) and
    :meth:`finish` does not switch."""

    def __init__(
        self, vertices: np.ndarray, triangles: np.ndarray, conn: Connectivity, *, scan_start: bool = False
    ) -> None:
        self.vertices, self.triangles, self.conn = vertices, triangles, conn
        self.adjacency = conn.face_adjacency
        self.scan_start = scan_start
        # the guidance's patches: only the guided passes read them
        self.patch_edges = None if scan_start else _patch_edges(self.adjacency)
        # the vertex steps' grouping of the faces depends on the connectivity alone: formed once
        self.grouping = _vertex_grouping(self.adjacency.incidence)
        # about the centroid: the planes' offsets n_f . c_f do not carry the distance to the origin
        self.used = np.bincount(triangles.ravel(), minlength=len(vertices)) > 0
        self.centre = vertices[self.used].mean(axis=0) if self.used.any() else np.zeros(3)
        self.x = vertices - self.centre
        self.medians: list[float] = []  # the median filtered dihedral angle of each pass
        self.stop_pass = 0  # the pass where the measured count ended (0: not yet)

    def step(self) -> np.ndarray:
        """One pass: the filtered face normals ``(m, 3)``, then the vertex steps towards their planes."""
        guided = not self.scan_start
        normals = filter_pass(self.x, self.triangles, self.adjacency, self.patch_edges, guided=guided)
        incidence = self.adjacency.incidence
        self.x = normal_steps(self.x, self.triangles, normals, incidence=incidence, grouping=self.grouping)
        self.medians.append(median_angle(normals, self.adjacency.pairs))
        if not self.stop_pass and (self.concentrated() or len(self.medians) >= MAX_PASSES):
            self.stop_pass = len(self.medians)
        return normals

    def reaches_cap(self, progress: bool = False) -> bool:
        """Take passes to the measured stop; whether it came at ``MAX_PASSES``: the filtered normals kept
        concentrating, as on flat pieces cut by creases (``method="auto"``'s choice, docs page)."""
        if not self.stop_pass:
            # the count is measured as the passes go: where the stop comes first the bar ends at the cap
            bar = Progress(progress, "feature passes").bar(MAX_PASSES, unit="pass", initial=len(self.medians))
            with bar:
                while not self.stop_pass:
                    self.step()
                    bar.update(1)
                bar.set_postfix_str(f"stopped at pass {self.stop_pass}")
                bar.update(MAX_PASSES - self.stop_pass)
        return self.stop_pass == MAX_PASSES

    def concentrated(self) -> bool:
        """Whether the filtered normals stopped concentrating after pass ``k``: the median dihedral angle
        is above ``CONCENTRATION`` times pass ``k // 2``'s. On piecewise-flat (CAD) surfaces it keeps falling
        like a power of ``k``; on curved ones it levels off at the surface's own angles, and the passes after
        that flatten the surface (docs page)."""
        k = len(self.medians)
        return k >= 2 and self.medians[-1] > CONCENTRATION * self.medians[k // 2 - 1]

    def finish(self, passes: int | None = None, progress: bool = False, solver: str = "auto") -> np.ndarray:
        """``passes`` more passes (``None``: until the measured stop), then the positions ``(n, 3)``;
        unreferenced vertices exactly where they were.

        With the measured stop before ``MAX_PASSES`` (a curved surface), the positions are instead
        :func:`.scan_denoise`'s result (solved by ``solver``) followed by ``stop_pass // 2`` passes of a
        ``scan_start`` run.
        Slivers at a rim then give back their drift (:func:`.relax_rim` with ``strength=0``)."""
        measured = passes is None
        if passes is None:
            self.reaches_cap(progress)
        else:
            for _ in Progress(progress, "constrained fairing (features)").over(range(passes)):
                self.step()
        if measured and not self.scan_start and self.stop_pass < MAX_PASSES:
            # the guided passes flatten a curved surface into facets before the noise is gone; the scan
            # energy removes it without facets, and bilateral passes from there (the guidance's patches
            # assume flat pieces) sharpen what creases it has: as many as concentrated the normals here,
            # the stop's k // 2 (docs page). The stop from the noisy mesh decides: CAD meshes reach the cap.
            start = scan_denoise(
                self.vertices, self.triangles, solver=solver, progress=progress, conn=self.conn
            )
            again = FeatureRun(start, self.triangles, self.conn, scan_start=True)
            x = again.finish(self.stop_pass // 2, progress)
        else:
            x = self.x + self.centre
        if not self.scan_start:  # the outer run only: the inner one's result comes back here
            # the vertex steps leave slivers at a scan's rim, where a triangle has a free side; their corners
            # give back their tangential drift as in the scan default, with its rim sweeps off (strength 0)
            x = relax_rim(self.vertices, x, self.triangles, strength=0.0, conn=self.conn)
        x[~self.used] = self.vertices[~self.used]
        return x


def feature_denoise(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    passes: int | None = None,
    progress: bool = False,
    conn: Connectivity | None = None,
    run: FeatureRun | None = None,
    solver: str = "auto",
) -> np.ndarray:
    """The feature mode on validated arrays: new ``(n, 3) float64`` positions.

    ``passes`` filter passes (``None``: until the filtered normals stop concentrating,
    :meth:`FeatureRun.concentrated`, at most :data:`MAX_PASSES`, from the scan energy's result where that
    stop comes before the cap, :meth:`FeatureRun.finish`; none on a mesh without measured noise), each
    followed by :data:`VERTEX_STEPS` vertex steps (:func:`filter_pass`, :func:`normal_steps`);
    ``conn``: the mesh's connectivity when the caller has it; ``run``: its passes begun on ``vertices``;
    ``solver``: how the scan energy's start is solved (:class:`~o3d_lsmesh.SPDSolver`).

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box().subdivide_midpoint(number_of_iterations=3)
    >>> V, F = np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)
    >>> feature_denoise(V + np.random.default_rng(0).normal(0.0, 0.01, V.shape), F).shape
    (386, 3)
    """
    conn = Connectivity(triangles, len(vertices)) if conn is None else conn
    if passes == 0 or (passes is None and measured_noise(vertices, triangles, conn=conn).noise == 0.0):
        return np.array(vertices, dtype=np.float64)
    return (run or FeatureRun(vertices, triangles, conn)).finish(passes, progress, solver)


def detect_creases_arrays(
    vertices: np.ndarray, triangles: np.ndarray, *, angle: float = CREASE_ANGLE, passes: int | None = None
) -> np.ndarray:
    """Crease edges of a mesh as vertex-index pairs, ``(k, 2) int64`` (``lo < hi``, sorted rows).

    The mesh is denoised first (:func:`feature_denoise`, ``passes`` as there); an edge
    is a crease when two of its faces' normals differ by more than ``angle`` degrees
    (an edge of more than two faces: two consecutive ones in its grouping).

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> V, F = np.asarray(box.vertices), np.asarray(box.triangles)
    >>> len(detect_creases_arrays(V, F))  # the 12 edges of the cube (its face diagonals are flat)
    12
    """
    angle = _angle(angle)
    vertices, triangles = mesh_arrays(vertices, triangles)
    return _creases(vertices, triangles, angle, passes)


def _angle(angle: object) -> float:
    angle = as_positive_float(angle, name="angle")
    if angle >= 180.0:
        raise InputError(f"angle must be below 180 degrees, got {angle}", param="angle")
    return angle


def _creases(vertices: np.ndarray, triangles: np.ndarray, angle: float, passes: object) -> np.ndarray:
    # checked arrays and angle in, the crease edges out
    passes = None if passes is None else as_iterations(passes, name="passes")
    conn = Connectivity(triangles, len(vertices))
    normals = face_normals(feature_denoise(vertices, triangles, passes=passes, conn=conn), triangles)[0]
    adjacency = conn.face_adjacency
    pairs = adjacency.pairs
    # a face without area has no normal (zero here): no fold against it
    folded = (pair_cosines(normals, pairs) < np.cos(np.radians(angle))) & (normals[pairs] != 0).any(
        axis=2
    ).all(axis=1)
    sharp = np.unique(adjacency.pair_edge[folded])
    return adjacency.edges[sharp].astype(np.int64)


def detect_creases(mesh: MeshT, *, angle: float = CREASE_ANGLE, passes: int | None = None) -> np.ndarray:
    """Crease edges of a mesh, ``(k, 2) int64``: each row the two vertex indices of one edge.

    Where ``constrained_fairing(mesh, method="features")`` folds by more than ``angle`` degrees.
    Vertices at equal positions are welded first; an edge names the first copy of each vertex.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    angle : float
        Dihedral threshold in degrees, in ``(0, 180)``.
    passes : int or None
        Filter passes of the denoiser (``None``: measured from the noise).

    Returns
    -------
    (k, 2) int64 ndarray
        Vertex-index pairs, ``lo < hi`` in the welded layout, rows sorted.

    Raises
    ------
    TypeError
        ``mesh`` not a mesh; ``angle`` not a number; ``passes`` not an integer.
    ValueError
        ``angle`` outside ``(0, 180)``; ``passes < 0``; an invalid mesh.

    Examples
    --------
    >>> import open3d as o3d
    >>> detect_creases(o3d.geometry.TriangleMesh.create_box()).shape
    (12, 2)
    """
    data = read_mesh(mesh, weld=True)
    edges = _creases(data.vertices, data.triangles, _angle(angle), passes)
    return data.source_indices(edges.ravel()).reshape(-1, 2)
