"""Deprecated path of :mod:`o3d_lsmesh.core.connectivity` and :mod:`o3d_lsmesh.core.boundary` (0.2's layout;
it goes in 0.4). The former free builders are parts of :class:`~o3d_lsmesh.core.connectivity.Connectivity`."""

from ._compat import deprecated_module
from .core.connectivity import Connectivity

_PARTS = {
    "edge_structure": "edge_structure",
    "adjacency_matrix": "adjacency",
    "connected_components": "components",
    "vertex_rings": "rings",
}


def _part(attribute: str):
    return lambda triangles, n=None: getattr(Connectivity(triangles, n), attribute)


__getattr__ = deprecated_module(
    __name__,
    "o3d_lsmesh.core.connectivity",
    "o3d_lsmesh.core.boundary",
    "o3d_lsmesh.core.arrays",
    replaced={name: (_part(part), f"Connectivity(triangles, n).{part}") for name, part in _PARTS.items()},
)
