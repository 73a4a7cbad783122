"""Add o3d_lsmesh operations as methods of Open3D's two triangle-mesh classes.

Nothing happens at import: :func:`register` must be called explicitly, and
calling it again is harmless. Afterwards the operations chain with Open3D's
own methods, on legacy and tensor meshes alike::

    import o3d_lsmesh
    o3d_lsmesh.register()
    out = (mesh.remove_duplicated_vertices()
               .filter_smooth_constrained(10)
               .simplify_quadric_decimation(5000))

Every registered method returns a new mesh of the caller's kind (attributes as in
``o3d_lsmesh._o3d``) and never modifies the caller. Open3D's pybind11 classes accept
functions set with ``setattr``; each carries a marker attribute, so :func:`register` recognizes
its own methods (idempotence) and refuses to replace one Open3D itself defines.
"""

from __future__ import annotations

import functools
import threading
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from ._types import Open3DMesh

__all__ = ["METHOD_NAMES", "register", "registered_methods", "unregister"]

_MARKER = "__o3d_lsmesh_method__"
_LOCK = threading.Lock()


def _filter_smooth_constrained(
    self: Open3DMesh, number_of_iterations: int | None = None, **kwargs: Any
) -> Open3DMesh:
    """Barycenter-constrained fairing (Liu et al. 2001, eq. 5-7); see :func:`o3d_lsmesh.fairing.constrained_fairing`.

    Keyword options: ``method="scan"|"local"|"global"``, ``mu``, ``smooth_boundary``,
    ``reimpose_every``, ``progress``. Returns a new mesh.
    """
    from .fairing import constrained_fairing

    return constrained_fairing(self, number_of_iterations, **kwargs)


def _filter_smooth_multiresolution(self: Open3DMesh, level: int, **kwargs: Any) -> Open3DMesh:
    """Multiresolution fairing at hierarchy ``level`` (Liu et al. 2001, section 4); see :func:`o3d_lsmesh.fairing.multiresolution_fairing`.

    Keyword options: ``hierarchy``, ``number_of_iterations``, ``method``,
    ``progress``. Returns a new mesh with the caller's connectivity.
    """
    from .fairing.multiresolution import multiresolution_fairing

    return multiresolution_fairing(self, level, **kwargs)


def _filter_smooth_boundary_curves(self: Open3DMesh, number_of_iterations: int = 10) -> Open3DMesh:
    """Smooth only the boundary loops with the curve operator of Liu et al. 2001, section 3.3.

    See :func:`o3d_lsmesh.fairing.smooth_boundary_curves`. Returns a new mesh.
    """
    from .fairing import smooth_boundary_curves

    return smooth_boundary_curves(self, number_of_iterations)


def _ls_mesh(
    self: Open3DMesh, constraint_vertex_indices: Any, constraint_vertex_positions: Any = None, **kwargs: Any
) -> Open3DMesh:
    """Least-squares mesh of this connectivity near the control vertices (Sorkine and Cohen-Or 2004, eq. 3).

    See :func:`o3d_lsmesh.ls_mesh`; keyword options ``weights``,
    ``interpolate``, ``laplacian``. Returns a new mesh.
    """
    from .lsmesh import ls_mesh

    return ls_mesh(self, constraint_vertex_indices, constraint_vertex_positions, **kwargs)


def _reconstruct_geometry(self: Open3DMesh, unknown_vertex_indices: Any, **kwargs: Any) -> Open3DMesh:
    """Rebuild the positions of the vertices in ``unknown_vertex_indices`` from the rest (LS meshes, figures 5 and 8).

    See :func:`o3d_lsmesh.reconstruct_geometry`. Returns a new mesh.
    """
    from .lsmesh import reconstruct_geometry

    return reconstruct_geometry(self, unknown_vertex_indices, **kwargs)


def _approximate_ls(self: Open3DMesh, count: int, **kwargs: Any) -> Open3DMesh:
    """LS-mesh approximation from ``count`` selected control points; see :func:`o3d_lsmesh.approximate`.

    Returns only the new mesh so that calls chain; call
    :func:`o3d_lsmesh.approximate` to get the selected indices too.
    """
    from .selection import approximate

    mesh, _ = approximate(self, count, **kwargs)
    return mesh


def _decode_geometry(self: Open3DMesh, data: Any, **kwargs: Any) -> Open3DMesh:
    """Geometry decoded from ``data`` (bytes of :func:`o3d_lsmesh.encode_geometry`) on this connectivity.

    See :func:`o3d_lsmesh.decode_geometry`; keyword option ``anchors`` for
    progressive decoding. Returns a new mesh.
    """
    from .encoding import decode_geometry

    return decode_geometry(self, data, **kwargs)


