"""Pictures of meshes side by side, drawn headless on the CPU (docs/algorithms/rendering.rst).

:func:`render` lays meshes out in a row under one orthographic camera and draws them with Open3D's
Filament ``OffscreenRenderer`` (Mesa's llvmpipe Vulkan driver without a GPU), post-processing off,
in a short-lived child process: a second renderer in one process hangs, and Filament's banner on
stdout would corrupt ``--json`` output. ``backend="raycast"`` needs no graphics driver.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import MeshData, read_mesh
from .._o3d.io import cast_rays, distances_to_surface, quiet_open3d, raycasting_scene, write_image
from ..core.arrays import area_weighted_normals
from ..core.connectivity import Connectivity
from ..core.errors import InputError, InputTypeError, warn
from ..core.validate import as_choice, as_count, as_positive_float, as_real_vector
from .metrics import common_frame

if TYPE_CHECKING:
    from .._types import AnyMesh

__all__ = ["VIRIDIS", "RenderedImage", "error_colors", "render"]

#: matplotlib's viridis sampled at 11 points, interpolated linearly (no matplotlib needed).
VIRIDIS = np.array(
    "0.267 0.005 0.329  0.283 0.141 0.458  0.254 0.265 0.530  0.207 0.372 0.553  0.164 0.471 0.558  "
    "0.128 0.567 0.551  0.135 0.659 0.518  0.267 0.749 0.441  0.478 0.821 0.318  0.741 0.873 0.150  "
    "0.993 0.906 0.144".split(),
    dtype=np.float64,
).reshape(-1, 3)

_DEFAULT_COLOR = (0.72, 0.74, 0.78)
#: Largest picture: 64 megapixels, whose rays and image buffers take about 5 GB on the raycast path.
MAX_PIXELS = 64 * 1024 * 1024
_BACKENDS = ("auto", "filament", "raycast")
#: Sun and image-based (ambient) light for Filament, tone mapping off: a surface facing the light
#: comes out at about 0.95 of its color, so not even a white mesh clips to white.
_SUN_LUX, _AMBIENT = 36000.0, 18000.0
_UNITS = ("model", "edge")


def error_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """Map ``values (n,) >= 0`` to viridis colors ``(n, 3)`` on the scale ``[0, vmax]`` (clipped)."""
    t = np.clip(np.asarray(values, dtype=np.float64) / max(float(vmax), 1e-300), 0.0, 1.0)
    grid = np.linspace(0.0, 1.0, len(VIRIDIS))
    return np.stack([np.interp(t, grid, VIRIDIS[:, c]) for c in range(3)], axis=1)


def _vertex_colors(data: MeshData) -> np.ndarray | None:
    mesh = data.source
    if data.kind == "legacy":
        return np.asarray(mesh.vertex_colors, dtype=np.float64).copy() if mesh.has_vertex_colors() else None
    if data.kind == "tensor" and "colors" in mesh.vertex:
        return mesh.vertex.colors.cpu().numpy().astype(np.float64).reshape(-1, 3)
    return None


def _unit(vector: Any, *, name: str) -> np.ndarray:
    v = as_real_vector(vector, 3, name=name)
    if np.abs(v).max() == 0:
        raise InputError(f"{name} must be a non-zero finite 3-vector, got {vector!r}", param=name)
    return v / np.linalg.norm(v)


def _layout(arrays, view_direction, up, width, height, margin, align):
    """Offset each mesh into its own panel along the camera's right axis; return the scene and camera.

    ``align="common"``: one center for all meshes (their joint bounding box); ``"each"``: their own.
    """
    back = _unit(view_direction, name="view_direction")
    up = _unit(up, name="up")
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-9:
        raise InputError(
            f"up must not be parallel to view_direction, got up={up.tolist()}, view_direction={back.tolist()}",
            param="up",
        )
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    if align == "common":
        centers = [common_frame(*(v for v, _ in arrays))[0]] * len(arrays)
    else:
        centers = [0.5 * (v.min(axis=0) + v.max(axis=0)) for v, _ in arrays]
    frame = np.stack([right, true_up, back], axis=1)
    extents = np.array([np.abs((v - c) @ frame).max(axis=0) for (v, _), c in zip(arrays, centers)])
    half = max(extents[:, 0].max(), extents[:, 1].max(), 1e-12) * (1.0 + margin)
    # Panels keep the pixel aspect ratio so that nothing is stretched.
    aspect = width / height
    half_w, half_h = half * max(1.0, aspect), half * max(1.0, 1.0 / aspect)
    count = len(arrays)
    all_vertices, all_triangles, offset = [], [], 0
    for k, ((vertices, triangles), center) in enumerate(zip(arrays, centers)):
        shift = (2.0 * k - (count - 1)) * half_w * right
        all_vertices.append(vertices - center + shift)
        all_triangles.append(triangles + offset)
        offset += len(vertices)
    depth = max(extents[:, 2].max(), half) * 2.0 + 1.0
    light = back + 0.4 * true_up - 0.3 * right  # towards the viewer's upper left (the sun: its opposite)
    camera = {
        "center": [0.0, 0.0, 0.0],
        "eye": (back * depth).tolist(),
        "up": true_up.tolist(),
        "right": right.tolist(),
        "back": back.tolist(),
        "light": (light / np.linalg.norm(light)).tolist(),
        "left": -count * half_w,
        "right_edge": count * half_w,
        "bottom": -half_h,
        "top": half_h,
        "near": 1e-3 * depth,
        "far": 3.0 * depth,
    }
    return np.concatenate(all_vertices), np.concatenate(all_triangles), camera


def _raycast(vertices, triangles, colors, camera, width, height, background) -> np.ndarray:
    scene = raycasting_scene(vertices, triangles)
    right, up, back, light = (np.array(camera[k]) for k in ("right", "up", "back", "light"))
    xs = camera["left"] + (np.arange(width) + 0.5) / width * (camera["right_edge"] - camera["left"])
    ys = camera["top"] - (np.arange(height) + 0.5) / height * (camera["top"] - camera["bottom"])
    px, py = np.meshgrid(xs, ys)
    origins = np.array(camera["eye"]) + px[..., None] * right + py[..., None] * up
    rays = np.concatenate([origins, np.broadcast_to(-back, origins.shape)], axis=-1).astype(np.float32)
    hit = cast_rays(scene, rays)
    found = np.isfinite(hit["t_hit"])
    ids = hit["primitive_ids"][found].astype(np.int64)
    uv = hit["primitive_uvs"][found].astype(np.float64)
    bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
    corners = triangles[ids]
    normals = area_weighted_normals(vertices, triangles)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), np.finfo(float).tiny)
    normal = np.einsum("pk,pkc->pc", bary, normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    color = np.einsum("pk,pkc->pc", bary, colors[corners])
    # abs(): the inside of an open mesh, seen through a hole, is lit rather than black.
    shade = 0.25 + 0.75 * np.abs(normal @ light)
    image = np.zeros((height, width, 3))
    image[...] = background
    image[found] = np.clip(color * shade[:, None], 0.0, 1.0)
    return np.round(image * 255.0).astype(np.uint8)


def _filament_worker(spec_path: str, image_path: str) -> None:
    """Child-process entry point: draw the scene in ``spec_path`` (npz) and save the image to ``image_path`` (npy)."""
    o3d = quiet_open3d()
    spec = np.load(spec_path)
    camera = json.loads(str(spec["camera"]))
    width, height = int(spec["size"][0]), int(spec["size"][1])
    rendering = o3d.visualization.rendering
    renderer = rendering.OffscreenRenderer(width, height)
    for switch in ("post_processing", "antialiasing", "ambient_occlusion", "shadowing"):
        getattr(renderer.scene.view, f"set_{switch}")(False)
    background = spec["background"].astype(np.float32)
    renderer.scene.set_background(np.append(background, 1.0))
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(spec["vertices"]),
        o3d.utility.Vector3iVector(spec["triangles"].astype(np.int32)),
    )
    mesh.vertex_colors = o3d.utility.Vector3dVector(spec["colors"])
    mesh.compute_vertex_normals()
    material = rendering.MaterialRecord()
    material.shader = "defaultLit"
    renderer.scene.add_geometry("meshes", mesh, material)
    # a sun from behind the viewer's upper left (as the raycast backend's), plus image-based ambient light
    sun = -np.array(camera["light"])
    renderer.scene.set_lighting(renderer.scene.LightingProfile.NO_SHADOWS, sun)
    renderer.scene.scene.set_sun_light(sun, [1.0, 1.0, 1.0], _SUN_LUX)
    renderer.scene.scene.enable_sun_light(True)
    renderer.scene.scene.set_indirect_light_intensity(_AMBIENT)
    box = (camera[key] for key in ("left", "right_edge", "bottom", "top", "near", "far"))
    renderer.scene.camera.set_projection(rendering.Camera.Projection.Ortho, *box)
    renderer.scene.camera.look_at(camera["center"], camera["eye"], camera["up"])
    image = np.asarray(renderer.render_to_image())[..., :3]
    np.save(image_path, np.ascontiguousarray(image, dtype=np.uint8))


def _filament(vertices, triangles, colors, camera, width, height, background, timeout) -> np.ndarray:
    with tempfile.TemporaryDirectory(prefix="o3d_lsmesh_render_") as folder:
        spec_path, image_path = os.path.join(folder, "spec.npz"), os.path.join(folder, "image.npy")
        scene = dict(vertices=vertices, triangles=triangles, colors=colors, camera=json.dumps(camera))
        np.savez(
            spec_path, **scene, size=np.array([width, height]), background=np.asarray(background, dtype=float)
        )
        package_parent = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env["PYTHONPATH"] = package_parent + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        code = "import sys; from o3d_lsmesh.app.render import _filament_worker; _filament_worker(sys.argv[1], sys.argv[2])"
        try:
            command = [sys.executable, "-c", code, spec_path, image_path]
            done = subprocess.run(command, capture_output=True, env=env, timeout=timeout, check=False)
        except subprocess.TimeoutExpired as error:
            raise RuntimeError(
                f"Filament OffscreenRenderer did not finish within timeout={timeout} s"
            ) from error
        if done.returncode != 0 or not os.path.exists(image_path):
            lines = [line for line in done.stderr.decode(errors="replace").splitlines() if line.strip()]
            reason = lines[-1] if lines else f"exit code {done.returncode}"
            raise RuntimeError(f"Filament OffscreenRenderer failed: {reason}")
        return np.load(image_path)


def _colorbar(image: np.ndarray, thickness: int) -> None:
    """The unlabelled fallback (no matplotlib): a viridis strip over the picture's bottom rows."""
    strip = error_colors(np.linspace(0.0, 1.0, image.shape[1]), 1.0)
    image[-thickness:] = np.round(strip * 255.0).astype(np.uint8)[None]


