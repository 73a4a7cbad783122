"""The package as pip users get it: a complete sdist, a wheel with full metadata, tested version bounds.

``make matrix`` builds the sdist and the wheel from it, installs the wheel in one venv with the oldest
releases setup.cfg allows and in one with the newest, and runs the unpacked sdist's own tests there; it
tells these tests where the built files are (``O3D_LSMESH_DIST``), which releases it pinned
(``O3D_LSMESH_PINS``) and that the package must come from the install (``O3D_LSMESH_INSTALLED``).
From a git checkout (``make test``) the sdist is built here and compared with ``git ls-files``.
"""

from __future__ import annotations

import configparser
import email
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from email.message import Message
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet
from packaging.version import Version

REPO = Path(__file__).resolve().parents[1]
#: tracked files an sdist does not need: CI's script and git's own
NOT_IN_SDIST = {".ci/run", ".gitignore"}
#: what the sdist's own tests, examples and docs read
SDIST_MUST_HOLD = [
    "LICENSE",
    "README.md",
    "CITATION.cff",
    "Makefile",
    "setup.cfg",
    "setup.py",
    "pyproject.toml",
    "MANIFEST.in",
    "o3d_lsmesh/hierarchy/collapse.pyx",
    "o3d_lsmesh/_triangulation_kernel.pyx",
    "o3d_lsmesh/_patch_kernel.pyx",
    "o3d_lsmesh/_fill_common.pxd",
    "o3d_lsmesh/_block_kernel.pyx",
    "o3d_lsmesh/_feature_kernel.pyx",
    "o3d_lsmesh/_parallel.pxd",
    "o3d_lsmesh/py.typed",
    "tests/conftest.py",
    "tests/test_packaging.py",
    "examples/01_denoise_scan.py",
    "examples/GALLERY_HEADER.rst",
    "docs/conf.py",
    "docs/images/01_denoise_scan.png",
    "benchmarks/results/denoise.md",
]


def _setup_cfg() -> configparser.ConfigParser:
    config = configparser.ConfigParser()
    config.read(REPO / "setup.cfg")
    return config


def _requirements(*extras: str) -> list[Requirement]:
    """install_requires, then the named extras' requirements."""
    config = _setup_cfg()
    lines = [config["options"]["install_requires"], *(config["options.extras_require"][e] for e in extras)]
    lines = "\n".join(lines).strip().splitlines()
    return [Requirement(line.strip()) for line in lines if line.strip() and not line.strip().startswith("#")]


def _make_variable(name: str) -> str:
    """A ``NAME := value`` line of the Makefile, with backslash continuations joined."""
    text = (REPO / "Makefile").read_text().replace("\\\n", " ")
    match = re.search(rf"^{name}\s*:?=(.*)$", text, flags=re.MULTILINE)
    assert match, f"{name} not set in the Makefile"
    return match.group(1).strip()


def _lower_bound(requirement: Requirement) -> Version | None:
    bounds = [Version(s.version) for s in requirement.specifier if s.operator == ">="]
    return max(bounds) if bounds else None


