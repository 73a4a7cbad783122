"""Constrained fairing (Liu et al. 2001, section 3): the entry points and their option table.

Four energies: ``"scan"`` (:mod:`.scan_fairing`), ``"local"`` (eq. 7), ``"global"`` (eq. 5 in penalty
form, :mod:`.barycenter`), ``"features"`` (:mod:`.features`); :data:`METHOD_OPTIONS` says which option
applies to which. ``method="auto"``, the default, runs ``"features"`` where its passes reach their cap
(the filtered normals keep concentrating: flat pieces cut by creases) and ``"scan"`` elsewhere. Docs:
``docs/algorithms/constrained_fairing.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from .._o3d import new_mesh, read_mesh
from ..core.boundary import boundary_curves
from ..core.connectivity import Connectivity
from ..core.errors import InputError, warn
from ..core.progress import Progress
from ..core.solve import SOLVERS
from ..core.validate import (
    Option,
    as_bool,
    as_choice,
    as_count,
    as_iterations,
    as_positive_float,
    check_options,
    mesh_arrays,
)
from .barycenter import GlobalSolver, local_operator
from .boundary_curve import CurveOperator, curve_operator
from .features import FeatureRun, feature_denoise
from .scan_fairing import scan_denoise
from .tuning import DEFAULT_MU

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = [
    "DEFAULT_METHOD",
    "FAIRING_METHODS",
    "METHOD_OPTIONS",
    "FairingReport",
    "constrained_fairing",
    "constrained_fairing_arrays",
]

#: The energy of ``constrained_fairing(mesh)``: the choice made on the mesh (:func:`_chosen`).
DEFAULT_METHOD = "auto"
_AUTO = "auto"
_SCAN_WEIGHTS = ("mu", "membrane", "boundary_weight")


@dataclass(frozen=True)
class FairingReport:
    """What ``constrained_fairing(..., return_report=True)`` ran.

    Attributes
    ----------
    method : str
        The energy that ran: the one given, or ``"auto"``'s choice (``"features"`` or ``"scan"``).
    feature_passes : int or None
        ``"auto"``: the passes of the feature mode to its measured stop, ``MAX_PASSES`` where it ran the
        feature mode (the stop came at the cap); None for any other method.
    """

    method: str
    feature_passes: int | None = None


def _one_solve(value: Any, *, name: str) -> int:
    # re-taken solves of the scan energy shrink the scan without smoothing it more
    value = as_iterations(value, name=name)
    if value > 1:
        raise InputError(
            f"{name} must be 0 or 1 for method='scan' (its energy is one solve; for smoothing by "
            f"iterations use method='local'), got {value}",
            param=name,
        )
    return value


def _boundary_moves(method: str) -> Option:
    # scan and features move the boundary with the surface: it cannot be held (_check_options passes
    # smooth_boundary=True on as None, so only False reaches the check)
    def refuse(value: Any, *, name: str) -> NoReturn:
        raise InputError(
            f"{name} must be True for method={method!r} (its boundary moves with the surface; hold it "
            "fixed with method='global' or 'local'), got False",
            param=name,
        )

    return Option(refuse, True)


_MU = "it weighs the barycenter penalty of method='scan' or method='global'"
_SCAN_TERM = "it weighs a term of method='scan'"
_REIMPOSE = "it re-takes the targets of method='local'"
_SMOOTH = Option(as_bool, True)
#: Which option applies to which method: its check and its default (None given = the default).
METHOD_OPTIONS: dict[str, dict[str, Option]] = {
    "scan": {
        "number_of_iterations": Option(_one_solve, 1),
        "mu": Option(as_positive_float, None, _MU),
        "membrane": Option(partial(as_positive_float, allow_zero=True), None, _SCAN_TERM),
        "boundary_weight": Option(as_positive_float, None, _SCAN_TERM),
        "smooth_boundary": _boundary_moves("scan"),
    },
    "local": {
        "number_of_iterations": Option(as_iterations, 10),
        "reimpose_every": Option(partial(as_count, minimum=1), None, _REIMPOSE),
        "smooth_boundary": _SMOOTH,
    },
    "global": {
        "number_of_iterations": Option(as_iterations, 10),
        "mu": Option(as_positive_float, DEFAULT_MU, _MU),
        "smooth_boundary": _SMOOTH,
    },
    # None iterations: a pass count measured on the mesh as the passes go
    "features": {
        "number_of_iterations": Option(as_iterations),
        "smooth_boundary": _boundary_moves("features"),
    },
}
FAIRING_METHODS = tuple(METHOD_OPTIONS)


#: ``constrained_fairing_arrays``' default method: ``"local"`` with a DeprecationWarning (``None``
#: already means the wrapper's default, so it cannot mark an omitted ``method``).
_OMITTED: Any = object()


def resolved_options(method: str | None, number_of_iterations: int | None, reimpose_every: int | None):
    """The method and iteration count that ``None`` stands for (unchecked values pass through)."""
    if method is None:
        # an iteration count and reimpose_every only mean something for the local operator (the scan
        # energy is one solve): a call written for the former default (method="local") keeps its meaning
        method = "local" if reimpose_every is not None or number_of_iterations is not None else DEFAULT_METHOD
    if number_of_iterations is None and isinstance(method, str) and method in METHOD_OPTIONS:
        number_of_iterations = METHOD_OPTIONS[method]["number_of_iterations"].default
    return method, number_of_iterations


def _check_options(method: Any, given: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    # the one check of every option: the method's row of METHOD_OPTIONS, then progress
    if method is None:
        method = resolved_options(None, given["number_of_iterations"], given["reimpose_every"])[0]
    # "auto": the mesh chooses; its options are checked as the scan energy's, and a weight of that energy
    # given chooses it (the feature mode has no use for it)
    auto = as_choice(method, (*FAIRING_METHODS, _AUTO), name="method") == _AUTO
    if auto and any(given[name] is not None for name in _SCAN_WEIGHTS):
        auto, method = False, "scan"
    # a bool's type is checked for every method; True is what scan and features require
    smooth = as_bool(given["smooth_boundary"], name="smooth_boundary")
    given = {**given, "smooth_boundary": None if smooth else False}
    progress = as_bool(given.pop("progress"), name="progress")
    method, options = check_options(METHOD_OPTIONS, "scan" if auto else method, given)
    options["progress"] = progress
    return _AUTO if auto else method, options


def _chosen(positions, conn, method, options) -> tuple[str, FeatureRun | None, int | None]:
    # method="auto" on the mesh: the feature mode's passes to their measured stop. At the cap the filtered
    # normals kept concentrating (flat pieces cut by creases) and the feature mode goes on from them; an
    # earlier stop is a curved surface, where the scan energy runs on the input (docs: features.rst)
    if method != _AUTO:
        return method, None, None
    if options["number_of_iterations"] == 0:  # an unchanged copy: nothing to choose
        return "scan", None, None
    run = FeatureRun(positions, conn.triangles, conn)
    method = "features" if run.reaches_cap(options["progress"]) else "scan"
    if options["progress"]:
        Progress.write(f"constrained fairing: feature passes {run.stop_pass}, method {method!r}")
    if method == "scan":  # the scan energy does not hold the passes' face neighbourhoods in memory
        conn.release("face_adjacency")
        return method, None, run.stop_pass
    return method, run, run.stop_pass


def constrained_fairing_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    number_of_iterations: int | None = 10,
    *,
    method: str | None = _OMITTED,
    mu: float | None = None,
    membrane: float | None = None,
    boundary_weight: float | None = None,
    smooth_boundary: bool = True,
    reimpose_every: int | None = None,
    progress: bool = False,
    solver: str = "auto",
) -> np.ndarray:
    """Array core of :func:`constrained_fairing` (same arguments): faired ``(n, 3) float64`` positions.

    Without ``method`` it runs ``"local"`` (10 iterations) and warns (``DeprecationWarning``: 0.4 takes
    the wrapper's defaults, which ``method=None, number_of_iterations=None`` give now).

    >>> import numpy as np, open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> constrained_fairing_arrays(np.asarray(box.vertices), np.asarray(box.triangles), 5, method="local").shape
    (8, 3)
    """
    implicit = method is _OMITTED
    method, options = _check_options("local" if implicit else method, _given(locals()))
    vertices, triangles = mesh_arrays(vertices, triangles)  # copies: _fair may write to its positions
    if implicit:
        warn(
            "constrained_fairing_arrays without method= runs method='local' (10 iterations); pass "
            "method='local' to keep that, or method=None for constrained_fairing's default ('auto'), "
            "which 0.4 makes the default",
            DeprecationWarning,
        )
    conn = Connectivity(triangles, len(vertices))
    method, run, _ = _chosen(vertices, conn, method, options)
    return _fair(vertices, conn, method, options, solver, run)


def _given(arguments: dict[str, Any]) -> dict[str, Any]:
    names = ("number_of_iterations", "mu", "membrane", "boundary_weight", "smooth_boundary", "reimpose_every")
    return {name: arguments[name] for name in (*names, "progress")}


def _fair(positions, conn, method, options, solver="auto", run=None):
    # validated positions (a private copy) and the mesh's one Connectivity in, new (n, 3) positions out;
    # run: "auto"'s passes, the feature mode's first ones
    solver = as_choice(solver, SOLVERS, name="solver")  # checked for every method ("local" solves none)
    iterations, progress = options["number_of_iterations"], options["progress"]
    if run is not None and method == "features":
        return feature_denoise(
            positions, conn.triangles, progress=progress, conn=conn, run=run, solver=solver
        )
    if iterations == 0:
        return positions
    triangles = conn.triangles
    if method == "scan":
        scan = {key: options[key] for key in ("number_of_iterations", "mu", "membrane", "boundary_weight")}
        return scan_denoise(positions, triangles, solver=solver, progress=progress, conn=conn, **scan)
    if method == "features":
        return feature_denoise(
            positions, triangles, passes=iterations, progress=progress, conn=conn, solver=solver
        )
    smooth_boundary = options["smooth_boundary"]
    if method == "local":
        return fair_local(positions, conn, iterations, smooth_boundary, options["reimpose_every"], progress)
    curve = _curve(conn, smooth_boundary and bool((conn.edge_triangles != 2).any()))
    steps = Progress(progress, f"constrained fairing ({method})").over(range(iterations))
    system = GlobalSolver(conn, options["mu"], solver=solver, progress=progress)
    for _ in steps:
        known = positions.copy()
        if len(curve):
            known[curve.vertex] = curve.step(positions, curve.target(positions))
        positions = system.solve(known, positions)
    return positions


def _curve(conn: Connectivity, walk: bool) -> CurveOperator:
    # the boundary curves' operator, or an empty one
    return curve_operator(boundary_curves(conn.triangles, conn.n, conn=conn) if walk else [])


def fair_local(positions, conn, number_of_iterations, smooth_boundary, reimpose_every, progress):
    # the paper's local operator (eq. 7) on the mesh's Connectivity (its rings: the 1-ring pattern)
    curve = _curve(conn, smooth_boundary and bool(conn.rings.boundary.any()))
    # E3 @ X0 is formed during the assembly; E3 itself is kept only when the targets are re-taken
    op = local_operator(conn, positions0=positions, keep_constraint=reimpose_every is not None)
    constant = op.initial
    from .._block_kernel import empty_small_pages  # compiled by the package's build: imported where used

    spare, work = (empty_small_pages(positions.shape) for _ in range(2))
    result = positions
    curve_target = curve.target(positions)
    steps = Progress(progress, "constrained fairing (local)").over(range(number_of_iterations))
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
    return_report: bool = False,
) -> MeshT | tuple[MeshT, FairingReport]:
    """Remove noise from a mesh while holding its triangle barycenters (Liu et al. 2001).

    ``"auto"`` (the default, every weight measured) runs ``"features"``, which keeps creases, where its
    passes reach their cap (flat pieces cut by creases) and ``"scan"``, made for raw range scans and
    independent noise, elsewhere (``return_report=True`` says which). ``"local"`` and
    ``"global"`` are the paper's operators (eq. 7, eq. 5). Docs: ``docs/algorithms/constrained_fairing.rst``, ``features.rst``.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Any ``(n, 3)`` vertices, ``(m, 3)`` triangles (non-manifold, several components).
    number_of_iterations : int or None
        Local iterations or global solves (``None``: 10); ``"scan"``: None, 0 or 1 (one solve);
        ``"features"``: filter passes (``None``: measured). 0 returns an unchanged copy.
    method : {"scan", "local", "global", "features", "auto"} or None
        ``None``: ``"auto"``, or ``"local"`` when ``number_of_iterations`` or ``reimpose_every`` is given.
        ``"auto"`` takes the scan energy's options; a weight of it given runs ``"scan"``.
    mu : float or None
        ``"scan"`` and ``"global"``: barycenter penalty weight (``None``: measured; ``DEFAULT_MU``).
    membrane, boundary_weight : float or None
        ``"scan"`` only: membrane weight ``>= 0`` and rim triangles' weight ``> 0`` (``None``: measured).
    smooth_boundary : bool
        Fair the boundary loops (True) or hold them (``"local"``, ``"global"``; others need True).
    reimpose_every : int or None
        ``"local"`` only: re-take the barycenter targets every this many iterations.
    progress : bool
        Show a progress bar.
    solver : {"auto", "cholmod", "iterative"}
        How ``"scan"``, ``"global"`` and the feature mode's scan-energy start solve their system (see
        :class:`~o3d_lsmesh.SPDSolver`).
    return_report : bool
        Also return a :class:`FairingReport` (the method that ran, ``"auto"``'s feature passes).

    Returns
    -------
    mesh or (mesh, FairingReport)
        A new mesh of the input's kind, same triangles, attributes kept, normals recomputed.

    Raises
    ------
    TypeError
        An argument of the wrong type.
    ValueError
        A value out of range, an option of another method, an invalid mesh (non-manifold edges and
        vertices, pinched boundaries and several components are handled, not refused).

    Examples
    --------
    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=20)
    >>> len(constrained_fairing(sphere).vertices) == len(sphere.vertices)
    True
    >>> constrained_fairing(sphere, return_report=True)[1].method  # no creases
    'scan'
    """
    method, options = _check_options(method, _given(locals()))
    report = as_bool(return_report, name="return_report")
    # read_mesh's vertices are a private copy: _fair may write to them; the local path only reads the
    # triangles, so it takes Open3D's own int32 array (no int64 copy, no cast back)
    data = read_mesh(mesh, weld=True, narrow=method == "local")
    conn = Connectivity(data.triangles, len(data.vertices))
    method, run, passes = _chosen(data.vertices, conn, method, options)
    out = new_mesh(data, _fair(data.vertices, conn, method, options, solver, run))
    return (out, FairingReport(method, passes)) if report else out
