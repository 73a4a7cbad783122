"""setup.py's compiler checks: a clear message without a compiler, OpenMP only where the compiler has it."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="the checks set CC, which MSVC ignores")
REPO = Path(__file__).resolve().parents[1]
#: the smallest extension module: what matters is how it is compiled
MODULE = """#include <Python.h>
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_block_kernel"};
PyMODINIT_FUNC PyInit__block_kernel(void) { return PyModule_Create(&module); }
"""


def _build(tmp_path: Path, compiler: str, monkeypatch):
    """Build MODULE as the block kernel with ``CC=compiler`` through setup.py's build_ext."""
    pytest.importorskip("Cython", reason="setup.py cythonizes the kernels (pip install Cython)")
    from setuptools import Distribution, Extension

    spec = importlib.util.spec_from_file_location("o3d_lsmesh_setup", REPO / "setup.py")
    assert spec is not None and spec.loader is not None
    setup = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(setup)  # not __main__: setup() does not run
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "kernel.c").write_text(MODULE)
    extension = Extension("o3d_lsmesh._block_kernel", [str(tmp_path / "kernel.c")])
    command = setup.BuildExt(Distribution({"ext_modules": [extension]}))
    command.build_lib, command.build_temp = str(tmp_path / "lib"), str(tmp_path / "temp")
    monkeypatch.setenv("CC", compiler)
    monkeypatch.delenv("LDSHARED", raising=False)
    command.ensure_finalized()
    command.run()
    return extension


def test_a_build_without_a_compiler_says_what_it_needs(tmp_path, monkeypatch):
    from setuptools.errors import CompileError

    with pytest.raises(CompileError) as error:
        _build(tmp_path, str(tmp_path / "no-such-compiler"), monkeypatch)
    message = str(error.value)
    assert message.startswith("o3d_lsmesh needs a C compiler and Python's headers to build from source")
    for hint in (
        "apt install gcc python3-dev",
        "xcode-select --install",
        "Microsoft C++ Build Tools",
        "wheel",
    ):
        assert hint in message
    assert "no-such-compiler" in message  # and what the compiler said


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc (OpenMP through -fopenmp)")
def test_openmp_only_where_the_compiler_has_it(tmp_path, monkeypatch):
    assert "-fopenmp" in _build(tmp_path / "gcc", "gcc", monkeypatch).extra_compile_args
    # a compiler that refuses -fopenmp, as Apple's clang does: the kernel is built, serially
    refusing = tmp_path / "cc-without-openmp"
    refusing.write_text('#!/bin/sh\nfor a; do [ "$a" = -fopenmp ] && exit 1; done\nexec gcc "$@"\n')
    refusing.chmod(0o755)
    serial = _build(tmp_path / "serial", str(refusing), monkeypatch)
    assert "-fopenmp" not in serial.extra_compile_args + serial.extra_link_args
    assert list((tmp_path / "serial" / "lib" / "o3d_lsmesh").glob("_block_kernel.*"))
