"""Mesh fairing: barycenter-constrained fairing and boundary-curve smoothing and multiresolution fairing (Liu et al. 2001, sections 3 and 4)."""

from .boundary_curve import smooth_boundary_curves, smooth_boundary_curves_arrays
from .constrained import constrained_fairing, constrained_fairing_arrays
from .multiresolution import multiresolution_fairing, multiresolution_fairing_arrays

__all__ = [
    "constrained_fairing",
    "constrained_fairing_arrays",
    "multiresolution_fairing",
    "multiresolution_fairing_arrays",
    "smooth_boundary_curves",
    "smooth_boundary_curves_arrays",
]
