"""Build the compiled kernels (hierarchy, hole filling); everything else about the package is in setup.cfg."""

import os
import sys
import tempfile

from Cython.Build import cythonize
from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CCompilerError, CompileError, PlatformError

# -ffp-contract=off: no fused multiply-adds, so the kernel's arithmetic is the plain IEEE arithmetic
# of the reference loop in tests/_hierarchy_oracle.py (identical levels on every platform)
flags = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off"]
OPENMP = ["/openmp"] if sys.platform == "win32" else ["-fopenmp"]
#: compiles and links only where the compiler has OpenMP (not Apple's clang)
OPENMP_PROBE = "#include <omp.h>\nint main(void) { return omp_get_max_threads() > 0 ? 0 : 1; }\n"


def no_compiler_message(error: BaseException) -> str:
    """What a build from source needs, said where the compiler (or Python's headers) is missing."""
    return (
        "o3d_lsmesh needs a C compiler and Python's headers to build from source: "
        "`apt install gcc python3-dev` (Debian/Ubuntu), `dnf install gcc python3-devel` (Fedora), "
        "`xcode-select --install` (macOS), or the Microsoft C++ Build Tools (Windows); "
        "or install a wheel (`pip install --only-binary o3d_lsmesh o3d_lsmesh`). "
        f"The compiler said: {error}"
    )


class BuildExt(build_ext):
    """Check the compiler once before the kernels: say what is missing, and use OpenMP where it exists
    (the block and feature kernels' loops then run serially, with the same results: they never depend on
    threads)."""

    def _build(self, source: str, args: list[str], *, link: bool) -> None:
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "probe.c")
            with open(path, "w") as handle:
                handle.write(source)
            objects = self.compiler.compile([path], output_dir=folder, extra_postargs=args)
            if link:
                self.compiler.link_executable(objects, "probe", output_dir=folder, extra_postargs=args)

    def build_extensions(self) -> None:
        try:
            self._build("#include <Python.h>\n", [], link=False)
        except (CCompilerError, PlatformError, OSError) as error:
            raise CompileError(no_compiler_message(error)) from error
        try:  # OpenMP needs its header at compile time and its runtime at link time
            self._build(OPENMP_PROBE, OPENMP, link=True)
            openmp = OPENMP
        except (CCompilerError, OSError):
            openmp = []
        print(f"o3d_lsmesh: OpenMP {' '.join(openmp) if openmp else 'not available: serial kernels'}")
        for extension in self.extensions:
            if extension.name in ("o3d_lsmesh._block_kernel", "o3d_lsmesh._feature_kernel"):
                extension.extra_compile_args += openmp
                extension.extra_link_args += openmp
        super().build_extensions()


extensions = [
    Extension(
        "o3d_lsmesh.hierarchy.collapse", ["o3d_lsmesh/hierarchy/collapse.pyx"], extra_compile_args=flags
    ),
    # hole filling's loops, in two (sharing _fill_common.pxd): Liepa's programme, the refinement's splits
    # and flips, a loop's geometry; then the fairing's local mesh and system, the relaxation, the crossings
    Extension(
        "o3d_lsmesh._triangulation_kernel", ["o3d_lsmesh/_triangulation_kernel.pyx"], extra_compile_args=flags
    ),
    Extension("o3d_lsmesh._patch_kernel", ["o3d_lsmesh/_patch_kernel.pyx"], extra_compile_args=flags),
    # the iterative solver's block products and Gauss-Seidel sweeps, on every core where the compiler
    # has OpenMP (BuildExt adds the flag)
    Extension("o3d_lsmesh._block_kernel", ["o3d_lsmesh/_block_kernel.pyx"], extra_compile_args=list(flags)),
    # the feature mode's loops over each face's ring of faces and Sun's vertex steps, on every core likewise
    # (sharing _parallel.pxd's thread rule with the block kernel)
    Extension(
        "o3d_lsmesh._feature_kernel", ["o3d_lsmesh/_feature_kernel.pyx"], extra_compile_args=list(flags)
    ),
    # the scan default's serial loops (the connectivity's half-edge grouping)
    Extension("o3d_lsmesh._scan_kernel", ["o3d_lsmesh/_scan_kernel.pyx"], extra_compile_args=flags),
]
if __name__ == "__main__":
    setup(
        ext_modules=cythonize(extensions, compiler_directives={"language_level": "3"}),
        cmdclass={"build_ext": BuildExt},
    )