def _build_sdist(out: Path) -> Path:
    pytest.importorskip(
        "build", reason="the sdist check needs `build` (pip install build; in the [test] extra)"
    )
    pytest.importorskip("Cython", reason="setup.py cythonizes the kernel (pip install Cython)")
    # --skip-dependency-check: an sdist needs setuptools and Cython (setup.py runs), not `wheel`
    command = [sys.executable, "-m", "build", "--sdist", "--no-isolation", "--skip-dependency-check"]
    done = subprocess.run(
        [*command, "--outdir", str(out), str(REPO)], capture_output=True, text=True, cwd=REPO
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    (sdist,) = out.glob("*.tar.gz")
    return sdist


def _dist_dir() -> Path | None:
    value = os.environ.get("O3D_LSMESH_DIST")
    return Path(value) if value else None


@pytest.fixture(scope="module")
def sdist(tmp_path_factory) -> Path:
    """The sdist ``make matrix`` built, or one built here from the checkout."""
    dist = _dist_dir()
    if dist is not None:
        (path,) = dist.glob("*.tar.gz")
        return path
    return _build_sdist(tmp_path_factory.mktemp("sdist"))


def _sdist_names(sdist: Path) -> set[str]:
    with tarfile.open(sdist) as archive:
        names = {member.name for member in archive.getmembers() if member.isfile()}
    # o3d_lsmesh-0.2.0/tests/conftest.py -> tests/conftest.py
    return {name.split("/", 1)[1] for name in names if "/" in name}


def test_sdist_holds_what_its_tests_examples_and_docs_read(sdist):
    names = _sdist_names(sdist)
    missing = [name for name in SDIST_MUST_HOLD if name not in names]
    assert not missing, f"missing from {sdist.name}: {missing}"
    assert not [n for n in names if n.endswith((".so", ".pyd", ".pyc"))], "build products in the sdist"


def test_sdist_holds_every_tracked_file(sdist):
    """Every file git tracks is in the sdist (but CI's script and .gitignore)."""
    if not (REPO / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout (an unpacked sdist has no `git ls-files` to compare with)")
    tracked = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True)
    tracked_names = {name for name in tracked.stdout.splitlines() if (REPO / name).is_file()}
    missing = sorted(tracked_names - _sdist_names(sdist) - NOT_IN_SDIST)
    assert not missing, f"tracked files missing from the sdist (MANIFEST.in): {missing}"


def _metadata_of_sdist(sdist: Path) -> Message:
    with tarfile.open(sdist) as archive:
        member = next(
            m for m in archive.getmembers() if m.name.count("/") == 1 and m.name.endswith("/PKG-INFO")
        )
        handle = archive.extractfile(member)
        assert handle is not None
        return email.message_from_bytes(handle.read())


def _check_metadata(metadata: Message, where: str, *, requires_dist: bool) -> None:
    assert metadata["Name"].replace("-", "_") == "o3d_lsmesh", where
    assert metadata["Author"], f"{where}: no author"
    assert metadata["License"] == "MIT" or metadata["License-Expression"] == "MIT", where
    assert metadata.get_all("License-File") == ["LICENSE"], where
    classifiers = metadata.get_all("Classifier")
    assert "License :: OSI Approved :: MIT License" in classifiers, where
    assert any(c.startswith("Operating System :: ") for c in classifiers), f"{where}: no OS classifier"
    assert metadata.get_all("Project-URL"), f"{where}: no project URLs"
    # the Python classifiers are the contiguous run from Requires-Python's lower bound
    minors = sorted(int(c.rsplit(".", 1)[1]) for c in classifiers if re.fullmatch(r".*:: 3\.\d+", c))
    assert minors == list(range(minors[0], minors[-1] + 1)), f"{where}: gaps in {minors}"
    assert SpecifierSet(metadata["Requires-Python"]) == SpecifierSet(f">=3.{minors[0]}"), where
    assert metadata.get_payload().lstrip().startswith("# o3d_lsmesh"), (
        f"{where}: README is not the description"
    )
    # a wheel lists its requirements; an sdist's PKG-INFO does from setuptools 68 (before, egg-info has them)
    requires = [Requirement(r) for r in metadata.get_all("Requires-Dist") or []]
    if not requires_dist and not requires:
        return
    cholmod = [r for r in requires if r.name == "scikit-sparse" and r.marker and "cholmod" in str(r.marker)]
    assert [r.specifier for r in cholmod] == [SpecifierSet(">=0.4.16,<0.5")], where
    for optional in ("scikit-sparse", "fast-simplification"):
        assert not [r for r in requires if r.name == optional and r.marker is None], (
            f"{where}: {optional} must stay optional"
        )


def test_sdist_metadata_is_complete(sdist):
    _check_metadata(_metadata_of_sdist(sdist), sdist.name, requires_dist=False)


def test_wheel_metadata_licence_and_contents():
    dist = _dist_dir()
    if dist is None:
        pytest.skip("no wheel built: `make matrix` builds one (from the sdist) and sets O3D_LSMESH_DIST")
    (wheel,) = dist.glob("*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        (metadata_name,) = [n for n in names if n.endswith(".dist-info/METADATA")]
        metadata = email.message_from_bytes(archive.read(metadata_name))
        licences = [n for n in names if re.search(r"\.dist-info/(licenses/)?LICENSE$", n)]
        assert licences, f"no licence file in {wheel.name}"
        assert archive.read(licences[0]).decode().startswith("MIT License")
    _check_metadata(metadata, wheel.name, requires_dist=True)
    assert any(re.fullmatch(r"o3d_lsmesh/hierarchy/collapse\..*(so|pyd)", n) for n in names), (
        "no compiled kernel"
    )
    for kernel in ("_triangulation_kernel", "_patch_kernel", "_scan_kernel", "_feature_kernel"):
        assert any(re.fullmatch(rf"o3d_lsmesh/{kernel}\..*(so|pyd)", n) for n in names), f"no {kernel}"
    assert any(re.fullmatch(r"o3d_lsmesh/_block_kernel\..*(so|pyd)", n) for n in names), "no block kernel"
    assert "o3d_lsmesh/py.typed" in names
    assert not [n for n in names if n.startswith(("tests/", "benchmarks/", "examples/", "docs/"))]


def test_licence_file_is_the_declared_licence():
    assert (REPO / "LICENSE").read_text().startswith("MIT License")
    assert _setup_cfg()["metadata"]["license"] == "MIT"


def test_lower_bounds_are_the_versions_the_matrix_tests():
    """Every dependency's lower bound (and the extras' the oldest venv installs) is what ``make matrix``
    pins there (same minor release, inside the bound), so no bound claims more than was tested."""
    pins = dict(pin.split("==") for pin in _make_variable("MATRIX_LOWEST").split())
    for requirement in _requirements("simplify", "render"):
        assert requirement.name in pins, f"{requirement.name} not pinned in MATRIX_LOWEST"
        pinned = Version(pins[requirement.name])
        assert pinned in requirement.specifier, f"{requirement.name}=={pinned} outside {requirement}"
        bound = _lower_bound(requirement)
        assert bound is not None, f"{requirement} has no lower bound"
        assert pinned.release[: len(bound.release)] == bound.release, (
            f"{requirement}: the matrix tests {pinned}"
        )


def test_fast_simplification_is_an_extra_named_where_it_is_missing(monkeypatch):
    """Only from_fast_simplification needs it: without it the package and the default hierarchy work,
    and that function says which extra to install."""
    import o3d_lsmesh

    monkeypatch.setitem(sys.modules, "fast_simplification", None)  # import fails as if not installed
    from o3d_lsmesh.app.shapes import demo_mesh

    sphere = demo_mesh(3)
    assert len(o3d_lsmesh.build_hierarchy(sphere)) > 1
    with pytest.raises(ImportError, match=re.escape('pip install "o3d_lsmesh[simplify]"')):
        o3d_lsmesh.from_fast_simplification(sphere)


def test_the_venv_has_the_pinned_releases():
    """In a matrix venv, the releases installed are the ones pinned (pip did not move any)."""
    pins = os.environ.get("O3D_LSMESH_PINS")
    if not pins:
        pytest.skip("not a `make matrix` venv (O3D_LSMESH_PINS unset)")
    for pin in pins.split():
        name, version = pin.split("==")
        assert importlib.metadata.version(name) == version, name


def test_the_tests_import_the_installed_package():
    """``make matrix`` tests the wheel it installed, not the unpacked sources next to the tests."""
    if not os.environ.get("O3D_LSMESH_INSTALLED"):
        pytest.skip("the package may come from the checkout here (O3D_LSMESH_INSTALLED unset)")
    import o3d_lsmesh

    location = Path(o3d_lsmesh.__file__).resolve()
    assert REPO not in location.parents, location
    assert importlib.metadata.version("o3d_lsmesh") == o3d_lsmesh.__version__


def test_readme_states_the_tested_versions_and_every_system_package():
    """The README's Install section names the supported Python range and each dependency's lower
    bound; it and the development set-up name every apt package the Makefile installs."""
    readme = (REPO / "README.md").read_text()
    install = readme.split("## Install", 1)[1].split("\n## ", 1)[0]
    set_up = readme.split("## Install", 1)[1].split("\n## A short tour", 1)[0]
    classifiers = _setup_cfg()["metadata"]["classifiers"].split("\n")
    minors = sorted(int(c.rsplit(".", 1)[1]) for c in classifiers if re.fullmatch(r".*:: 3\.\d+", c.strip()))
    assert f"Python 3.{minors[0]}-3.{minors[-1]}" in install
    for requirement in _requirements():
        bound = _lower_bound(requirement)
        assert re.search(rf"\b{re.escape(requirement.name)} >= {re.escape(str(bound))}\b", install), (
            requirement
        )
    for variable in ("APT_PACKAGES", "DOCS_APT_PACKAGES"):
        for package in _make_variable(variable).split():
            assert re.search(rf"(?<![\w.-]){re.escape(package)}(?![\w.-])", set_up), package


def test_the_package_imports_from_a_source_tree_without_its_built_extensions(tmp_path):
    # a source checkout (or an unpacked sdist) first on sys.path shadows the installed wheel: the compiled
    # kernels are imported at first use, so everything but the hierarchy and hole filling still imports
    shutil.copytree(
        REPO / "o3d_lsmesh", tmp_path / "o3d_lsmesh", ignore=shutil.ignore_patterns("*.so", "*.pyd", "*.c")
    )
    # without an editable install's finder, which would map the extensions to the checkout's builds
    code = (
        "import sys; sys.meta_path[:] = [f for f in sys.meta_path if '__editable__' not in getattr(f, "
        "'__module__', '')]; import o3d_lsmesh, o3d_lsmesh.app.cli, o3d_lsmesh.holes; "
        "assert o3d_lsmesh.__file__.startswith(sys.argv[1]), o3d_lsmesh.__file__"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path)], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
