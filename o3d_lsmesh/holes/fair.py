"""Fairing the patches: the new vertices minimize a continuity-0/1/2 energy, the rings around them fixed.

O. Sorkine and D. Cohen-Or, Least-squares Meshes, SMI 2004, eq. 1, 3 and section 6; the choice among
candidates (a lower continuity where a patch crosses the mesh) is in docs/algorithms/hole_filling.rst.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..core import tuning as core_tuning
from ..core.arrays import concatenated_ranges, in_sorted
from ..core.errors import SingularSystemError
from ..core.operators import patch_system
from ..core.solve import solve_spd
from . import tuning
from .crossings import _crossings


def _fair(x: np.ndarray, tris: np.ndarray, unknown: np.ndarray, rings: list, level: int, cot: bool):
    """Positions ``(p, 3)`` of the ``unknown`` local vertices minimizing continuity ``level``'s energy
    (:func:`o3d_lsmesh.core.operators.patch_system`), the others fixed at ``x``. Solved by the gateway; a
    block whose system is not finite is left NaN.
    """
    dense = len(unknown) <= core_tuning.DENSE_UNKNOWNS
    # about the local mesh's centroid: the normal equations' round-off grows with the coordinates' size
    # (a mesh in world coordinates), not only with the patch's
    centre = x.mean(axis=0)  # the unknowns are rows of x: never empty
    normal, rhs = patch_system(x - centre, tris, unknown, rings, level, cotangent=cot, dense=dense)
    if dense and np.isfinite(normal).all() and np.isfinite(rhs).all():
        return solve_spd(normal, rhs) + centre
    # the blocks (patches, and patches sharing rings) with a non-finite entry are left NaN, for the
    # caller to fall back on those patches alone
    return solve_spd(sp.csr_matrix(normal), rhs, isolate_nonfinite=True) + centre


def moves_little(x: np.ndarray, again: np.ndarray, new_tris: np.ndarray) -> bool:
    """Whether ``again`` (new positions of the last ``len(again)`` vertices of ``x``) moves no vertex by
    :data:`~o3d_lsmesh.holes.tuning.COTANGENT_LEAP` of the size of the patch ``new_tris`` in ``x`` (obtuse
    slivers can make cotangent weights ill-conditioned: the solve then leaps away)."""
    first = len(x) - len(again)
    p = x[new_tris]
    extent = p.max(axis=(0, 1)) - p.min(axis=(0, 1)) if len(p) else np.zeros(3)
    size = np.sqrt(extent.dot(extent))  # np.linalg.norm's bits
    move = np.abs(again - x[first:]).max() if len(again) else 0.0
    return bool(move < tuning.COTANGENT_LEAP * size)


def fair_patches(
    filler: Any,
    vertices: np.ndarray,
    triangles: np.ndarray,
    holes: list,
    continuity: int,
    cot: bool,
    owner: np.ndarray,
    vertex_owner: np.ndarray,
    index: Any,
):
    """Fair every new vertex (there is one at least) at once: one local system over the patches and the
    rings around them.

    ``vertices`` (the input's, then the new ones) take the result in place, ``triangles``' new rows their
    flips. Each hole (``owner`` of each new triangle, ``vertex_owner`` of each new vertex) keeps the first
    candidate (the docs page's order) whose new triangles cross nothing; returns the continuity each hole
    got and the holes where none is (the caller leaves them open).
    """
    from .._patch_kernel import local_mesh, tangential_relax  # compiled: imported where used
    from .._triangulation_kernel import relax

    total, m, n = len(vertices), len(filler.triangles), len(filler.vertices)
    unknown = np.arange(n, total)
    loops = holes[0].vertices if len(holes) == 1 else np.concatenate([hole.vertices for hole in holes])
    # triangles within `continuity` rings of the loops in the input, plus every new triangle; a local
    # numbering (nothing as long as the mesh): the new vertices, every one on a new triangle and
    # numbered last, stay last; one connectivity for every solve below
    new_tris = triangles[m:].copy()  # as refined: the candidates' flips start from it
    indptr, data = filler.vertex_triangles
    local_vertices, local, local_rings = local_mesh(
        filler.triangles, indptr, data, loops, continuity, new_tris
    )
    local_unknown = np.arange(len(local_vertices) - len(unknown), len(local_vertices))
    refined = vertices[n:].copy()
    work = vertices  # its new rows hold the candidate being solved from or checked

    def solve(level: int, weighted: bool) -> np.ndarray | None:
        try:
            x = _fair(work[local_vertices], local, local_unknown, local_rings, level, weighted)
        except SingularSystemError:
            return None
        return x if np.isfinite(x).any() else None  # a patch whose system is not finite: NaN rows

    def candidates():  # lazily: most calls stop at the first
        for level in range(continuity, -1, -1):
            solution = solve(level, False)
            if solution is None:
                continue
            work[n:] = solution
            if cot and level > 0:
                # cotangent weights (clamped, area-normalized) read off the uniform solution: a fair
                # embedding, where weights from the flat refined patch diverged (camel 15h: 87 h off)
                again = solve(level, True)
                if again is not None:  # a patch whose cotangent system is not finite keeps uniform
                    again = np.where(np.isfinite(again).all(axis=1)[:, None], again, solution)
                if again is not None and moves_little(work, again, new_tris):
                    work[n:] = again
                    yield level, tangential_relax(work, new_tris, n)
                    work[n:] = solution
            yield level, tangential_relax(work, new_tris, n)
            work[n:] = refined
        yield -1, refined  # the refined patch as triangulated

    tried = []
    chosen = np.full(len(holes), -1)
    out, final = refined.copy(), new_tris.copy()
    # each candidate's patches flipped again as the refinement's were (Liepa's rule, and no crease made
    # sharper): fairing moved the vertices those flips were chosen on; holes without a new vertex keep
    # the bare programme. The input's edges between patch vertices: no flip may make one twice
    flip = (np.bincount(vertex_owner, minlength=len(holes)) > 0)[owner]
    used = np.unique(new_tris[flip])
    loop = used[used < n]
    near = filler.triangles[data[concatenated_ranges(indptr[loop], indptr[loop + 1] - indptr[loop])]]
    inside = in_sorted(used, near)
    fixed = np.concatenate([near[:, e][inside[:, e].all(axis=1)] for e in ([0, 1], [1, 2], [2, 0])])
    for rank, (level, candidate) in enumerate(candidates()):
        tried.append(level)
        # a patch left NaN (its system not finite) is checked as refined and fails this candidate
        broken = ~np.isfinite(candidate).all(axis=1)
        work[n:] = np.where(broken[:, None], refined, candidate)
        dirty = np.ones(int(flip.sum()), dtype=bool)
        triangles[m:][flip] = relax(work, new_tris[flip], fixed, dirty, True)
        # relaxed once more on the flipped patch, and flipped again (remeshing's alternation): the flips
        # made the new triangles the relaxation had not seen
        candidate = np.where(broken[:, None], candidate, tangential_relax(work, triangles[m:], n))
        work[n:] = np.where(broken[:, None], refined, candidate)
        triangles[m:][flip] = relax(work, triangles[m:][flip], fixed, dirty, True)
        crossing = _crossings(work, triangles, m, index, owner)  # (q,) nonzero on crossing holes
        per_hole = np.bincount(owner, weights=crossing, minlength=len(holes))
        per_hole += np.bincount(vertex_owner, weights=broken, minlength=len(holes))
        for hole_index in np.flatnonzero((chosen < 0) & (per_hole == 0)):
            mine = vertex_owner == hole_index
            out[mine] = candidate[mine]
            final[owner == hole_index] = triangles[m:][owner == hole_index]
            chosen[hole_index] = rank
        if (chosen >= 0).all():
            break
    work[n:], triangles[m:] = out, final
    return np.array([tried[c] if c >= 0 else tried[0] for c in chosen], dtype=np.int64), np.flatnonzero(
        chosen < 0
    )
