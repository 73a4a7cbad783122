"""Constrained fairing for denoising meshes (Liu et al. 2001, section 3): the public entry points.

:func:`constrained_fairing_arrays` is the array core (also the kernel that the
multiresolution fairing runs on every hierarchy level);
:func:`constrained_fairing` converts Open3D meshes to and from it. Three
energies: ``"scan"`` (the default of :func:`constrained_fairing`, for raw
range scans, :mod:`.scan_fairing`), and the paper's ``"local"`` (eq. 7) and
``"global"`` (penalty form of eq. 5) operators (:mod:`.barycenter`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from typing import TYPE_CHECKING

import numpy as np

from .._o3d import new_mesh, read_mesh
from .._progress import check_progress, iterate
from .._solvers import SOLVERS
from .._validate import as_bool, as_choice, as_count, as_iterations, as_positive_float, mesh_arrays
from ..topology import boundary_curves, edge_structure, vertex_rings
from .barycenter import DEFAULT_MU, GlobalSolver, fairing_topology, local_operator
from .boundary_curve import curve_operator
from .features import feature_denoise
from .scan_fairing import scan_denoise

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = ["DEFAULT_METHOD", "FAIRING_METHODS", "constrained_fairing", "constrained_fairing_arrays"]

FAIRING_METHODS = ("scan", "local", "global", "features")
#: The energy of ``constrained_fairing(mesh)`` (see its docstring for the measurements).
DEFAULT_METHOD = "scan"
_DEFAULT_ITERATIONS = {"scan": 1, "local": 10, "global": 10}


def resolved_options(method: str | None, number_of_iterations: int | None, reimpose_every: int | None):
    """The method and iteration count that ``None`` stands for (unchecked values pass through)."""
    if method is None:
        # an iteration count and reimpose_every only mean something for the paper's local operator (the scan
        # energy is one solve): a call written for the former default (method="local") keeps its meaning
        method = "local" if reimpose_every is not None or number_of_iterations is not None else DEFAULT_METHOD
    if number_of_iterations is None and isinstance(method, str) and method in _DEFAULT_ITERATIONS:
        number_of_iterations = _DEFAULT_ITERATIONS[method]
    return method, number_of_iterations


def _check_options(
    number_of_iterations,
    method,
    mu,
    smooth_boundary,
    reimpose_every,
    progress,
    membrane=None,
    boundary_weight=None,
):
    method, number_of_iterations = resolved_options(method, number_of_iterations, reimpose_every)
    method = as_choice(method, FAIRING_METHODS, name="method")  # valid: resolved_options filled the count
    if method != "features" or number_of_iterations is not None:  # features: None is a measured count
        number_of_iterations = as_iterations(number_of_iterations)
    if method == "scan" and number_of_iterations > 1:
        # re-taken solves shrink the scan (10: 4x the time, 3x the inward move) without the smoothing of
        # iterations: the scan energy is one solve
        raise ValueError(
            "number_of_iterations must be None, 0 or 1 for method='scan' (its energy is one solve; for "
            f"smoothing by iterations use method='local'), got {number_of_iterations}"
        )
    for name, value in (("membrane", membrane), ("boundary_weight", boundary_weight)):
        if value is not None and method != "scan":
            raise ValueError(
                f"{name} must be None for method={method!r} (it weighs a term of method='scan'), got {value}"
            )
    if membrane is not None:
        membrane = as_positive_float(membrane, name="membrane", allow_zero=True)
    if boundary_weight is not None:
        boundary_weight = as_positive_float(boundary_weight, name="boundary_weight")
    if method in ("scan", "features") and reimpose_every is not None:
        raise ValueError(
            f"reimpose_every must be None for method={method!r} (it is a local-operator option), got "
            f"{reimpose_every}"
        )
    if mu is not None:
        mu = as_positive_float(mu, name="mu")
        if method in ("local", "features"):
            raise ValueError(
                f"mu must be None for method={method!r} (it weighs the penalty of method='global'), got {mu}"
            )
    if reimpose_every is not None:
        reimpose_every = as_count(reimpose_every, name="reimpose_every", minimum=1)
        if method == "global":
            raise ValueError(
                "reimpose_every must be None for method='global' (every global iteration re-imposes the "
                f"constraints at the previous result), got {reimpose_every}"
            )
    smooth_boundary = as_bool(smooth_boundary, name="smooth_boundary")
    progress = check_progress(progress)
    if method in ("scan", "features") and not smooth_boundary:
        raise ValueError(
            f"smooth_boundary must be True for method={method!r} (its boundary moves with the surface; "
            "hold it fixed with method='global' or 'local'), got False"
        )
    options = (number_of_iterations, method, mu, bool(smooth_boundary), reimpose_every, bool(progress))
    return options, {"membrane": membrane, "boundary_weight": boundary_weight}


def constrained_fairing_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    number_of_iterations: int | None = 10,
    *,
    method: str | None = "local",
    mu: float | None = None,
    membrane: float | None = None,
    boundary_weight: float | None = None,
    smooth_boundary: bool = True,
    reimpose_every: int | None = None,
    progress: bool = False,
    solver: str = "auto",
) -> np.ndarray:
    """Array core of :func:`constrained_fairing`: faired ``(n, 3) float64`` positions.

    Takes and returns plain arrays so that the multiresolution fairing can
    run it on every level of a hierarchy; the arguments and the methods are
    described in :func:`constrained_fairing`. Unlike the wrapper, whose
    default is ``method="scan"``, the array core keeps its explicit callers'
    defaults (``method="local"``, 10 iterations, the multiresolution
    fairing's kernel); pass ``method=None`` (and ``number_of_iterations=None``)
    for the wrapper's default. The input arrays are not modified.

    Parameters
    ----------
    vertices : (n, 3) array-like of float
    triangles : (m, 3) array-like of int
    number_of_iterations, method, mu, membrane, boundary_weight, smooth_boundary, reimpose_every, progress
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
    options, extra = _check_options(
        number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress, membrane, boundary_weight
    )
    vertices, triangles = mesh_arrays(vertices, triangles)  # copies: _fair may write to its positions
    return _fair(vertices, triangles, *options, solver=solver, **extra)


def _fair(
    positions,
    triangles,
    number_of_iterations,
    method,
    mu,
    smooth_boundary,
    reimpose_every,
    progress,
    *,
    membrane=None,
    boundary_weight=None,
    solver="auto",
):
    # validated arrays in, new (n, 3) positions out (``positions`` is a private copy)
    solver = as_choice(solver, SOLVERS, name="solver")  # checked for every method ("local" solves none)
    if number_of_iterations == 0:
        return positions
    if method == "scan":
        return scan_denoise(
            positions,
            triangles,
            number_of_iterations=number_of_iterations,
            mu=mu,
            membrane=membrane,
            boundary_weight=boundary_weight,
            solver=solver,
            progress=progress,
        )
    if method == "features":
        return feature_denoise(positions, triangles, passes=number_of_iterations, progress=progress)
    if method == "local":
        with plain_pages():
            return fair_local(
                positions, triangles, number_of_iterations, smooth_boundary, reimpose_every, progress
            )
    topo = fairing_topology(triangles, len(positions), with_loops=smooth_boundary)
    curve = curve_operator(topo.loops)
    steps = iterate(progress, range(number_of_iterations), desc=f"constrained fairing ({method})")
    system = GlobalSolver(triangles, topo, DEFAULT_MU if mu is None else mu, solver=solver, progress=progress)
    for _ in steps:
        known = positions.copy()
        if len(curve):
            known[curve.vertex] = curve.step(positions, curve.target(positions))
        positions = system.solve(known, positions)
    return positions


def fair_local(
    positions, triangles, number_of_iterations, smooth_boundary, reimpose_every, progress, rings=None
):
    # the paper's local operator (eq. 7): one pass over the corners grouped by vertex gives the
    # 1-ring pattern, the valences and the boundary; the edge list is sorted only for a boundary walk.
    # ``rings``: the mesh's VertexRings when the caller has them (multiresolution fairing), spent here
    n = len(positions)
    rings = vertex_rings(triangles, n) if rings is None else rings
    curves = (
        boundary_curves(triangles, n, edges=edge_structure(triangles, n))
        if smooth_boundary and rings.boundary.any()
        else []
    )
    curve = curve_operator(curves)
    del curves
    # the constraint part E3 @ X0 is formed during the assembly; E3 itself is kept only when the
    # targets are re-taken
    op = local_operator(triangles, rings, positions0=positions, keep_constraint=reimpose_every is not None)
    constant = op.initial
    # the rings' slot pairs are dead now: their pages (already mapped, where fresh (n, 3) buffers
    # would cost a page fault per page at scan sizes) hold the two buffers of the whole run
    spare, work = (_reused(array, positions.shape) for array in rings.pairs)
    del rings
    curve_target = curve.target(positions)
    result = positions  # a plain array (the reused buffers are views of the rings' int arrays)
    steps = iterate(progress, range(number_of_iterations), desc="constrained fairing (local)")
    for iteration in steps:
        if reimpose_every is not None and iteration and iteration % reimpose_every == 0:
            constant, curve_target = op.constant(positions, out=constant), curve.target(positions)
        relaxed = op.step(positions, constant, out=spare, work=work)
        if len(curve):
            relaxed[curve.vertex] = curve.step(positions, curve_target)
        positions, spare = relaxed, positions
    if positions is not result:  # an odd number of iterations
        np.copyto(result, positions)
    return result


_PAGE_ADVICE_LOCK = threading.Lock()
_PAGE_ADVICE_STATE = {"depth": 0, "previous": True}


def huge_page_toggle() -> Callable[[bool], bool] | None:
    """numpy's private switch of its huge-page advice (``np._core`` from numpy 2, ``np.core`` before)."""
    core = getattr(np, "_core", None) or getattr(np, "core", None)
    return getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)


