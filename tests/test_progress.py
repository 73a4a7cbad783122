"""Progress bars: every long operation takes ``progress=`` (a bool) and its bars end at their totals."""

import io

import numpy as np
import open3d as o3d
import pytest
import scipy.sparse as sp
import tqdm.auto
import tqdm.std
from conftest import grid

from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.core.progress import Progress, close_all
from o3d_lsmesh.core.solve import SPDSolver
from o3d_lsmesh.fairing import constrained_fairing
from o3d_lsmesh.lsmesh import ls_mesh, reconstruct_geometry
from o3d_lsmesh.lsmesh.encoding import decode_geometry, encode_geometry, iter_decode_geometry
from o3d_lsmesh.lsmesh.selection import approximate, select_control_points
from o3d_lsmesh.lsmesh.spectral import spectral_approximation


def pieces():
    """Three bumpy grids side by side: a mesh of 3 components, 120 vertices."""
    vertices, triangles, offset = [], [], 0
    for i, (nx, ny) in enumerate(((8, 8), (7, 6), (4, 4))):
        V, F = grid(nx, ny, z=lambda x, y: 0.2 * np.sin(5 * x) * np.cos(4 * y))
        vertices.append(V + [1.5 * i, 0.0, 0.0])
        triangles.append(F + offset)
        offset += len(V)
    return np.vstack(vertices), np.vstack(triangles)


@pytest.fixture
def bars(monkeypatch):
    """Route every tqdm bar the package opens to a StringIO and record it."""
    stream = io.StringIO()
    made = []

    class Recording(tqdm.std.tqdm):
        def __init__(self, *args, **kwargs):
            kwargs["file"] = stream
            kwargs["mininterval"] = 0
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(tqdm.auto, "tqdm", Recording)
    return made, stream


def assert_complete(made, stream, *, count=None):
    assert made, "no progress bar was shown"
    for bar in made:
        assert bar.total is not None and bar.total > 0
        assert bar.n == bar.total, f"{bar.desc}: ended at {bar.n}/{bar.total}"
    if count is not None:
        assert f"{count}/{count}" in stream.getvalue()


@pytest.mark.parametrize("method", ["greedy", "combined"])
def test_selection_bar_counts_the_component_seeds(bars, method):
    made, stream = bars
    V, F = pieces()
    assert Connectivity(F, len(V)).components[0] == 3
    _, indices = approximate((V, F), 40, method=method, progress=True)
    assert len(indices) == 40
    assert_complete(made, stream, count=40)
    assert [bar.total for bar in made] == [40]
    made.clear()
    select_control_points((V, F), 25, method=method, progress=True)
    assert_complete(made, stream, count=25)


def test_approximate_interpolate_and_random_show_the_solve(bars):
    made, stream = bars
    V, F = pieces()
    approximate((V, F), 10, method="random", seed=0, progress=True)  # selection is instant; ls_mesh factors
    assert_complete(made, stream)
    assert [bar.desc for bar in made] == ["ls_mesh"]
    made.clear()
    approximate((V, F), 10, interpolate=True, progress=True)
    assert [bar.desc for bar in made] == ["greedy selection", "ls_mesh"]
    assert_complete(made, stream)


def test_no_bar_without_progress(bars):
    made, stream = bars
    V, F = pieces()
    approximate((V, F), 10)
    stream_data = encode_geometry((V, F), 10)
    decode_geometry((V, F), stream_data)
    list(iter_decode_geometry((V, F), stream_data, step=3))
    ls_mesh(o3d.geometry.TriangleMesh.create_sphere(resolution=6), [0, 5])
    spectral_approximation((V, F), 10)
    assert made == [] and stream.getvalue() == ""


def test_encode_decode_bars(bars):
    made, stream = bars
    V, F = pieces()
    data = encode_geometry((V, F), 30, progress=True)
    assert_complete(made, stream, count=30)
    made.clear()
    decode_geometry((V, F), data, progress=True)
    assert_complete(made, stream)
    assert [(bar.desc, bar.total) for bar in made] == [("decode_geometry", 2)]
    made.clear()
    meshes = list(iter_decode_geometry((V, F), data, step=7, progress=True))
    assert len(meshes) == 5  # 7, 14, 21, 28, 30 anchors
    assert [(bar.desc, bar.total, bar.n) for bar in made] == [("progressive decoding", 30, 30)]


def test_abandoned_progressive_decoding_closes_its_bar(bars):
    made, _ = bars
    V, F = pieces()
    data = encode_geometry((V, F), 30)
    refinements = iter_decode_geometry((V, F), data, step=7, progress=True)
    next(refinements)
    refinements.close()
    assert made[0].n == 7 and made[0].disable  # closed tqdm bars are disabled


def test_ls_mesh_reconstruct_spectral_bars(bars):
    made, stream = bars
    V, F = pieces()
    ls_mesh((V, F), [0, 70, 110], progress=True)
    for interpolate in (True, False):
        reconstruct_geometry((V, F), np.arange(10, 30), interpolate=interpolate, progress=True)
    spectral_approximation((V, F), 10, progress=True)  # 3 components, then 7 eigenpairs by shift-invert
    assert [bar.desc for bar in made] == [
        "ls_mesh",
        "reconstruct_geometry",
        "reconstruct_geometry",
        "spectral basis",
    ]
    assert_complete(made, stream)