def _fill_holes_faired(self: Open3DMesh, **kwargs: Any) -> Open3DMesh:
    """Close holes with triangulated, refined patches faired as LS meshes; see :func:`o3d_lsmesh.fill_holes`.

    Keyword options: ``max_hole_edges``, ``max_hole_diameter``, ``continuity``,
    ``density``, ``fill_border``, ``progress``. Returns a new mesh.
    """
    from .hole_filling import fill_holes

    return fill_holes(self, **kwargs)


_METHODS: dict[str, Callable[..., Any]] = {
    "filter_smooth_constrained": _filter_smooth_constrained,
    "filter_smooth_multiresolution": _filter_smooth_multiresolution,
    "filter_smooth_boundary_curves": _filter_smooth_boundary_curves,
    "ls_mesh": _ls_mesh,
    "reconstruct_geometry": _reconstruct_geometry,
    "approximate_ls": _approximate_ls,
    "decode_geometry": _decode_geometry,
    "fill_holes_faired": _fill_holes_faired,
}

#: Names that :func:`register` adds to both mesh classes.
METHOD_NAMES: tuple[str, ...] = tuple(_METHODS)


def _classes() -> tuple[type, type]:
    from ._o3d import open3d

    o3d = open3d()
    return o3d.geometry.TriangleMesh, o3d.t.geometry.TriangleMesh


def _is_ours(value: Any) -> bool:
    return getattr(value, _MARKER, False) is True


def _method(name: str, function: Callable[..., Any], cls: type) -> Callable[..., Any]:
    # A fresh function object per class so that __qualname__ and the marker
    # describe where it lives, and unregister() can tell it apart.
    def method(self: Any, *args: Any, **kwargs: Any) -> Any:
        return function(self, *args, **kwargs)

    method.__name__ = name
    method.__qualname__ = f"{cls.__qualname__}.{name}"
    method.__module__ = __name__
    # the docstring, and __wrapped__ so that inspect.signature() shows the real parameters
    functools.update_wrapper(method, function, assigned=("__doc__",), updated=())
    setattr(method, _MARKER, True)
    return method


def register() -> tuple[str, ...]:
    """Add o3d_lsmesh's operations as methods of both Open3D triangle-mesh classes.

    Adds, to ``open3d.geometry.TriangleMesh`` and
    ``open3d.t.geometry.TriangleMesh``:

    =========================================  ==================================================
    ``filter_smooth_constrained(n=10, **kw)``  :func:`o3d_lsmesh.fairing.constrained_fairing`
    ``filter_smooth_multiresolution(level)``   :func:`o3d_lsmesh.fairing.multiresolution_fairing`
    ``filter_smooth_boundary_curves(n=10)``    :func:`o3d_lsmesh.fairing.smooth_boundary_curves`
    ``ls_mesh(indices, positions=None)``       :func:`o3d_lsmesh.ls_mesh`
    ``reconstruct_geometry(unknown)``          :func:`o3d_lsmesh.reconstruct_geometry`
    ``approximate_ls(count, **kw)``            :func:`o3d_lsmesh.approximate` (mesh only)
    ``decode_geometry(data, anchors=None)``    :func:`o3d_lsmesh.decode_geometry`
    ``fill_holes_faired(**kw)``                :func:`o3d_lsmesh.fill_holes`
    =========================================  ==================================================

    Each returns a new mesh of the caller's kind. Importing o3d_lsmesh changes nothing;
    a second call re-installs the same methods.

    Returns
    -------
    tuple of str
        The method names now present on both classes.

    Raises
    ------
    RuntimeError
        Open3D already defines one of these names itself (a future Open3D
        version); nothing is then changed.

    Examples
    --------
    >>> import open3d as o3d
    >>> from o3d_lsmesh.registration import register, unregister  # also exported as o3d_lsmesh.register
    >>> names = register()
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> out = sphere.ls_mesh([0, 10, 50], weights=5.0)
    >>> out is sphere, len(out.vertices) == len(sphere.vertices)
    (False, True)
    >>> unregister()
    """
    with _LOCK:
        classes = _classes()
        for cls in classes:
            for name in _METHODS:
                existing = cls.__dict__.get(name)
                if existing is not None and not _is_ours(existing):
                    raise RuntimeError(
                        f"{cls.__module__}.{cls.__qualname__} already defines {name!r}; "
                        "o3d_lsmesh.register() will not replace an Open3D method"
                    )
        for cls in classes:
            for name, function in _METHODS.items():
                setattr(cls, name, _method(name, function, cls))
    return METHOD_NAMES


def unregister() -> None:
    """Remove the methods :func:`register` added (and nothing else). Harmless if none are there."""
    with _LOCK:
        for cls in _classes():
            for name in _METHODS:
                if _is_ours(cls.__dict__.get(name)):
                    delattr(cls, name)


def registered_methods() -> dict[str, tuple[str, ...]]:
    """The o3d_lsmesh method names currently installed on each Open3D mesh class, keyed by class path."""
    return {
        f"{cls.__module__}.{cls.__qualname__}": tuple(n for n in _METHODS if _is_ours(cls.__dict__.get(n)))
        for cls in _classes()
    }