@contextmanager
def plain_pages() -> Iterator[None]:
    """Within the block, numpy does not ask the kernel for transparent huge pages on new arrays.

    numpy advises huge pages (``madvise``) for arrays of 4 MB and more; where the kernel then
    compacts memory at the fault (THP ``defrag = madvise``, its default) on a fragmented machine,
    the faults cost more than the huge pages save. Local fairing is a few passes over fresh
    mesh-sized arrays, so that is most of its system time: measured at 4M vertices (noisy sphere,
    10 iterations, this 2-core virtual machine) 1.3-1.6 s of system time without the advice
    against 3.1-3.7 s with it, 7.7-8.4 s of CPU time in all against 9.6-10.7 s; a wash at 1M. The
    setting is process-wide: nested and concurrent calls share one save and restore.
    """
    toggle = huge_page_toggle()
    if toggle is None:  # pragma: no cover - another numpy
        yield
        return
    with _PAGE_ADVICE_LOCK:
        if _PAGE_ADVICE_STATE["depth"] == 0:
            _PAGE_ADVICE_STATE["previous"] = bool(toggle(False))
        _PAGE_ADVICE_STATE["depth"] += 1
    try:
        yield
    finally:
        with _PAGE_ADVICE_LOCK:
            _PAGE_ADVICE_STATE["depth"] -= 1
            if _PAGE_ADVICE_STATE["depth"] == 0:
                toggle(bool(_PAGE_ADVICE_STATE["previous"]))


