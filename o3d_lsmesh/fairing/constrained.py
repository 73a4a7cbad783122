"""Constrained fairing for denoising meshes (Liu et al. 2001, section 3): the public entry points.

:func:`constrained_fairing_arrays` is the array core (also the kernel that the
multiresolution fairing runs on every hierarchy level);
:func:`constrained_fairing` converts Open3D meshes to and from it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._o3d import new_mesh, read_mesh
from .._validate import as_choice, as_count, as_positive_float
from .barycenter import DEFAULT_MU, GlobalSolver, fairing_topology, local_operator
from .boundary_curve import curve_operator

__all__ = ["constrained_fairing", "constrained_fairing_arrays", "FAIRING_METHODS"]

FAIRING_METHODS = ("local", "global")


def _check_options(number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress):
    number_of_iterations = as_count(number_of_iterations, name="number_of_iterations")
    method = as_choice(method, FAIRING_METHODS, name="method")
    if mu is not None:
        mu = as_positive_float(mu, name="mu")
        if method == "local":
            raise ValueError("mu must be None for method='local' (it weighs the penalty of method='global'), got "
                             f"{mu}")
    if reimpose_every is not None:
        reimpose_every = as_count(reimpose_every, name="reimpose_every", minimum=1)
        if method == "global":
            raise ValueError(
                "reimpose_every must be None for method='global' (every global iteration re-imposes the "
                f"constraints at the previous result), got {reimpose_every}"
            )
    for name, value in (("smooth_boundary", smooth_boundary), ("progress", progress)):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {type(value).__name__}")
    return number_of_iterations, method, mu, bool(smooth_boundary), reimpose_every, bool(progress)


def _iterations(count: int, progress: bool, description: str):
    if not progress:
        return range(count)
    from tqdm.auto import tqdm

    return tqdm(range(count), desc=description)


def constrained_fairing_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    number_of_iterations: int = 10,
    *,
    method: str = "local",
    mu: float | None = None,
    smooth_boundary: bool = True,
    reimpose_every: int | None = None,
    progress: bool = False,
    solver: str = "auto",
) -> np.ndarray:
    """Array core of :func:`constrained_fairing`: faired ``(n, 3) float64`` positions.

    Takes and returns plain arrays so that the multiresolution fairing can
    run it on every level of a hierarchy; the arguments and the method are
    described in :func:`constrained_fairing`. The input arrays are not
    modified.

    Parameters
    ----------
    vertices : (n, 3) array-like of float
    triangles : (m, 3) array-like of int
    number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress
        As in :func:`constrained_fairing`.

    Returns
    -------
    (n, 3) float64 ndarray

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> V, F = np.asarray(box.vertices), np.asarray(box.triangles)
    >>> constrained_fairing_arrays(V, F, 5).shape
    (8, 3)
    """
    number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress = _check_options(
        number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress
    )
    data = read_mesh((vertices, triangles), name="mesh")
    return _fair(data.vertices, data.triangles, number_of_iterations, method, mu, smooth_boundary, reimpose_every,
                 progress, solver=solver)


def _fair(positions, triangles, number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress, *,
          solver="auto"):
    # validated arrays in, new (n, 3) positions out (``positions`` is a private copy)
    if number_of_iterations == 0:
        return positions
    topo = fairing_topology(triangles, len(positions), with_loops=smooth_boundary)
    curve = curve_operator(topo.loops)
    steps = _iterations(number_of_iterations, progress, f"constrained fairing ({method})")
    if method == "local":
        op = local_operator(triangles, topo)
        constant, curve_target = op.constant(positions), curve.target(positions)
        for iteration in steps:
            if reimpose_every is not None and iteration and iteration % reimpose_every == 0:
                constant, curve_target = op.constant(positions), curve.target(positions)
            relaxed = op.step(positions, constant)
            if len(curve):
                relaxed[curve.vertex] = curve.step(positions, curve_target)
            positions = relaxed
        return positions
    system = GlobalSolver(triangles, topo, DEFAULT_MU if mu is None else mu, solver=solver, progress=progress)
    for _ in steps:
        known = positions.copy()
        if len(curve):
            known[curve.vertex] = curve.step(positions, curve.target(positions))
        positions = system.solve(known, positions)
    return positions


def constrained_fairing(
    mesh: Any,
    number_of_iterations: int = 10,
    *,
    method: str = "local",
    mu: float | None = None,
    smooth_boundary: bool = True,
    reimpose_every: int | None = None,
    progress: bool = False,
    solver: str = "auto",
) -> Any:
    """Remove noise from a mesh while holding its triangle barycenters (Liu et al. 2001).

    Minimizes the uniform-Laplacian membrane energy under the constraint that
    every triangle keeps its barycenter (eq. 5)::

        min  X^T K^T K X   subject to   H (X - X0) = 0,

    where ``K = I - D^-1 W`` (``w_ij = 1/n_i`` for the ``n_i`` edge
    neighbours of vertex ``i``, eq. 3) and ``H`` is the ``(m, n)``
    triangle-vertex incidence matrix (one row per triangle, ones at its three
    vertices). Holding the barycenters is a "skeleton" that stops the
    shrinkage and drift of plain Laplacian smoothing.

    ``method="local"`` (the paper's operator, section 3.2): for every
    triangle, its three vertices minimize their local Laplacian energy
    ``|A P - Q|^2`` subject to ``P_0 + P_1 + P_2 = C`` (eq. 6), solved in
    closed form (eq. 7), where ``q_i`` is ``1/n_i`` times the sum of the
    neighbours of ``i`` outside the triangle; each vertex then takes the
    average of its estimates. With uniform weights ``A`` depends only on the
    three valences, so the 3x3 algebra is done once per distinct valence
    triple, and one iteration is the fixed linear map
    ``X <- E1 W X + E2 X + E3 X0`` assembled once (three sparse mat-vecs per
    iteration). The targets ``X0`` are the input for the whole run;
    ``reimpose_every=k`` re-takes them from the current positions every ``k``
    iterations, the paper's "imposing and relaxing the center constraints by
    turns", for stronger smoothing.

    ``method="global"``: the penalty form of eq. 5,
    ``min X^T K^T K X + mu (X - X0)^T H^T H (X - X0)``, factored once by
    CHOLMOD. The hard-constrained form is degenerate for a closed mesh: it has
    ``m ~ 2n`` barycenter equations on ``n`` unknowns per coordinate, and
    ``H`` has full column rank on most meshes, so ``H (X - X0) = 0`` alone
    forces ``X = X0`` and there is nothing left to minimize (on a
    3-colourable mesh, such as a regular grid, ``H`` has a two-dimensional
    null space, the colour-class patterns summing to zero on every triangle,
    so the feasible set is a tiny, non-smooth family). The penalty trades:
    ``mu -> inf`` returns the input, ``mu -> 0`` the unconstrained Laplacian
    minimum (each component shrinks towards a point). ``K`` is dimensionless
    and ``H`` has unit entries, so ``mu`` is independent of the mesh's scale.
    The default ``mu = 0.03`` (``DEFAULT_MU``) was chosen by measurement
    (benchmarks/bench_denoise.py, one solve, seeded Gaussian noise, ``mu`` in
    {0.01, 0.03, 0.1, 0.3, 1}): at noise 0.2 mean edge lengths it gives the
    lowest mean vertex error on bunny, screwdriver and feline (0.172-0.175
    edge lengths; the open Venus prefers 0.1 by 5%); at noise 0.5, ``mu=0.01``
    is 13% better for one solve, but 3 to 5 iterations at 0.03 reach the same
    error. ``|volume change|`` stays under 0.15% on the closed meshes.
    Each further iteration re-takes ``X0`` from the previous result and costs
    one back-substitution with the kept factor (so ``reimpose_every`` must be
    ``None``).

    Boundaries (section 3.3): the surface relaxation of both methods uses the
    *interior triangles*, those with no boundary vertex, and moves only
    non-boundary vertices. A triangle touching the boundary would relax its
    boundary vertex with a one-sided Laplacian that pulls it into the
    surface; dropping that vertex's estimate would break the triangle's
    barycenter constraint for the positions actually used, so such triangles
    are left out (their interior vertices still take estimates from their
    other triangles; a vertex all of whose triangles touch the boundary stays
    put). This is the paper's "for each interior triangle". Boundary vertices
    move only by the boundary-curve fairing of
    :func:`~o3d_lsmesh.fairing.smooth_boundary_curves`, one curve step per
    iteration; ``smooth_boundary=False`` keeps them fixed. Loops with fewer
    than four vertices are held fixed.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        ``(n, 3)`` vertices and ``(m, 3)`` triangles. Several components,
        isolated vertices (kept where they are), zero-area triangles and
        low-valence vertices are fine.
    number_of_iterations : int
        Local iterations, or global solves. 0 returns an unchanged copy.
    method : {"local", "global"}
    mu : float or None
        Penalty weight of ``method="global"`` (``None``: ``DEFAULT_MU``).
        Must be ``None`` for ``"local"``.
    smooth_boundary : bool
        Fair the boundary loops (True) or keep boundary vertices fixed.
    reimpose_every : int or None
        ``method="local"`` only: re-take the constraint targets from the
        current positions every this many iterations.
    progress : bool
        Show a tqdm progress bar over the iterations.
    solver : {"auto", "cholmod", "iterative"}
        ``method="global"`` only: how the system is solved (see
        :class:`~o3d_lsmesh.SPDSolver`); ``"auto"`` factors it unless the factor
        would exceed the memory budget, then runs conjugate gradients with an
        AMG preconditioner, warm-started from the current positions.

    Returns
    -------
    mesh
        A new mesh of the input's kind with the same triangles; vertex colors
        (and, for tensor meshes, other per-vertex and per-triangle attributes)
        are kept, and normals are recomputed when the input had them. The
        input is not modified.

    Raises
    ------
    TypeError
        ``mesh`` is not a mesh; ``number_of_iterations`` or ``reimpose_every``
        not an integer; ``mu`` not a number; ``method`` not a string;
        ``smooth_boundary`` or ``progress`` not a bool.
    ValueError
        Negative ``number_of_iterations``; ``reimpose_every < 1``; unknown
        ``method``; ``mu <= 0``; ``mu`` with ``"local"`` or ``reimpose_every``
        with ``"global"``; an invalid mesh (see
        :func:`o3d_lsmesh._o3d.read_mesh`); an edge shared by more than two
        triangles (named); with ``smooth_boundary``, a boundary vertex on
        other than two boundary edges (named). Vertices joining several closed
        fans are accepted: their 1-ring is the union of the fans.

    See Also
    --------
    constrained_fairing_arrays : the array core.
    o3d_lsmesh.fairing.smooth_boundary_curves : the boundary fairing alone.

    References
    ----------
    X. Liu, H. Bao, P.-A. Heng, T.-T. Wong, Q. Peng, "Constrained Fairing for
    Meshes", Computer Graphics Forum 20(2), 2001, sections 3.1 to 3.3.

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=20)
    >>> noisy = o3d.geometry.TriangleMesh(sphere)
    >>> rng = np.random.default_rng(0)
    >>> noisy.vertices = o3d.utility.Vector3dVector(np.asarray(sphere.vertices) + rng.normal(0, 0.02, (len(sphere.vertices), 3)))
    >>> smooth = constrained_fairing(noisy, number_of_iterations=10)
    >>> error = lambda m: np.abs(np.linalg.norm(np.asarray(m.vertices), axis=1) - 1).mean()
    >>> bool(error(smooth) < error(noisy))
    True
    """
    options = _check_options(number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress)
    data = read_mesh(mesh)
    return new_mesh(data, _fair(data.vertices.copy(), data.triangles, *options, solver=solver))