class RenderedImage(np.ndarray):
    """The picture ``render`` drew: a ``(height, width, 3)`` uint8 ndarray with the scale it used.

    ``error_max`` (top of the color scale in ``units``), ``units`` (``"model"`` or ``"edge"``) and
    ``edge_length`` (the reference's mean edge length): None without a reference.
    """

    error_max: float | None
    units: str | None
    edge_length: float | None

    def __new__(cls, image: np.ndarray, error_max=None, units=None, edge_length=None):
        obj = np.asarray(image).view(cls)
        obj.error_max, obj.units, obj.edge_length = error_max, units, edge_length
        return obj

    def __array_finalize__(self, obj) -> None:
        for name in ("error_max", "units", "edge_length"):
            setattr(self, name, getattr(obj, name, None))


def _matplotlib():
    """matplotlib's object API (no pyplot: no global state, no display), or None when it is not installed."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.colorbar import ColorbarBase
        from matplotlib.colors import LinearSegmentedColormap, Normalize
        from matplotlib.figure import Figure
    except ImportError:
        return None
    return FigureCanvasAgg, ColorbarBase, LinearSegmentedColormap, Normalize, Figure


def _annotate(image, panel_width, titles, bar, background):
    """Add a title band above the panels and, if ``bar = (error_max, label)``, a labelled color bar below
    (the panels' pixels copied unchanged: ``figimage``, no resampling)."""
    FigureCanvasAgg, ColorbarBase, LinearSegmentedColormap, Normalize, Figure = _matplotlib()
    height, total_width = image.shape[:2]
    font = float(np.clip(panel_width / 22.0, 8.0, 18.0))  # points = pixels at dpi 72
    title_band = round(2.2 * font) if titles is not None else 0
    bar_band = round(5.2 * font) if bar is not None else 0
    full = height + title_band + bar_band
    dpi = 72.0
    fig = Figure(figsize=(total_width / dpi, full / dpi), dpi=dpi, facecolor=tuple(background))
    fig.figimage(image, xo=0, yo=bar_band, origin="upper")
    text_color = "white" if np.mean(background) < 0.5 else "black"
    if titles is not None:
        style = {"ha": "center", "va": "center", "fontsize": font, "color": text_color, "clip_on": True}
        for k, title in enumerate(titles):
            fig.text((k + 0.5) * panel_width / total_width, 1.0 - 0.5 * title_band / full, title, **style)
    if bar is not None:
        error_max, label = bar
        cmap = LinearSegmentedColormap.from_list("o3d_lsmesh_viridis", VIRIDIS)
        left = 0.1 if total_width >= 300 else 0.05
        strip = 1.1 * font
        cax = fig.add_axes((left, (2.2 * font) / full, 1.0 - 2 * left, strip / full))
        bar_artist = ColorbarBase(
            cax, cmap=cmap, norm=Normalize(0.0, error_max), orientation="horizontal", extend="max"
        )
        bar_artist.ax.tick_params(labelsize=0.85 * font, colors=text_color, length=0.3 * font)
        bar_artist.outline.set_edgecolor(text_color)
        cax.set_title(label, fontsize=0.9 * font, color=text_color, pad=0.25 * font)
    (canvas := FigureCanvasAgg(fig)).draw()
    return np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])


