"""Add o3d_lsmesh operations as methods of Open3D's two triangle-mesh classes: ``o3d_lsmesh.register()``.

Nothing happens at import; calling :func:`register` again is harmless. Each method returns a new mesh
of the caller's kind and chains with Open3D's own, e.g.
``mesh.remove_duplicated_vertices().filter_smooth_constrained(10)``. Each carries a marker attribute,
so :func:`register` recognizes its own methods and refuses to replace one Open3D defines.
"""

from __future__ import annotations

import importlib
import inspect
import textwrap
import threading
from typing import Any, Callable

from .._o3d.io import mesh_classes

__all__ = ["METHOD_NAMES", "register", "registered_methods", "unregister"]

_MARKER = "__o3d_lsmesh_method__"
_LOCK = threading.Lock()


def _approximate_mesh(mesh: Any, count: int, **kwargs: Any) -> Any:
    """:func:`o3d_lsmesh.approximate`'s mesh alone, so that calls chain."""
    from ..lsmesh.selection import approximate

    return approximate(mesh, count, **kwargs)[0]


#: method name: the public function of o3d_lsmesh it calls (its signature, ``self`` for ``mesh``, and
#: the first line of its docstring, then the note below if any, make the method's)
_METHODS = {
    "filter_smooth_constrained": "constrained_fairing",
    "filter_smooth_multiresolution": "multiresolution_fairing",
    "filter_smooth_boundary_curves": "smooth_boundary_curves",
    "ls_mesh": "ls_mesh",
    "reconstruct_geometry": "reconstruct_geometry",
    "approximate_ls": "approximate",
    "decode_geometry": "decode_geometry",
    "fill_holes_faired": "fill_holes",
}
_NOTES = {
    "filter_smooth_constrained": '``mu`` is the weight of the barycenter penalty (method "global" or '
    '"scan"), not the Taubin factor of Open3D\'s ``filter_smooth_taubin(mu=)``.',
    "approximate_ls": "The mesh only, so that calls chain (:func:`o3d_lsmesh.approximate` returns the "
    "selected indices too).",
}

#: Names that :func:`register` adds to both mesh classes.
METHOD_NAMES: tuple[str, ...] = tuple(_METHODS)


def _is_ours(value: Any) -> bool:
    return getattr(value, _MARKER, False) is True


def _method(name: str, cls: type) -> Callable[..., Any]:
    # A fresh function object per class so that __qualname__ and the marker
    # describe where it lives, and unregister() can tell it apart.
    public = _METHODS[name]
    target = getattr(importlib.import_module("o3d_lsmesh"), public)
    summary = " ".join([(inspect.getdoc(target) or "").split("\n")[0], _NOTES.get(name, "")]).strip()
    function = _approximate_mesh if name == "approximate_ls" else target

    def method(self: Any, *args: Any, **kwargs: Any) -> Any:
        return function(self, *args, **kwargs)

    method.__name__ = name
    method.__qualname__ = f"{cls.__qualname__}.{name}"
    method.__module__ = __name__
    method.__doc__ = textwrap.fill(summary, 79) + textwrap.fill(
        f"Options and errors as :func:`o3d_lsmesh.{public}` (``self`` is its ``mesh``); returns a new "
        "mesh of the caller's kind.",
        79,
        initial_indent="\n\n",
    )
    signature = inspect.signature(target)
    first, *rest = signature.parameters.values()
    returns = "MeshT" if name == "approximate_ls" else signature.return_annotation
    method.__signature__ = signature.replace(  # type: ignore[attr-defined]
        parameters=[first.replace(name="self"), *rest], return_annotation=returns
    )
    setattr(method, _MARKER, True)
    return method


def register() -> tuple[str, ...]:
    """Add o3d_lsmesh's operations as methods of both Open3D triangle-mesh classes.

    Adds, to ``open3d.geometry.TriangleMesh`` and
    ``open3d.t.geometry.TriangleMesh``:

    =========================================  ==================================================
    ``filter_smooth_constrained(n, **kw)``     :func:`o3d_lsmesh.fairing.constrained_fairing`
    ``filter_smooth_multiresolution(level)``   :func:`o3d_lsmesh.fairing.multiresolution_fairing`
    ``filter_smooth_boundary_curves(n=10)``    :func:`o3d_lsmesh.fairing.smooth_boundary_curves`
    ``ls_mesh(indices, positions=None)``       :func:`o3d_lsmesh.ls_mesh`
    ``reconstruct_geometry(unknown)``          :func:`o3d_lsmesh.reconstruct_geometry`
    ``approximate_ls(count, **kw)``            :func:`o3d_lsmesh.approximate` (mesh only)
    ``decode_geometry(data, anchors=None)``    :func:`o3d_lsmesh.decode_geometry`
    ``fill_holes_faired(**kw)``                :func:`o3d_lsmesh.fill_holes`
    =========================================  ==================================================

    Each has its function's signature (``self`` for ``mesh``) and returns a new mesh of the
    caller's kind; a second call re-installs the same methods.

    Returns
    -------
    tuple of str
        The method names now present on both classes.

    Raises
    ------
    RuntimeError
        Open3D already defines one of these names itself; nothing is then changed.

    Examples
    --------
    >>> import open3d as o3d
    >>> names = register()
    >>> len(o3d.geometry.TriangleMesh.create_sphere(resolution=10).ls_mesh([0, 10, 50]).vertices)
    182
    >>> unregister()
    """
    with _LOCK:
        classes = mesh_classes()
        for cls in classes:
            for name in _METHODS:
                existing = cls.__dict__.get(name)
                if existing is not None and not _is_ours(existing):
                    raise RuntimeError(
                        f"{cls.__module__}.{cls.__qualname__} already defines {name!r}; "
                        "o3d_lsmesh.register() will not replace an Open3D method"
                    )
        for cls in classes:
            for name in _METHODS:
                setattr(cls, name, _method(name, cls))
    return METHOD_NAMES


def unregister() -> None:
    """Remove the methods :func:`register` added (and nothing else). Harmless if none are there."""
    with _LOCK:
        for cls in mesh_classes():
            for name in _METHODS:
                if _is_ours(cls.__dict__.get(name)):
                    delattr(cls, name)


def registered_methods() -> dict[str, tuple[str, ...]]:
    """The o3d_lsmesh method names currently installed on each Open3D mesh class, keyed by class path."""
    return {
        f"{cls.__module__}.{cls.__qualname__}": tuple(n for n in _METHODS if _is_ours(cls.__dict__.get(n)))
        for cls in mesh_classes()
    }
