"""The mesh types the public functions accept and return, named once for the type checker.

They exist only while type checking (Open3D is imported here only then): import them under
``if TYPE_CHECKING:`` and use them in annotations (``from __future__ import annotations``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar, Union

if TYPE_CHECKING:
    import open3d
    from numpy.typing import ArrayLike

    #: ``open3d.geometry.TriangleMesh``
    LegacyMesh = open3d.geometry.TriangleMesh
    #: ``open3d.t.geometry.TriangleMesh``
    TensorMesh = open3d.t.geometry.TriangleMesh
    #: ``(vertices (n, 3), triangles (m, 3))``, array-likes of floats and integers
    ArrayMesh = tuple[ArrayLike, ArrayLike]
    #: either Open3D triangle mesh (the methods :func:`o3d_lsmesh.register` adds)
    Open3DMesh = Union[LegacyMesh, TensorMesh]
    #: any mesh a public function accepts
    AnyMesh = Union[LegacyMesh, TensorMesh, ArrayMesh]
    #: a mesh in, a new mesh of the same kind out
    MeshT = TypeVar("MeshT", bound=AnyMesh)
