"""Picture of the boundary-curve page: an open noisy surface faired with and without boundary fairing.

The built-in blob with its top cap cut off (a jagged boundary loop, as a
scan's silhouette is) and seeded noise, then constrained fairing with
``smooth_boundary=False`` and ``True``. Writes ``docs/images/boundary_curves.png``::

    python docs/pictures/boundary_curves.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import open3d as o3d

from o3d_lsmesh import constrained_fairing, render
from o3d_lsmesh.app.shapes import add_noise, demo_mesh, mean_edge_length

OUT = Path(__file__).resolve().parents[1] / "images" / "boundary_curves.png"


def main() -> int:
    clean = demo_mesh(5)
    noisy = add_noise(clean, 0.3 * mean_edge_length(clean), seed=11)
    vertices = np.asarray(noisy.vertices)
    triangles = np.asarray(noisy.triangles)
    # Cut the cap above z = 0.2 (of the noisy positions, so the cut is jagged).
    keep = ~(vertices[triangles, 2] > 0.2).any(axis=1)
    cut = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles[keep])
    )
    cut = cut.remove_unreferenced_vertices()
    plain = constrained_fairing(cut, 20, method="local", smooth_boundary=False)
    faired = constrained_fairing(cut, 20, method="local", smooth_boundary=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    titles = ["open noisy input", "local fairing, boundary held", "with boundary curves faired"]
    render([cut, plain, faired], OUT, width=360, height=360, view_direction=(0.0, -1.0, 0.35), titles=titles)
    print(f"picture: {OUT} (open noisy input | fairing, boundary held | fairing with boundary curves)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
