"""``method="auto"``'s choice between the feature mode and the scan energy: a feature likeness measured on
the mesh alone (no reference surface), the mean over the median of the dihedral angles after the feature
mode's first passes. Docs: ``docs/algorithms/features.rst`` (choosing on the mesh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.connectivity import Connectivity
from .features import FeatureRun, pair_angles
from .scan_measure import measured_noise
from .tuning import FEATURE_LIKENESS, PROBE_PASSES_PER_NOISE

__all__ = ["FeatureProbe", "dihedral_likeness", "feature_probe"]


def dihedral_likeness(normals: np.ndarray, pairs: np.ndarray) -> float:
    """Mean over median of the angles between ``normals[pairs[:, 0]]`` and ``normals[pairs[:, 1]]``.

    ``inf`` when the median is 0 and the mean is not (flat pieces and creases), 0 without pairs or angles.

    >>> n = np.array([[0.0, 0, 1], [0, 0, 1], [0, 0, 1], [1, 0, 0]])
    >>> dihedral_likeness(n, np.array([[0, 1], [1, 2], [2, 3]]))
    inf
    """
    angle = pair_angles(normals, pairs)
    mean = float(angle.mean()) if len(angle) else 0.0
    median = float(np.median(angle)) if len(angle) else 0.0
    if median > 0.0:
        return mean / median
    return math.inf if mean > 0.0 else 0.0


@dataclass
class FeatureProbe:
    """What :func:`feature_probe` measured, and the feature mode's run it started.

    Attributes
    ----------
    likeness : float
        Mean over median of the filtered dihedral angles after ``probe_passes`` passes.
    noise : float
        The measured noise in mean edge lengths (:func:`.scan_measure.measured_noise`).
    probe_passes : int
        The probe's pass count.
    run : FeatureRun
        The feature mode after the probe's passes (:meth:`finish` takes the rest).
    """

    likeness: float
    noise: float
    probe_passes: int
    run: FeatureRun

    @property
    def features(self) -> bool:
        """Whether the default takes the feature mode (``likeness >= FEATURE_LIKENESS``)."""
        return self.likeness >= FEATURE_LIKENESS

    def finish(self, progress: bool = False) -> np.ndarray:
        """The feature mode's result, ``(n, 3)``: equal to ``feature_denoise(vertices, triangles)``."""
        if self.noise == 0.0:
            return np.array(self.run.vertices, dtype=np.float64)
        # where the mode's count ended within the probe, the run kept those positions
        return self.run.finish(None, progress)


def feature_probe(
    vertices: np.ndarray, triangles: np.ndarray, *, conn: Connectivity | None = None
) -> FeatureProbe:
    """Measure the feature likeness of a mesh (validated arrays) after the feature mode's first
    ``max(1, ceil(PROBE_PASSES_PER_NOISE sigma))`` passes, ``sigma`` the measured noise.

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box().subdivide_midpoint(number_of_iterations=3)
    >>> V, F = np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)
    >>> feature_probe(V + np.random.default_rng(0).normal(0.0, 0.02, V.shape), F).features
    True
    """
    conn = Connectivity(triangles, len(vertices)) if conn is None else conn
    noise = measured_noise(vertices, triangles, conn=conn).noise
    probe_passes = max(1, math.ceil(PROBE_PASSES_PER_NOISE * noise))
    run = FeatureRun(vertices, triangles, conn)
    for _ in range(probe_passes):
        normals = run.step()
    return FeatureProbe(dihedral_likeness(normals, run.adjacency.pairs), noise, probe_passes, run)
