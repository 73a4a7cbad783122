"""A short tour of an installed wheel (``make wheel``, cibuildwheel's test): the package comes from the
install, its compiled kernels load, and the default denoiser (the compiled CG path above 5k
vertices), hole filling and an LS mesh give what they should. ``--no-compiler``: also check that no C
compiler is on PATH (the wheel must not need one).

    python tests/wheel_tour.py [--no-compiler]
"""

import importlib
import shutil
import sys

import numpy as np
import open3d as o3d

import o3d_lsmesh

assert "site-packages" in o3d_lsmesh.__file__, f"not the installed package: {o3d_lsmesh.__file__}"
if "--no-compiler" in sys.argv:
    found = [name for name in ("gcc", "cc", "clang") if shutil.which(name)]
    assert not found, f"a compiler is on PATH: {found}"
for kernel in (
    "o3d_lsmesh.hierarchy.collapse",
    "o3d_lsmesh._triangulation_kernel",
    "o3d_lsmesh._patch_kernel",
    "o3d_lsmesh._block_kernel",
    "o3d_lsmesh._feature_kernel",
    "o3d_lsmesh._scan_kernel",
):
    print("loaded", importlib.import_module(kernel).__file__)

# a noisy unit sphere of 6.4k vertices: the denoiser brings its radii closer to 1
sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=80)
vertices = np.asarray(sphere.vertices)
noise = np.random.default_rng(0).normal(0.0, 0.01, (len(vertices), 1))
noisy = o3d.geometry.TriangleMesh(
    o3d.utility.Vector3dVector(vertices * (1.0 + noise)), o3d.utility.Vector3iVector(sphere.triangles)
)
faired = o3d_lsmesh.constrained_fairing(noisy)
before = np.abs(np.linalg.norm(np.asarray(noisy.vertices), axis=1) - 1.0).mean()
after = np.abs(np.linalg.norm(np.asarray(faired.vertices), axis=1) - 1.0).mean()
print(f"constrained_fairing: {len(vertices)} vertices, mean |radius - 1| {before:.4f} -> {after:.4f}")
assert after < 0.5 * before

# a cap cut off the sphere (its only border: closed on request) is filled near the sphere
cut = o3d.geometry.TriangleMesh(sphere)
centres = np.asarray(sphere.vertices)[np.asarray(sphere.triangles)].mean(axis=1)
cut.remove_triangles_by_mask(centres[:, 2] > 0.9)
cut.remove_unreferenced_vertices()
filled = o3d_lsmesh.fill_holes(cut, fill_border=True)
radii = np.linalg.norm(np.asarray(filled.vertices), axis=1)
print(f"fill_holes: watertight {filled.is_watertight()}, radii {radii.min():.3f}-{radii.max():.3f}")
assert not cut.is_watertight() and filled.is_watertight()
assert 0.8 < radii.min() and radii.max() < 1.05

# an LS mesh through every seventh vertex of the sphere: the anchors kept, the rest near the sphere
anchors = np.arange(0, len(vertices), 7)
rebuilt = o3d_lsmesh.ls_mesh(sphere, anchors, interpolate=True)
error = np.abs(np.asarray(rebuilt.vertices)[anchors] - vertices[anchors]).max()
radii = np.linalg.norm(np.asarray(rebuilt.vertices), axis=1)
print(f"ls_mesh: {len(anchors)} anchors kept to {error:.1e}, radii {radii.min():.3f}-{radii.max():.3f}")
assert error < 1e-9 and 0.95 < radii.min() and radii.max() < 1.05
print("wheel tour: OK")