def test_default_denoiser_bar_names_its_stages_and_cg_shows_its_residual(bars):
    made, stream = bars
    V, F = pieces()
    V = V + np.random.default_rng(0).normal(0, 0.01, V.shape)
    # the feature mode's passes to their stop (curved pieces: before the cap, whose total the bar ends at),
    # then the scan energy, factored: one bar over its three stages
    constrained_fairing((V, F), progress=True)
    assert [bar.desc for bar in made] == ["feature passes", "constrained fairing (scan)"]
    assert_complete(made, stream, count=3)
    assert "solve" in stream.getvalue() and "stopped at pass" in stream.getvalue()
    constrained_fairing((V, F), progress=True, solver="iterative")
    assert [bar.desc for bar in made[2:]] == [
        "feature passes",
        "constrained fairing (scan)",
        "conjugate gradients",
    ]
    assert_complete(made, stream)
    assert "residual=" in stream.getvalue()


def test_every_function_rejects_a_non_bool_progress():
    V, F = pieces()
    data = encode_geometry((V, F), 10)
    calls = {
        "approximate": lambda p: approximate((V, F), 10, progress=p),
        "select_control_points": lambda p: select_control_points((V, F), 10, progress=p),
        "encode_geometry": lambda p: encode_geometry((V, F), 10, progress=p),
        "decode_geometry": lambda p: decode_geometry((V, F), data, progress=p),
        "iter_decode_geometry": lambda p: iter_decode_geometry((V, F), data, progress=p),
        "ls_mesh": lambda p: ls_mesh((V, F), [0, 70, 110], progress=p),
        "reconstruct_geometry": lambda p: reconstruct_geometry((V, F), [1, 2], progress=p),
        "spectral_approximation": lambda p: spectral_approximation((V, F), 10, progress=p),
    }
    for name, call in calls.items():
        for bad in (1, "yes", None, 0.0):
            with pytest.raises(TypeError, match="progress must be a bool"):
                call(bad)
                pytest.fail(f"{name} accepted progress={bad!r}")
        call(np.bool_(False))  # numpy's bool is a bool


def test_bars_end_at_their_totals_and_an_error_leaves_its_stage(bars):
    made, stream = bars
    assert Progress(np.bool_(True), "x").enabled is True
    with pytest.raises(TypeError, match="progress must be a bool, got int"):
        Progress(1, "x")
    silent = Progress(False, "x").bar(5)
    silent.update(3)
    silent.close()
    assert made == []
    with pytest.raises(RuntimeError), Progress(True, "failing").stages(("factor", "solve")) as begin:
        begin("factor")
        raise RuntimeError("boom")
    assert made[-1].n == 0 and made[-1].total == 2  # an error leaves the bar where it happened
    with Progress(True, "ok").stages(("factor", "solve")) as begin:
        begin("factor")
        assert made[-1].n == 0
        begin("solve")
        assert made[-1].n == 1
    assert made[-1].n == 2
    with Progress(True, "seeded").bar(10, initial=4) as bar:
        bar.update(6)
    assert "10/10" in stream.getvalue()


def test_cg_bar_counts_the_decades_to_its_tolerance_not_the_iteration_cap(bars):
    made, stream = bars
    n = 400  # a 1-D Laplacian plus a small shift: CG takes tens of iterations
    matrix = sp.diags([-np.ones(n - 1), np.full(n, 2.01), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    rhs = np.random.default_rng(0).normal(size=(n, 3))
    x = SPDSolver(matrix, backend="iterative", tol=1e-6, max_iterations=5000, progress=True).solve(rhs)
    assert np.linalg.norm(matrix @ x - rhs) <= 1e-6 * np.linalg.norm(rhs, axis=0).max() * 3
    # from a zero start every column's residual falls a millionfold: six decades, not 5000 iterations
    (bar,) = made
    assert (bar.desc, bar.total, bar.n) == ("conjugate gradients", 6, 6)
    assert "/5000" not in stream.getvalue() and "residual=" in stream.getvalue()
    with Progress(True, "solve").decades(1e6) as bar:
        bar.reached(1e4)
        assert made[-1].n == 2
        bar.reached(2e4)  # CG's residual may rise: the bar shows it
        assert made[-1].n == 1
        bar.finish()
    assert (made[-1].n, made[-1].total) == (6, 6)


def test_over_yields_every_item_and_its_bar_ends_at_the_total(bars):
    made, stream = bars
    assert list(Progress(True, "squares").over(range(4))) == [0, 1, 2, 3]
    assert list(Progress(True, "list").over([5, 6, 7])) == [5, 6, 7]  # total from len()
    assert_complete(made, stream, count=3)
    assert list(Progress(False, "silent").over("ab")) == ["a", "b"]
    assert len(made) == 2
    with pytest.raises(TypeError, match="progress"):
        Progress(1, "x").over([1])


def test_one_progress_object_makes_every_bar_and_close_all_ends_the_open_ones(bars):
    made, _ = bars
    progress = Progress(True, "load")
    assert list(progress.over(range(3))) == [0, 1, 2]
    left_open = progress.bar(5)  # as a bar held by a traceback would stay
    left_open.update(2)
    with progress.stages(("read", "write")) as begin:
        begin("read")
    close_all()
    assert all(bar.disable or bar.n <= bar.total for bar in made) and left_open.disable
    assert [bar.desc for bar in made] == ["load"] * 3
    with pytest.raises(TypeError, match="progress must be a bool"):
        Progress("yes", "x")
