"""Build the compiled kernels (hierarchy, hole filling); everything else about the package is in setup.cfg."""

import sys

from Cython.Build import cythonize
from setuptools import Extension, setup

# -ffp-contract=off: no fused multiply-adds, so the kernel's arithmetic is the plain IEEE arithmetic
# of the reference loop in tests/_hierarchy_oracle.py (identical levels on every platform)
flags = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off"]
openmp = ["/openmp"] if sys.platform == "win32" else ["-fopenmp"]
extensions = [
    Extension(
        "o3d_lsmesh.hierarchy.collapse", ["o3d_lsmesh/hierarchy/collapse.pyx"], extra_compile_args=flags
    ),
    # hole filling's dynamic programme, refinement flips, relaxation and crossing test
    Extension("o3d_lsmesh._fill_kernel", ["o3d_lsmesh/_fill_kernel.pyx"], extra_compile_args=flags),
    # the iterative solver's block products and Gauss-Seidel sweeps, on every core (OpenMP)
    Extension(
        "o3d_lsmesh._block_kernel",
        ["o3d_lsmesh/_block_kernel.pyx"],
        extra_compile_args=flags + openmp,
        extra_link_args=openmp,
    ),
]
setup(ext_modules=cythonize(extensions, compiler_directives={"language_level": "3"}))
