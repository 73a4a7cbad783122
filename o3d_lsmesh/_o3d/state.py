"""Picklable descriptions of :class:`~o3d_lsmesh._o3d.MeshData` (Open3D meshes do not pickle), from ATTRIBUTES."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import MeshData, present_attributes
from .io import legacy_mesh, open3d

__all__ = ["mesh_from_state", "mesh_state"]


def mesh_state(data: MeshData) -> dict:
    """A picklable description of ``data`` that :func:`mesh_from_state` rebuilds.

    It keeps the arrays, the kind, the weld and what :func:`~o3d_lsmesh._o3d.new_mesh` takes from
    the source (every attribute of :data:`~o3d_lsmesh._o3d.ATTRIBUTES` present, the tensor material,
    device and dtypes): :func:`~o3d_lsmesh._o3d.new_mesh` on the rebuilt data gives the same result.
    """
    state: dict[str, Any] = {
        key: getattr(data, key)
        for key in ("vertices", "triangles", "kind", "split", "split_triangles", "rows")
    }
    src = data.source
    if data.kind == "legacy":
        state["attributes"] = {row.key: _legacy_state(src, row) for row, _ in present_attributes(data)}
    elif data.kind == "tensor":
        state["device"] = str(src.vertex.positions.device)
        values = [(row.group, key, getattr(src, row.group)[key]) for row, key in present_attributes(data)]
        state["tensor"] = [
            (group, key, value.cpu().numpy().copy(), str(value.dtype)) for group, key, value in values
        ]
        state["material"] = _material_state(src.material) if src.has_valid_material() else None
    return state


def _legacy_state(src: Any, row: Any) -> Any:
    """A legacy mesh's attribute of ``row`` as plain values (normals: True, they are recomputed)."""
    if row.follows == "texture":
        return [None if texture.is_empty() else np.asarray(texture).copy() for texture in src.textures]
    return True if row.follows == "normals" else np.asarray(getattr(src, row.key)).copy()


def _material_state(material: Any) -> dict:
    """The fields of an ``open3d.visualization.Material`` (which does not pickle) as plain values."""
    return {
        "name": material.material_name,
        "scalar": dict(material.scalar_properties),
        "vector": {key: np.array(value) for key, value in material.vector_properties.items()},
        "textures": {key: image.as_tensor().numpy().copy() for key, image in material.texture_maps.items()},
    }


def _material_from_state(state: dict) -> Any:
    o3d = open3d()
    material = o3d.visualization.Material(state["name"])
    for key, value in state["scalar"].items():
        material.scalar_properties[key] = value
    for key, value in state["vector"].items():
        material.vector_properties[key] = value
    for key, value in state["textures"].items():
        material.texture_maps[key] = o3d.t.geometry.Image(o3d.core.Tensor(value))
    return material


def mesh_from_state(state: dict) -> MeshData:
    """Rebuild the :class:`~o3d_lsmesh._o3d.MeshData` described by :func:`mesh_state`, with a source of its kind."""
    from . import ATTRIBUTES

    vertices, triangles, kind = state["vertices"], state["triangles"], state["kind"]
    split, split_triangles, rows = state["split"], state["split_triangles"], state["rows"]
    # the source's own layout: a welded source's positions are its welded vertices' (they coincide)
    source_v = vertices if split is None else vertices[split]
    source_t = triangles if split_triangles is None else split_triangles
    if kind == "arrays":
        return MeshData(vertices, triangles, (source_v, source_t), kind, split, split_triangles, rows)
    o3d = open3d()
    if kind == "legacy":
        source = legacy_mesh(source_v, source_t)
        table = {row.key: row for row in ATTRIBUTES if row.kind == "legacy"}
        for key, value in state["attributes"].items():  # (in the table's order)
            row = table[key]
            if row.follows == "texture":
                source.textures = [
                    o3d.geometry.Image() if t is None else o3d.geometry.Image(t) for t in value
                ]
            elif row.follows == "normals":
                getattr(source, f"compute_{row.key}")()
            else:
                setattr(source, row.key, getattr(o3d.utility, row.vector)(value))
        return MeshData(vertices, triangles, source, kind, split, split_triangles, rows)
    device = o3d.core.Device(state["device"])
    source = o3d.t.geometry.TriangleMesh(device)
    for group, key, array, dtype in state["tensor"]:
        getattr(source, group)[key] = o3d.core.Tensor(array, device=device).to(
            getattr(o3d.core, dtype.lower())
        )
    if state["material"] is not None:
        source.material = _material_from_state(state["material"])
    return MeshData(vertices, triangles, source, kind, split, split_triangles, rows)
