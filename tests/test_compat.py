"""0.2's module paths (#36): each still gives its names for one release, with a DeprecationWarning naming
the new home; the names of ``o3d_lsmesh`` itself and ``python -m o3d_lsmesh.cli`` stay silent."""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import numpy as np
import pytest
from conftest import PACKAGE_HOME

import o3d_lsmesh

MOVED = [
    ("o3d_lsmesh.hole_filling", "fill_holes_arrays", "o3d_lsmesh.holes"),
    ("o3d_lsmesh.batch", "run", "o3d_lsmesh.app.batch"),
    ("o3d_lsmesh.rendering", "error_colors", "o3d_lsmesh.app.render"),
    ("o3d_lsmesh.shapes", "demo_mesh", "o3d_lsmesh.app.shapes"),
    ("o3d_lsmesh.demo", "run_demo", "o3d_lsmesh.app.demo"),
    ("o3d_lsmesh.registration", "registered_methods", "o3d_lsmesh.app.registration"),
    ("o3d_lsmesh.selection", "start_vertices", "o3d_lsmesh.lsmesh.selection"),
    ("o3d_lsmesh.encoding", "encode_geometry", "o3d_lsmesh.lsmesh.encoding"),
    ("o3d_lsmesh.spectral", "spectral_approximation", "o3d_lsmesh.lsmesh.spectral"),
    ("o3d_lsmesh.cli", "build_parser", "o3d_lsmesh.app.cli"),
    ("o3d_lsmesh.topology", "boundary_loops", "o3d_lsmesh.core.boundary"),
    ("o3d_lsmesh.topology", "halfedges", "o3d_lsmesh.core.connectivity"),
]


@pytest.mark.parametrize(("old", "name", "new"), MOVED, ids=[f"{o}.{n}" for o, n, _ in MOVED])
def test_an_old_path_gives_the_same_object_and_names_its_new_home(old, name, new):
    module = importlib.import_module(old)
    with pytest.warns(DeprecationWarning, match=rf"{old}\.{name} is deprecated: use {new}\.{name}"):
        value = getattr(module, name)
    assert value is getattr(importlib.import_module(new), name)


def test_a_name_that_never_moved_there_is_an_attribute_error():
    import o3d_lsmesh.encoding

    with pytest.raises(AttributeError, match="moved to o3d_lsmesh.lsmesh.encoding"):
        _ = o3d_lsmesh.encoding.no_such_name


@pytest.mark.parametrize(
    ("name", "part"),
    [("edge_structure", "edge_structure"), ("vertex_rings", "rings"), ("connected_components", "components")],
)
def test_topology_builders_name_the_connectivity_part_that_replaced_them(name, part):
    import o3d_lsmesh.topology
    from o3d_lsmesh.core.connectivity import Connectivity

    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]])
    with pytest.warns(DeprecationWarning, match=rf"Connectivity\(triangles, n\)\.{part}"):
        builder = getattr(o3d_lsmesh.topology, name)
    got, expected = builder(triangles, 7), getattr(Connectivity(triangles, 7), part)
    if name == "connected_components":
        assert got[0] == expected[0] == 2 and np.array_equal(got[1], expected[1])
    else:
        assert type(got) is type(expected)


def test_the_package_names_and_the_cli_module_stay_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in o3d_lsmesh.__all__:
            getattr(o3d_lsmesh, name)
        assert (
            o3d_lsmesh.metrics.vertex_error is importlib.import_module("o3d_lsmesh.app.metrics").vertex_error
        )
    done = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-m", "o3d_lsmesh.cli", "--version"],
        capture_output=True,
        text=True,
        cwd=PACKAGE_HOME,
    )
    assert done.returncode == 0 and o3d_lsmesh.__version__ in done.stdout + done.stderr, done.stderr