def _mean_edge_length(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Mean length of the undirected edges (each counted once), the unit of ``units="edge"``."""
    edges = Connectivity(triangles, len(vertices)).edges.astype(np.int64)
    return float(np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).mean())


def render(
    meshes: AnyMesh | Sequence[AnyMesh],
    path: str | os.PathLike | None = None,
    *,
    width: int = 480,
    height: int = 480,
    reference: AnyMesh | None = None,
    error_max: float | None = None,
    color: Sequence[float] = _DEFAULT_COLOR,
    background: Sequence[float] | np.ndarray = (1.0, 1.0, 1.0),
    view_direction: Sequence[float] = (0.0, 0.0, 1.0),
    up: Sequence[float] = (0.0, 1.0, 0.0),
    margin: float = 0.05,
    align: str = "common",
    backend: str = "auto",
    timeout: float = 180.0,
    titles: Sequence[str] | None = None,
    units: str = "model",
    colorbar_title: str | None = None,
) -> RenderedImage:
    """Draw one or several meshes side by side and write the picture as a PNG.

    Every mesh gets its own ``width x height`` panel, left to right, under one orthographic camera
    looking along ``-view_direction``: equal sizes look equal across panels.

    Parameters
    ----------
    meshes : TriangleMesh, tensor TriangleMesh, (V, F) tuple, or a sequence of them
    path : str or path-like, optional
        PNG file to write; ``None`` only returns the image.
    width, height : int
        Size of one panel in pixels.
    reference : mesh, optional
        Color each vertex by its distance to it (viridis, dark 0, yellow ``error_max``: default the
        99th percentile, in ``units``: ``"model"`` or ``"edge"``, mean edge lengths of the reference)
        under a color bar titled ``colorbar_title``. Without it: a mesh's own colors, else ``color``.
    titles : sequence of str, optional
        One title per panel, in a band above the panels.
    color, background, view_direction, up : 3-vectors
        RGB in [0, 1]; from the scene towards the camera, and the camera's up.
    margin, align : float, {"common", "each"}
        Border as a fraction of the largest half size; one center for every panel, or each its own.
    backend, timeout : {"auto", "filament", "raycast"}, float
        Filament in a child process (given ``timeout`` seconds), or Open3D's ``RaycastingScene``
        in-process; ``"auto"``: Filament, else raycasting with an ``O3DLSMeshWarning``.

    Returns
    -------
    RenderedImage
        ``(H, width * len(meshes), 3)`` uint8, ``H = height`` plus the title band and color bar
        (drawn with matplotlib if installed, else an unlabelled strip and a warning).

    Raises
    ------
    InputError
        A mesh or option is invalid (``InputTypeError`` for a wrong type).
    RuntimeError
        ``backend="filament"`` and the offscreen renderer failed or timed out.

    Examples
    --------
    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    >>> render([sphere, o3d.geometry.TriangleMesh.create_box()], None, width=64, height=64, backend="raycast").shape
    (64, 128, 3)
    """
    pair = isinstance(meshes, tuple) and len(meshes) == 2 and isinstance(meshes[0], np.ndarray)  # one (V, F)
    items = list(meshes) if isinstance(meshes, (list, tuple)) and not pair else [meshes]
    if not items:
        raise InputError("meshes must hold at least one mesh, got an empty sequence", param="meshes")
    width = as_count(width, name="width", minimum=8, maximum=8192)
    height = as_count(height, name="height", minimum=8, maximum=8192)
    backend = as_choice(backend, _BACKENDS, name="backend")
    align = as_choice(align, ("common", "each"), name="align")
    margin = as_positive_float(margin, name="margin", allow_zero=True)
    timeout = as_positive_float(timeout, name="timeout")
    if error_max is not None:  # checked without a reference too: a wrong value is a mistake either way
        error_max = as_positive_float(error_max, name="error_max")
    background = as_real_vector(background, 3, name="background", low=0.0, high=1.0)
    units = as_choice(units, _UNITS, name="units")
    if titles is not None:
        if (
            isinstance(titles, str)
            or not isinstance(titles, Sequence)
            or not all(isinstance(t, str) for t in titles)
        ):
            message = f"titles must be a sequence of strings (one per mesh), got {titles!r}"
            raise InputTypeError(message, param="titles")
        if len(titles) != len(items):
            message = f"titles must hold one title per mesh ({len(items)}), got {len(titles)}"
            raise InputError(message, param="titles")
    if colorbar_title is not None and not isinstance(colorbar_title, str):
        message = f"colorbar_title must be a string, got {type(colorbar_title).__name__}"
        raise InputTypeError(message, param="colorbar_title")
    base_color = as_real_vector(color, 3, name="color", low=0.0, high=1.0)

    if width * height * len(items) > MAX_PIXELS:
        # each panel is checked alone above; many panels multiply the picture (and its ray buffers)
        raise InputError(
            f"width * height * len(meshes) must be at most {MAX_PIXELS:,} pixels, got {width} * {height} * "
            f"{len(items)} = {width * height * len(items):,}",
            param="width",
        )
    datas = [read_mesh(mesh, name=f"meshes[{k}]") for k, mesh in enumerate(items)]
    ref = read_mesh(reference, name="reference") if reference is not None else None
    # drawn at unit size (float32 raycasting overflows near 1e30); distances scaled back to model units
    scale = max([float(np.abs(d.vertices).max()) for d in [*datas, ref] if d is not None] + [1e-300])
    arrays = [(d.vertices / scale, d.triangles) for d in datas]
    colors = []
    for data, (vertices, _) in zip(datas, arrays):
        own = _vertex_colors(data)
        colors.append(
            own if own is not None and len(own) == len(vertices) else np.tile(base_color, (len(vertices), 1))
        )
    edge_length = None
    if ref is not None:
        # the reference itself, drawn beside the others, keeps its own colors (its distances are zero)
        measured = [k for k, mesh in enumerate(items) if mesh is not reference]
        distances = [
            scale * distances_to_surface(arrays[k][0], ref.vertices / scale, ref.triangles) for k in measured
        ]
        edge_length = _mean_edge_length(ref.vertices, ref.triangles)
        if units == "edge":
            distances = [d / edge_length for d in distances]
        if error_max is None:
            pooled = np.concatenate([np.zeros(0), *distances])
            error_max = float(np.percentile(pooled, 99.0)) if pooled.size else 0.0
            error_max = error_max if error_max > 0 else 1.0
        for k, d in zip(measured, distances):
            colors[k] = error_colors(d, error_max)

    vertices, triangles, camera = _layout(arrays, view_direction, up, width, height, margin, align)
    all_colors = np.concatenate(colors)
    total_width = width * len(arrays)
    image = None
    if backend in ("auto", "filament"):
        try:
            image = _filament(
                vertices, triangles, all_colors, camera, total_width, height, background, timeout
            )
        except RuntimeError as error:
            if backend == "filament":
                raise
            warn(f"{error}; drawing with the RaycastingScene backend instead")
    if image is None:
        image = _raycast(vertices, triangles, all_colors, camera, total_width, height, background)
    image = np.ascontiguousarray(image, dtype=np.uint8)
    bar = None
    if reference is not None:
        unit_text = "mean edge lengths of the reference" if units == "edge" else "model units"
        bar = (error_max, f"{colorbar_title or 'distance to reference'} ({unit_text})")
    if titles is not None or bar is not None:
        if _matplotlib() is not None:
            image = _annotate(image, width, titles, bar, background)
        else:
            warn(
                "matplotlib is not installed: the picture has no titles and an unlabelled color bar (pip install matplotlib)"
            )
            if bar is not None:
                _colorbar(image, max(3, height // 40))
    if path is not None:
        path = os.fspath(path)
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise InputError(f"path must be in an existing folder, got {path!r}", param="path")
        if not write_image(path, image):
            raise InputError(f"path must name a writable .png file, got {path!r}", param="path")
    return RenderedImage(image) if reference is None else RenderedImage(image, error_max, units, edge_length)
