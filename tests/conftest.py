"""Shared fixtures: real meshes from O3D_LSMESH_DATA (default ../shared/data/meshes) and small generated ones."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import strategies as st

try:  # without scikit-sparse the suite runs on the SciPy path, as a user without it would choose
    import sksparse.cholmod  # noqa: F401
except ImportError:
    os.environ.setdefault("O3D_LSMESH_NO_CHOLMOD", "1")

REPO = Path(__file__).resolve().parents[1]
#: The directory holding the package this suite imports: the installed wheel's in `make matrix` (whose
#: compiled kernels a source tree lacks), the checkout otherwise. Subprocesses that run the package put it
#: first on their path, and run there (`python -c` and `-m` put the working directory first).
PACKAGE_HOME = str(Path(importlib.util.find_spec("o3d_lsmesh").origin).resolve().parents[1])
DATA = Path(os.environ.get("O3D_LSMESH_DATA", REPO.parent / "shared" / "data" / "meshes"))
SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", REPO.parent / "shared" / "data" / "scans"))
# a scan in world coordinates (UTM easting, northing, height in metres), where georeferenced scans lie
WORLD = np.array([5.1e5, 4.2e6, 120.0])


def welded_vertices(V) -> np.ndarray:
    """Each vertex's first copy at exactly equal coordinates, by a plain dictionary (-0.0 == 0.0 as keys):
    the package's weld, written independently of ``o3d_lsmesh._o3d.weld_map``."""
    first: dict = {}
    return np.array([first.setdefault(tuple(row + 0.0), i) for i, row in enumerate(np.asarray(V))])


def welded_surface(V, F) -> tuple[np.ndarray, np.ndarray]:
    """(each vertex's first copy, the triangles on first copies): the surface the package's operations
    see, the triangles that lose a corner (zero-area needles) left out, by plain loops; nothing welded
    where every triangle would lose one."""
    to = welded_vertices(V)
    kept = [[int(to[v]) for v in t] for t in np.asarray(F) if len({int(to[v]) for v in t}) == 3]
    if not kept:
        return np.arange(len(V)), np.asarray(F, dtype=np.int64)
    return to, np.array(kept, dtype=np.int64)


def load_mesh(name: str):
    """Read ``name`` (e.g. ``"bunny.ply"``) from the data folder, or skip the test with the reason."""
    path = DATA / name
    if not path.exists():
        pytest.skip(f"real mesh {name} not found in {DATA} (set O3D_LSMESH_DATA to the meshes folder)")
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(str(path))
    if len(mesh.triangles) == 0:
        pytest.skip(f"{path} could not be read as a triangle mesh")
    return mesh


def grid(nx: int = 8, ny: int = 8, *, z=None):
    """A regular triangulated grid in the unit square as ``(vertices, triangles)``; ``z`` maps (x, y) to heights."""
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="xy")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size) if z is None else z(x, y).ravel()], axis=1)
    index = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = (
        index[:-1, :-1].ravel(),
        index[:-1, 1:].ravel(),
        index[1:, :-1].ravel(),
        index[1:, 1:].ravel(),
    )
    triangles = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return vertices, triangles.astype(np.int64)


@pytest.fixture
def sphere():
    import open3d as o3d

    return o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=12)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def triangle_soups(max_vertices: int = 12, max_triangles: int = 25):
    """Hypothesis strategy of ``(n, triangles)``: any triangles without a repeated vertex, so
    non-manifold edges, mixed orientations, repeated triangles and unreferenced vertices."""
    return st.integers(3, max_vertices).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.lists(st.permutations(range(n)).map(lambda p: p[:3]), min_size=1, max_size=max_triangles),
        )
    )


def load_scan(name: str):
    """``(vertices, triangles)`` of the raw scan ``name`` in ``SCANS``, or skip the test with the reason."""
    path = SCANS / name
    if not path.exists():
        pytest.skip(f"raw scan {name} not found in {SCANS} (set O3D_LSMESH_SCANS to the scans folder)")
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)
