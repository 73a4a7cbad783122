"""Raw-scan denoising helpers shared by the real-scan benchmarks: scans, the reference surface, peers, scores.

Error of a denoised scan = distance from each of its vertices to the
reference surface (``bunny.ply``, Open3D's ``RaycastingScene``), split into
interior and boundary vertices; the signed distance is measured along the
reference's normal at the closest point (positive outside), so that an
inward move (shrinkage) shows as a drop of the signed mean.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from _common import DATA, REPO

import open3d as o3d

SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", REPO.parent / "shared" / "data" / "scans"))
REFERENCE = "bunny.ply"


def scan_names() -> list[str]:
    return sorted(p.name for p in SCANS.glob("*.ply")) if SCANS.is_dir() else []


def load_scan(name: str):
    mesh = o3d.io.read_triangle_mesh(str(SCANS / name))
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


class Reference:
    """Closest-point queries against the reference surface."""

    def __init__(self, path: Path | None = None) -> None:
        mesh = o3d.io.read_triangle_mesh(str(path or DATA / REFERENCE))
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))

    def closest(self, points: np.ndarray):
        answer = self.scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
        return answer["points"].numpy().astype(np.float64), answer["primitive_normals"].numpy().astype(np.float64)


def boundary_vertices(triangles: np.ndarray, n: int) -> np.ndarray:
    from o3d_lsmesh.topology import boundary_halfedges

    mask = np.zeros(n, dtype=bool)
    mask[boundary_halfedges(triangles, n).ravel()] = True
    return mask


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)
    normals = np.zeros_like(vertices)
    for i in range(3):
        np.add.at(normals, triangles[:, i], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.maximum(length, 1e-300)


def score(vertices: np.ndarray, triangles: np.ndarray, reference: Reference, boundary: np.ndarray) -> dict:
    """Distances (in micrometres) of the scan's referenced vertices to the reference surface."""
    used = np.zeros(len(vertices), dtype=bool)
    used[triangles.ravel()] = True
    closest, normals = reference.closest(vertices[used])
    offset = vertices[used] - closest
    distance = np.linalg.norm(offset, axis=1) * 1e6
    signed = np.einsum("ij,ij->i", offset, normals) * 1e6
    rim = boundary[used]
    ours = vertex_normals(vertices, triangles)[used]
    angle = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", ours, normals)), 0.0, 1.0)))
    return {
        "mean": float(distance.mean()),
        "p90": float(np.percentile(distance, 90)),
        "interior": float(distance[~rim].mean()),
        "boundary": float(distance[rim].mean()) if rim.any() else float("nan"),
        "signed": float(signed.mean()),
        "signed_interior": float(signed[~rim].mean()),
        "angle": float(angle.mean()),
        "distance": distance,
    }


# ----------------------------------------------------------------------------------------------- peers


def _legacy(vertices, triangles):
    return o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))


def _o3d(kind):
    def run(vertices, triangles, k):
        mesh = _legacy(vertices, triangles)
        out = getattr(mesh, f"filter_smooth_{kind}")(number_of_iterations=k)
        return np.asarray(out.vertices)

    return run


def _meshlab(filter_name, **fixed):
    def run(vertices, triangles, k):
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=triangles.astype(np.int32)))
        if filter_name == "apply_coord_hc_laplacian_smoothing":
            for _ in range(k):  # HC has no step count: repeat it
                ms.apply_filter(filter_name)
        else:
            ms.apply_filter(filter_name, stepsmoothnum=k, **fixed)
        out = ms.current_mesh().vertex_matrix()
        if len(out) != len(vertices):
            raise RuntimeError(f"{filter_name} changed the vertex count")
        return np.asarray(out, dtype=np.float64)

    return run


def _trimesh(kind):
    def run(vertices, triangles, k):
        import trimesh
        from trimesh import smoothing

        mesh = trimesh.Trimesh(vertices.copy(), triangles.copy(), process=False)
        getattr(smoothing, f"filter_{kind}")(mesh, iterations=k)  # filters work in place
        return np.asarray(mesh.vertices, dtype=np.float64)

    return run


#: every conventional filter with the settings of its sweep (iteration counts)
PEERS = {
    "Open3D simple": (_o3d("simple"), [1, 2, 3, 4, 6]),
    "Open3D Laplacian": (_o3d("laplacian"), [1, 2, 3, 5, 8, 12, 20]),
    "Open3D Taubin": (_o3d("taubin"), [5, 10, 20, 50, 100, 200]),
    "MeshLab HC": (_meshlab("apply_coord_hc_laplacian_smoothing"), [1, 2, 3, 5, 8]),
    "MeshLab Laplacian": (_meshlab("apply_coord_laplacian_smoothing", cotangentweight=False), [1, 2, 3, 5, 8]),
    "MeshLab Taubin": (_meshlab("apply_coord_taubin_smoothing"), [5, 10, 20, 50, 100, 200]),
    "MeshLab two-step": (_meshlab("apply_coord_two_steps_smoothing"), [1, 2, 3, 5, 8]),
    "trimesh Taubin": (_trimesh("taubin"), [5, 10, 20, 50, 100, 200]),
    "trimesh Humphrey": (_trimesh("humphrey"), [2, 5, 10, 20, 50]),
}
