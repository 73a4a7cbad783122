"""render(): side-by-side pictures that are not blank and differ exactly where the meshes differ."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import open3d as o3d
import pytest

from o3d_lsmesh.core.errors import O3DLSMeshWarning

# The module, not the function of the same name that the package may export.
render_module = importlib.import_module("o3d_lsmesh.app.render")
render = render_module.render

W = H = 96
BACKGROUND = np.array([255, 255, 255])


def _sphere():
    return o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=30)


def _bumped(mesh):
    """``mesh`` with a bump on its +x side: only the right part of the silhouette and shading changes."""
    out = o3d.geometry.TriangleMesh(mesh)
    vertices = np.asarray(out.vertices)
    direction = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    weight = np.exp(-0.5 * (np.arccos(np.clip(direction[:, 0], -1, 1)) / 0.25) ** 2)
    vertices += 0.3 * weight[:, None] * direction
    return out, weight > 0.01


def _panels(image, count):
    return [image[:, k * W : (k + 1) * W].astype(np.int64) for k in range(count)]


def _foreground(panel):
    return np.any(np.abs(panel - BACKGROUND) > 8, axis=2)


def _check_layout(image):
    sphere = _sphere()
    _bumped(sphere)
    assert image.shape == (H, 3 * W, 3) and image.dtype == np.uint8
    a, a_again, b = _panels(image, 3)
    # Not blank: the sphere covers a good part of its panel (pi r^2 in a square of side 2.1 r: ~0.6
    # less the bump's margin), and it is shaded, not flat.
    covered = _foreground(a).mean()
    assert 0.25 < covered < 0.9
    assert a[_foreground(a)].std() > 5
    # The same mesh in two panels draws the same picture.
    assert np.abs(a - a_again).mean() < 1.0
    # The bumped sphere differs, and only on its +x (right, for the default camera) side.
    diff = np.any(np.abs(a_again - b) > 24, axis=2)
    assert diff.mean() > 0.01
    columns = np.flatnonzero(diff.any(axis=0))
    assert columns.min() > W // 2, "differences must lie on the bump's side of the panel"


def test_raycast_backend_draws_side_by_side():
    sphere = _sphere()
    bumped, _ = _bumped(sphere)
    image = render([sphere, sphere, bumped], None, width=W, height=H, backend="raycast")
    _check_layout(image)


def test_filament_offscreen_renderer_draws_side_by_side_and_keeps_highlights(tmp_path):
    """One Filament child process for both checks: the layout, and a white sphere under the default
    light shaded from dark to bright without clipping to pure white (the fourth panel)."""
    sphere = _sphere()
    bumped, _ = _bumped(sphere)
    white = o3d.geometry.TriangleMesh(sphere).paint_uniform_color([1.0, 1.0, 1.0])
    path = tmp_path / "four.png"
    try:
        image = render(
            [sphere, sphere, bumped, white], path, width=W, height=H, backend="filament", timeout=240
        )
    except RuntimeError as error:
        pytest.skip(f"Open3D's OffscreenRenderer cannot render on this machine: {error}")
    _check_layout(np.ascontiguousarray(image[:, : 3 * W]))
    # The PNG holds exactly the returned picture.
    np.testing.assert_array_equal(np.asarray(o3d.io.read_image(str(path))), image)
    first, _, _, fourth = _panels(image, 4)
    lit = fourth[_foreground(first)]  # the same sphere at the same pixels, white on white
    assert lit.max() > 200
    assert (lit >= 254).all(axis=1).mean() < 0.01


def test_error_color_map_marks_the_changed_region():
    sphere = _sphere()
    bumped, _changed = _bumped(sphere)
    image = render([sphere, bumped], None, width=W, height=H, reference=sphere, backend="raycast")
    # the panels keep their rows; the labelled color bar is a band below them
    assert image.shape[0] > H and image.shape[1] == 2 * W
    body = image[:H]
    a, b = body[:, :W].astype(np.int64), body[:, W:].astype(np.int64)

    # Yellow-green end of viridis: red and green high, blue low. Shading only darkens,
    # so a dark-purple (zero error) pixel can never look like this.
    def hot(panel):
        return (panel[..., 1] > 110) & (panel[..., 2] < 110) & _foreground(panel)

    assert not hot(a).any()
    assert hot(b).sum() > 20
    assert np.flatnonzero(hot(b).any(axis=0)).min() > W // 2
    # The color bar spans the scale from viridis' first to last color (left and right end of its strip).
    band = image[H:].astype(np.int64)
    first, last = (np.round(render_module.VIRIDIS[i] * 255).astype(np.int64) for i in (0, -1))
    assert (np.abs(band - first).max(axis=2) <= 3).sum() > 10
    assert (np.abs(band - last).max(axis=2) <= 3).sum() > 10


def _sphere_pair():
    sphere = _sphere()
    bumped, _ = _bumped(sphere)
    return sphere, bumped


def _ink(region):
    """Pixels that are not background (text or lines drawn on a white band)."""
    return np.any(np.abs(region.astype(np.int64) - BACKGROUND) > 60, axis=2)


def test_titles_label_every_panel_and_leave_the_panels_unchanged():
    sphere, bumped = _sphere_pair()
    plain = render([sphere, bumped], None, width=W * 2, height=H * 2, backend="raycast")
    titled = render(
        [sphere, bumped],
        None,
        width=W * 2,
        height=H * 2,
        backend="raycast",
        titles=["input", "constrained fairing (local, 10 iterations)"],
    )
    band = titled.shape[0] - plain.shape[0]
    assert band > 10 and titled.shape[1] == plain.shape[1]
    # the panels are copied pixel for pixel below the title band
    np.testing.assert_array_equal(np.asarray(titled[band:]), np.asarray(plain))
    # each panel's title band holds text, centered over its panel, and nothing else does
    for k in range(2):
        panel_band = _ink(titled[:band, k * 2 * W : (k + 1) * 2 * W])
        assert panel_band.sum() > 20
        columns = np.flatnonzero(panel_band.any(axis=0))
        assert abs(columns.mean() - W) < W / 2
    # a longer title inks more pixels
    assert _ink(titled[:band, 2 * W :]).sum() > _ink(titled[:band, : 2 * W]).sum()
    assert titled.error_max is None and titled.units is None


def test_color_bar_has_tick_labels_units_and_a_title():
    sphere, bumped = _sphere_pair()
    image = render(
        [sphere, bumped], None, width=W * 2, height=H * 2, backend="raycast", reference=sphere, error_max=0.2
    )
    assert image.error_max == 0.2 and image.units == "model"
    band = image[2 * H :]
    ink = _ink(band)
    strip_rows = np.flatnonzero(
        (np.abs(band.astype(np.int64) - np.round(render_module.VIRIDIS[5] * 255)).max(axis=2) <= 6).any(
            axis=1
        )
    )
    assert len(strip_rows)
    above, below = ink[: strip_rows.min()], ink[strip_rows.max() + 1 :]
    assert above.sum() > 30, "the color bar needs a title above it"
    assert below.sum() > 30, "the color bar needs tick labels below it"
    # tick labels spread along the bar: ink in each third of its width
    columns = np.flatnonzero(below.any(axis=0))
    thirds = np.array_split(np.arange(band.shape[1]), 3)
    assert all(np.isin(t, columns).any() for t in thirds)
    # a larger scale changes the numbers, not the panels
    other = render(
        [sphere, bumped], None, width=W * 2, height=H * 2, backend="raycast", reference=sphere, error_max=7.5
    )
    assert np.any(np.asarray(other[2 * H :]) != np.asarray(band))


def test_returned_scale_matches_distances_and_units():
    sphere, bumped = _sphere_pair()
    model = render([sphere, bumped], None, width=W, height=H, backend="raycast", reference=sphere)
    edge = render(
        [sphere, bumped], None, width=W, height=H, backend="raycast", reference=sphere, units="edge"
    )
    # independent reference: the vertex distances to the sphere of radius 1 (its mesh lies inside by at most
    # the sagitta of a facet), and the mean edge length by a plain loop over triangles
    distances = np.abs(np.linalg.norm(np.asarray(bumped.vertices), axis=1) - 1.0)
    # the reference's own distances (zero) do not count
    assert model.error_max == pytest.approx(np.percentile(distances, 99), abs=0.01)
    edges = set()
    for tri in np.asarray(sphere.triangles).tolist():
        for i, j in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            edges.add((min(i, j), max(i, j)))
    v = np.asarray(sphere.vertices)
    mean_edge = np.mean([np.linalg.norm(v[i] - v[j]) for i, j in edges])
    assert edge.edge_length == pytest.approx(mean_edge, rel=1e-9)
    assert edge.error_max == pytest.approx(model.error_max / mean_edge, rel=1e-6)
    assert edge.units == "edge"


def test_the_reference_beside_the_others_keeps_its_own_colors():
    # a fine sphere as the reference and a coarse one 10% larger: colored by its distance to itself, the
    # reference's panel would be uniformly dark (and its zeros would pull the scale down)
    fine = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=36)
    coarse = o3d.geometry.TriangleMesh.create_sphere(radius=1.1, resolution=6)
    image = render([fine, coarse], None, width=W, height=H, backend="raycast", reference=fine)
    plain = render([fine, coarse], None, width=W, height=H, backend="raycast")
    assert np.array_equal(_panels(image[:H], 2)[0], _panels(plain, 2)[0])
    # every coarse vertex lies 0.1 straight above a fine one (resolution 36 refines 6's grid)
    assert image.error_max == pytest.approx(0.1, rel=1e-6)


def test_titles_and_units_bad_values_raise():
    sphere = _sphere()
    with pytest.raises(ValueError, match=r"titles must hold one title per mesh \(2\), got 1"):
        render([sphere, sphere], None, width=16, height=16, backend="raycast", titles=["a"])
    with pytest.raises(TypeError, match="titles must be a sequence of strings"):
        render([sphere], None, width=16, height=16, backend="raycast", titles="a")
    with pytest.raises(TypeError, match="titles must be a sequence of strings"):
        render([sphere], None, width=16, height=16, backend="raycast", titles=[3])
    with pytest.raises(ValueError, match="units"):
        render([sphere], None, width=16, height=16, backend="raycast", units="inch")
    with pytest.raises(TypeError, match="colorbar_title must be a string, got int"):
        render([sphere], None, width=16, height=16, backend="raycast", colorbar_title=3)


def test_without_matplotlib_the_picture_keeps_an_unlabelled_bar(monkeypatch):
    monkeypatch.setattr(render_module, "_matplotlib", lambda: None)
    sphere, bumped = _sphere_pair()
    with pytest.warns(O3DLSMeshWarning, match="matplotlib is not installed"):
        image = render(
            [sphere, bumped], None, width=W, height=H, reference=sphere, backend="raycast", titles=["a", "b"]
        )
    assert image.shape == (H, 2 * W, 3)
    np.testing.assert_array_equal(image[-1, 0], np.round(render_module.VIRIDIS[0] * 255).astype(np.uint8))
    np.testing.assert_array_equal(image[-1, -1], np.round(render_module.VIRIDIS[-1] * 255).astype(np.uint8))


def test_error_colors_scale():
    colors = render_module.error_colors(np.array([0.0, 0.5, 1.0, 7.0]), 1.0)
    np.testing.assert_allclose(colors[0], render_module.VIRIDIS[0])
    np.testing.assert_allclose(colors[2], render_module.VIRIDIS[-1])
    np.testing.assert_allclose(colors[3], render_module.VIRIDIS[-1])  # clipped
    np.testing.assert_allclose(colors[1], render_module.VIRIDIS[5])


def test_align_each_centers_every_mesh():
    sphere = _sphere()
    bumped, _ = _bumped(sphere)
    common = render([sphere, bumped], None, width=W, height=H, backend="raycast")
    each = render([sphere, bumped], None, width=W, height=H, backend="raycast", align="each")

    def center_column(panel):
        return np.flatnonzero(_foreground(panel).any(axis=0)).mean()

    # The joint box is the bumped sphere's, whose center lies on the bump's (+x) side: with a common
    # center the plain sphere sits left of its panel's middle; centered on its own box it does not.
    assert abs(center_column(_panels(each, 2)[0]) - (W - 1) / 2) < 1
    assert center_column(_panels(common, 2)[0]) < (W - 1) / 2 - 3


def test_vertex_colors_and_tensor_meshes_are_drawn():
    sphere = _sphere()
    sphere.paint_uniform_color([1.0, 0.0, 0.0])
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(_sphere())
    image = render(
        [sphere, tensor, (np.asarray(sphere.vertices), np.asarray(sphere.triangles))],
        None,
        width=W,
        height=H,
        backend="raycast",
    )
    red, gray, tuple_panel = _panels(image, 3)
    mask = _foreground(red)
    assert (red[mask][:, 0] > 3 * red[mask][:, 2] + 10).mean() > 0.9  # red stays red
    assert (
        np.abs(gray[_foreground(gray)][:, 0] - gray[_foreground(gray)][:, 2]).mean() < 40
    )  # default gray-blue
    assert _foreground(tuple_panel).mean() > 0.25


def test_auto_falls_back_to_raycasting_with_a_warning(monkeypatch):
    monkeypatch.setattr(sys, "executable", "/bin/false")
    with pytest.warns(O3DLSMeshWarning, match="RaycastingScene backend"):
        image = render(_sphere(), None, width=32, height=32, backend="auto")
    assert _foreground(image.astype(np.int64)).any()


def test_filament_failure_and_timeout_raise(monkeypatch):
    with pytest.raises(RuntimeError, match="did not finish within timeout"):
        render(_sphere(), None, width=32, height=32, backend="filament", timeout=0.001)
    monkeypatch.setattr(sys, "executable", "/bin/false")
    with pytest.raises(RuntimeError, match="OffscreenRenderer failed: exit code 1"):
        render(_sphere(), None, width=32, height=32, backend="filament")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"width": 2}, "width"),
        ({"height": 0}, "height"),
        ({"backend": "vulkan"}, "backend"),
        ({"align": "left"}, "align"),
        ({"timeout": 0}, "timeout"),
        ({"margin": -1.0}, "margin"),
        ({"color": (2.0, 0.0, 0.0)}, r"color must have 3 entries in \[0, 1\], got \[2.0, 0.0, 0.0\]"),
        ({"background": (0.0, 0.0)}, r"background must be a sequence of 3 numbers, got shape \(2,\)"),
        ({"view_direction": (0.0, 0.0, 0.0)}, "view_direction must be a non-zero finite 3-vector"),
        ({"up": (0.0, 0.0, 2.0)}, "up must not be parallel to view_direction"),
        ({"reference": "sphere.ply"}, "reference must be"),
        ({"error_max": -1.0, "reference": None}, None),
    ],
)
def test_bad_options_raise(kwargs, match):
    if match is None:  # error_max is checked with or without a reference
        with pytest.raises(ValueError, match="error_max must be positive and finite, got -1.0"):
            render(_sphere(), None, width=16, height=16, backend="raycast", **kwargs)
        with pytest.raises(TypeError, match="error_max must be a number, got 'big'"):
            render(_sphere(), None, width=16, height=16, backend="raycast", error_max="big")
        with pytest.raises(ValueError, match="error_max"):
            render(
                _sphere(), None, width=16, height=16, backend="raycast", error_max=-1.0, reference=_sphere()
            )
        return
    with pytest.raises((ValueError, TypeError), match=match):
        render(_sphere(), None, width=16, height=16, backend="raycast", **kwargs)


def test_bad_meshes_and_paths_raise(tmp_path):
    with pytest.raises(ValueError, match="meshes must hold at least one mesh"):
        render([], None)
    with pytest.raises(TypeError, match=r"meshes\[0\] must be"):
        render(["not a mesh"], None, backend="raycast")
    with pytest.raises(TypeError, match=r"meshes\[1\] must be an open3d.geometry.TriangleMesh.*got str"):
        render([_sphere(), "x"], None, backend="raycast")
    with pytest.raises(TypeError, match=r"color must be a sequence of 3 numbers, got 'red'"):
        render(_sphere(), None, color="red", backend="raycast")
    with pytest.raises(
        TypeError, match=r"up must be a sequence of 3 numbers of real numbers, got dtype complex"
    ):
        render(_sphere(), None, up=(0, 1j, 0), backend="raycast")
    with pytest.raises(ValueError, match="must have vertices, got an empty mesh"):
        render(o3d.geometry.TriangleMesh(), None, backend="raycast")
    with pytest.raises(ValueError, match="path must be in an existing folder"):
        render(_sphere(), tmp_path / "missing" / "x.png", width=16, height=16, backend="raycast")
    with pytest.raises(ValueError, match="path must name a writable .png file"):
        render(_sphere(), tmp_path / "x.unknown", width=16, height=16, backend="raycast")


def test_absurd_picture_sizes_are_refused_before_drawing():
    from o3d_lsmesh.app.render import MAX_PIXELS

    meshes = [_sphere()] * 20
    assert 8192 * 8192 * 20 > MAX_PIXELS
    with pytest.raises(
        ValueError,
        match=r"width \* height \* len\(meshes\) must be at most 67,108,864 pixels, "
        r"got 8192 \* 8192 \* 20 = 1,342,177,280",
    ):
        render(meshes, None, width=8192, height=8192, backend="raycast")