def _reused(array: np.ndarray, shape: tuple) -> np.ndarray:
    """An uninitialized float64 array of ``shape`` on the memory of the dead contiguous ``array``, or a new one."""
    size = int(np.prod(shape)) * 8
    if array.flags.c_contiguous and array.nbytes >= size:
        return array.reshape(-1).view(np.uint8)[:size].view(np.float64).reshape(shape)
    return np.empty(shape)


def constrained_fairing(
    mesh: MeshT,
    number_of_iterations: int | None = None,
    *,
    method: str | None = None,
    mu: float | None = None,
    membrane: float | None = None,
    boundary_weight: float | None = None,
    smooth_boundary: bool = True,
    reimpose_every: int | None = None,
    progress: bool = False,
    solver: str = "auto",
) -> MeshT:
    """Remove noise from a mesh while holding its triangle barycenters (Liu et al. 2001).

    **Default** (``constrained_fairing(mesh)``, ``method="scan"``, one
    linear system, no parameter to set): made for raw range scans, whose
    noise is correlated along the scanlines and whose rim samples (grazing
    angles) carry 2.5-4 times the interior's error, and first as well on
    independent noise. It minimizes the global penalty form of eq. 5 with
    the boundary freed, the barycenters weighted by their noise and, on a
    scan, a small membrane term, and then twices the result (module
    :mod:`o3d_lsmesh.fairing.scan_fairing`)::

        E(X) = |K X|^2 + mu sum_t w_t |h_t (X - X0)|^2 + lambda sum_edges |x_i - x_j|^2,
        X1 = argmin E,   X = X1 + S (X0 - X1)   (S: the same minimization, same system)

    with every referenced vertex unknown and ``w_t = w`` for a triangle with
    a boundary vertex, 1 otherwise. Every weight is measured on the input,
    never set from a reference
    (:func:`~o3d_lsmesh.fairing.scan_fairing.scan_parameters` says how): ``w``
    from the rim's noise against the interior's (0.10-0.13 on the raw scans'
    ragged silhouettes); a range scan gets ``mu = SCAN_MU (g / sigma)^2``
    from its measured detail-to-noise ratio (fine detail above the noise is
    held), a rim weight ``mu w = SCAN_RIM_MU w``, ``lambda = 0.45`` and the
    twicing step (the membrane damps the scanline-correlated noise that
    ``|K X|^2`` keeps, the twicing puts back most of its shrinkage), then a
    tangential relaxation of its rim's triangles (no slivers);
    independent noise gets the barycenter-only energy with ``mu`` from the
    measured noise and surface detail, and a rim vertex's thin-plate row
    along its boundary curve, which has no inward pull; in between, every
    weight moves with the measured *scan likeness*.

    All measures are dimensionless, so the result is equivariant under rigid
    motions and scaling. Measured on the ten raw Stanford bunny scans
    against a reference surface (benchmarks/results/realscans_denoise.md),
    each peer (Open3D simple/Laplacian/Taubin, PyMeshLab
    HC/Laplacian/Taubin/two-step, trimesh Taubin/Humphrey) at its best
    setting per scan: the default beats every peer on 10 of 10 scans (error
    / best peer 0.90-0.999, mean 0.940), mean distance 70.3 um against 75.0
    um for the best single filter (Open3D ``filter_smooth_simple`` at its
    best count), and moves the interior inward by 4.4 um (Open3D simple:
    17.9 um). On seeded Gaussian noise of 0.2 and 0.5 mean edge lengths
    (benchmarks/results/denoise.md) it is first on bunny, Venus,
    screwdriver and feline: mean vertex error 0.97-1.00 times the best
    peer's at its best setting; closed-mesh volume change at noise 0.5
    -0.12% (screwdriver) to +0.02%. Why not the paper's operators: with the
    boundary held (``"local"``, ``"global"``) a scan's rim keeps its error
    (bun000: 246 um against Open3D's 154-159 um), ranking 8th-9th of 15
    methods.

    Limits of the default (measured): on a range scan the membrane and the
    rim's low weight collapse rim triangles (hundreds of slivers of quality
    under 0.05 per scan, none in the raw scans; see
    benchmarks/results/realscans_denoise.md); weakening the membrane at the
    rim halves them but loses scans to the peers. Time: from 5,000 vertices
    conjugate gradients preconditioned by the system's incomplete Cholesky
    factor, each solve stopped at 1e-4 of its starting residual (within
    1.3e-4 mean edge lengths RMS of the exact minimizer on the raw scans),
    3.3-4.0 times Open3D's ``filter_smooth_laplacian`` at its best count at
    40k vertices and 2.5-2.8 times at 1.4M; below, one sparse Cholesky
    factorization (benchmarks/results/realscans_denoise_speed.md).

    The paper's operators minimize the uniform-Laplacian energy ``|K X|^2``
    under the constraint that every triangle keeps its barycenter,
    ``H (X - X0) = 0`` (eq. 5; :mod:`o3d_lsmesh.fairing.barycenter` defines
    ``K`` and ``H``): a "skeleton" that stops the shrinkage and drift of plain
    Laplacian smoothing.

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

    ``method="features"`` keeps sharp creases (CAD parts, mechanical
    scans): guided normal filtering (Zhang et al. 2015) alternated with Sun
    et al.'s vertex update, ``number_of_iterations`` passes (``None``:
    measured from the noise); see :mod:`o3d_lsmesh.fairing.features` and
    :func:`~o3d_lsmesh.detect_creases`. Its figures are in
    benchmarks/results/features_denoise.md.

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
    number_of_iterations : int or None
        Local iterations, or global solves, at most
        :data:`~o3d_lsmesh._validate.MAX_ITERATIONS`; 0 returns an unchanged
        copy. ``"scan"`` is one solve: None, 0 or 1 (re-taken solves would
        only shrink the scan). ``None``: 1 for ``"scan"``, 10 for ``"local"``
        and ``"global"``, measured from the noise for ``"features"`` (its
        filter passes).
    method : {"scan", "local", "global", "features"} or None
        ``None``: ``"scan"``, or ``"local"`` when ``number_of_iterations`` or
        ``reimpose_every`` is given (options of the iterative operator only;
        it was the default before ``"scan"``).
    mu : float or None
        Penalty weight of ``"global"`` and ``"scan"`` (``None``:
        ``DEFAULT_MU`` = 0.03; for ``"scan"`` measured from the input, see
        ``scan_parameters``). Must be ``None`` for ``"local"``.
    membrane : float or None
        ``"scan"`` only: membrane weight ``lambda >= 0`` (``None``: measured,
        0.45 on a range scan, 0 with independent noise).
    boundary_weight : float or None
        ``"scan"`` only: barycenter weight ``w_t > 0`` of the triangles with a
        boundary vertex (``None``: measured from the input, in ``[0.1, c]``,
        see ``measured_boundary_weight``; 1 trusts the rim like the interior).
    smooth_boundary : bool
        Fair the boundary loops (True) or keep boundary vertices fixed
        (``"local"`` and ``"global"``; ``"scan"`` needs True, its boundary is
        part of the surface solve).
    reimpose_every : int or None
        ``method="local"`` only: re-take the constraint targets from the
        current positions every this many iterations.
    progress : bool
        Show a tqdm progress bar over the iterations.
    solver : {"auto", "cholmod", "iterative"}
        ``"scan"`` and ``"global"``: how the system is solved (see
        :class:`~o3d_lsmesh.SPDSolver`); ``"auto"`` factors it unless the factor
        would exceed the memory budget, then runs conjugate gradients with an
        AMG preconditioner, warm-started from the current positions.
        ``"scan"``: from 5,000 vertices (and with ``"iterative"``) conjugate
        gradients with the incomplete Cholesky factor, to 1e-4 of the starting
        residual (:class:`~o3d_lsmesh.fairing.scan_fairing.ScanFairingSolver`).
        ``"local"`` solves no system.

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
        not an integer; ``mu``, ``membrane`` or ``boundary_weight`` not a
        number; ``method`` not a string;
        ``smooth_boundary`` or ``progress`` not a bool.
    ValueError
        ``number_of_iterations`` negative, above ``MAX_ITERATIONS``, or above 1
        with ``"scan"``; ``reimpose_every < 1``; unknown
        ``method``; ``mu <= 0``; ``membrane < 0``; ``boundary_weight <= 0``;
        ``mu`` with ``"local"``, ``membrane`` or ``boundary_weight`` with other
        than ``"scan"``, ``reimpose_every`` with other than ``"local"``,
        ``smooth_boundary=False`` with ``"scan"``; an invalid mesh (see
        :func:`o3d_lsmesh._o3d.read_mesh`). ``"local"`` and ``"global"``
        only: an edge shared by more than two triangles (named); with
        ``smooth_boundary``, a boundary vertex on other than two boundary
        edges (named). ``"scan"`` takes non-manifold edges and vertices and
        pinched boundaries as they are. Vertices joining several fans have
        the union of the fans as their 1-ring.

    See Also
    --------
    constrained_fairing_arrays : the array core.
    o3d_lsmesh.fairing.scan_fairing.ScanFairingSolver : the default's energy, factored once.
    o3d_lsmesh.fairing.smooth_boundary_curves : the boundary fairing alone.

    References
    ----------
    X. Liu, H. Bao, P.-A. Heng, T.-T. Wong, Q. Peng, "Constrained Fairing for
    Meshes", Computer Graphics Forum 20(2), 2001, sections 3.1 to 3.3.
    J. W. Tukey, Exploratory Data Analysis, 1977 ("twicing").

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=20)
    >>> noisy = o3d.geometry.TriangleMesh(sphere)
    >>> rng = np.random.default_rng(0)
    >>> noisy.vertices = o3d.utility.Vector3dVector(np.asarray(sphere.vertices) + rng.normal(0, 0.02, (len(sphere.vertices), 3)))
    >>> smooth = constrained_fairing(noisy)  # method="scan"
    >>> error = lambda m: np.abs(np.linalg.norm(np.asarray(m.vertices), axis=1) - 1).mean()
    >>> bool(error(smooth) < error(noisy))
    True
    """
    options, extra = _check_options(
        number_of_iterations, method, mu, smooth_boundary, reimpose_every, progress, membrane, boundary_weight
    )
    local = options[1] == "local"
    with plain_pages() if local else nullcontext():
        # read_mesh's vertices are already a private copy: _fair may write to them; the local path
        # only reads the triangles, so it takes Open3D's own int32 array (no int64 copy, no cast back)
        data = read_mesh(mesh, weld=True, narrow=local)
        return new_mesh(data, _fair(data.vertices, data.triangles, *options, solver=solver, **extra))
