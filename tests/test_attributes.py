"""No data lost by fill_holes and by writing OBJ: UVs, material ids, textures kept; a seam is not a hole."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

o3d = pytest.importorskip("open3d")

from conftest import grid  # noqa: E402

import o3d_lsmesh  # noqa: E402
from o3d_lsmesh._o3d.io import obj_writable  # noqa: E402
from o3d_lsmesh.app.cli import main  # noqa: E402

#: UV = position @ AFFINE + OFFSET: on a flat patch, harmonic (cotangent) values of it stay on it
AFFINE = np.array([[0.7, 0.2], [-0.1, 0.6], [0.0, 0.0]])
OFFSET = np.array([0.1, 0.15])
TEXTURE = (np.arange(8 * 8 * 3).reshape(8, 8, 3) * 5 % 256).astype(np.uint8)


def _affine(points):
    return points @ AFFINE + OFFSET


def _holed_box():
    """A closed unit box (midpoint-subdivided: flat faces) with a round hole in its top face, ``(vertices,
    triangles)``: closed, so that fill_holes has no outer border to leave open."""
    box = o3d.geometry.TriangleMesh.create_box().subdivide_midpoint(4)
    V, T = np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)
    centre = V[T].mean(axis=1)
    top = np.abs(centre[:, 2] - 1.0) < 1e-12
    return V, T[~(top & (np.linalg.norm(centre[:, :2] - [0.5, 0.47], axis=1) < 0.2))]


def _textured(V, T, ids):
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T.astype(np.int32))
    )
    mesh.triangle_uvs = o3d.utility.Vector2dVector(_affine(V[T]).reshape(-1, 2))
    mesh.triangle_material_ids = o3d.utility.IntVector(ids.astype(np.int32))
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.clip(_affine(V) @ [[1, 0, 0.5], [0, 1, 0.5]], 0, 1))
    mesh.textures = [o3d.geometry.Image(TEXTURE), o3d.geometry.Image(TEXTURE[::-1].copy())]
    return mesh


def _loop_triangles(T, new):
    """Indices of the triangles of ``T`` sharing an edge with a triangle of ``new`` (plain sets)."""
    new_edges = {frozenset(e) for t in new.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    return [
        i
        for i, t in enumerate(T.tolist())
        if any(frozenset(e) in new_edges for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])))
    ]


def test_legacy_fill_keeps_uvs_ids_textures_and_new_uvs_are_the_affine_map():
    V, T = _holed_box()
    ids = np.arange(len(T)) % 2
    mesh = _textured(V, T, ids)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing is dropped: no warning
        out = o3d_lsmesh.fill_holes(mesh)
    W, F = np.asarray(out.vertices), np.asarray(out.triangles)
    m = len(T)
    assert len(F) > m and len(W) > len(V)
    np.testing.assert_array_equal(F[:m], T)
    uvs = np.asarray(out.triangle_uvs).reshape(-1, 3, 2)
    np.testing.assert_array_equal(uvs[:m], np.asarray(mesh.triangle_uvs).reshape(-1, 3, 2))
    # the chart is continuous around the hole: new corners carry the affine map at their positions
    np.testing.assert_allclose(uvs[m:], _affine(W[F[m:]]), rtol=0, atol=1e-9)
    colours = np.asarray(out.vertex_colors)
    np.testing.assert_array_equal(colours[: len(V)], np.asarray(mesh.vertex_colors))
    np.testing.assert_allclose(
        colours[len(V) :],
        np.asarray(mesh.vertex_colors)[:1] * 0
        + np.clip(_affine(W[len(V) :]) @ [[1, 0, 0.5], [0, 1, 0.5]], 0, 1),
        rtol=0,
        atol=1e-9,
    )
    out_ids = np.asarray(out.triangle_material_ids)
    np.testing.assert_array_equal(out_ids[:m], ids)
    # the new triangles take the material of one triangle along the loop
    assert len(set(out_ids[m:].tolist())) == 1
    assert out_ids[m] in set(ids[_loop_triangles(T, F[m:])].tolist())
    assert len(out.textures) == 2
    for got, expected in zip(out.textures, mesh.textures, strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(expected))


def test_fill_with_needles_before_the_hole_extends_the_attributes_of_the_right_triangles():
    # zero-area needles (two coincident corners, as marching cubes leaves them) first among the triangles:
    # welded, they are left out of the surface, so the surface's triangle k is the source's k + 3; the new
    # triangles must take their material and UVs from the source's loop triangles, not 3 rows off
    V, T = _holed_box()
    copies = np.array([0, 5, 9])  # a vertex at the position of each of these, used by its needle alone
    far = [int(next(v for t in T if c in t for v in t if v != c)) for c in copies]
    V2 = np.concatenate([V, V[copies]])
    needles = np.stack([copies, len(V) + np.arange(3), far], axis=1)
    T2 = np.concatenate([needles, T])
    ids = np.arange(len(T2))  # every triangle its own material: a row off is seen
    mesh = _textured(V2, T2, ids)
    out = o3d_lsmesh.fill_holes(mesh)
    W, F = np.asarray(out.vertices), np.asarray(out.triangles)
    m = len(T2)
    np.testing.assert_array_equal(F[:m], T2)  # the needles kept, in place
    out_ids = np.asarray(out.triangle_material_ids)
    np.testing.assert_array_equal(out_ids[:m], ids)
    assert len(F) > m and out_ids[m] in set(ids[_loop_triangles(T2, F[m:])].tolist())
    uvs = np.asarray(out.triangle_uvs).reshape(-1, 3, 2)
    np.testing.assert_allclose(uvs[m:], _affine(W[F[m:]]), rtol=0, atol=1e-9)


def test_attributes_that_do_not_match_the_triangles_are_named_when_dropped():
    # Open3D's remove_triangles_by_index keeps every material id: 3 more ids than triangles, which
    # Open3D then says the mesh has none of; a fill drops them with a warning (it went without a word)
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=12)
    mesh.triangle_material_ids = o3d.utility.IntVector(list(range(len(mesh.triangles))))
    mesh.remove_triangles_by_index([100, 101, 102])
    assert len(mesh.triangle_material_ids) == len(mesh.triangles) + 3
    with pytest.warns(o3d_lsmesh.O3DLSMeshWarning, match="triangle material ids do not match"):
        out = o3d_lsmesh.fill_holes(mesh)
    assert len(out.triangles) > len(mesh.triangles) and not out.has_triangle_material_ids()
    # the same connectivity keeps them as given, without a warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same = o3d_lsmesh.constrained_fairing(mesh)
    np.testing.assert_array_equal(
        np.asarray(same.triangle_material_ids), np.asarray(mesh.triangle_material_ids)
    )
    # a tensor mesh's attribute of the wrong length likewise (it was extended: 3 rows too many)
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(mesh)
    tensor.triangle["label"] = o3d.core.Tensor(np.arange(len(mesh.triangles) + 3, dtype=np.int32))
    with pytest.warns(o3d_lsmesh.O3DLSMeshWarning, match="triangle attribute 'label' do not match"):
        out = o3d_lsmesh.fill_holes(tensor)
    assert "label" not in out.triangle and len(out.triangle.indices) > len(mesh.triangles)


def test_legacy_fill_without_new_vertices_keeps_uvs():
    V, T = _holed_box()
    mesh = _textured(V, T, np.zeros(len(T)))
    out = o3d_lsmesh.fill_holes(mesh, density=0.0)
    W, F = np.asarray(out.vertices), np.asarray(out.triangles)
    assert len(W) == len(V) and len(F) > len(T)
    np.testing.assert_allclose(
        np.asarray(out.triangle_uvs).reshape(-1, 3, 2), _affine(W[F]), rtol=0, atol=1e-12
    )


def test_tensor_fill_keeps_every_attribute_and_extends_them():
    V, T = _holed_box()
    m, n = len(T), len(V)
    mesh = o3d.t.geometry.TriangleMesh(o3d.core.Tensor(V), o3d.core.Tensor(T))
    mesh.vertex.colors = o3d.core.Tensor(np.c_[_affine(V), V[:, :1]].astype(np.float32))
    mesh.vertex.labels = o3d.core.Tensor(np.full((n, 1), 7, dtype=np.int32))
    mesh.triangle.texture_uvs = o3d.core.Tensor(_affine(V[T]).astype(np.float32))
    mesh.triangle.ids = o3d.core.Tensor(np.arange(m, dtype=np.int64))
    mesh.material.set_default_properties()
    mesh.material.texture_maps["albedo"] = o3d.t.geometry.Image(o3d.core.Tensor(TEXTURE))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = o3d_lsmesh.fill_holes(mesh)
    W, F = out.vertex.positions.numpy().astype(np.float64), out.triangle.indices.numpy()
    assert len(F) > m and len(W) > n
    np.testing.assert_array_equal(F[:m], T)
    colours = out.vertex.colors.numpy()
    assert colours.dtype == np.float32
    np.testing.assert_array_equal(colours[:n], mesh.vertex.colors.numpy())
    np.testing.assert_allclose(colours[n:], np.c_[_affine(W[n:]), W[n:, :1]], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(out.vertex.labels.numpy(), np.full((len(W), 1), 7))
    uvs = out.triangle.texture_uvs.numpy()
    np.testing.assert_array_equal(uvs[:m], mesh.triangle.texture_uvs.numpy())
    np.testing.assert_allclose(uvs[m:], _affine(W[F[m:]]), rtol=0, atol=1e-6)
    ids = out.triangle.ids.numpy()
    np.testing.assert_array_equal(ids[:m], np.arange(m))
    assert set(ids[m:].tolist()) <= set(_loop_triangles(T, F[m:]))
    np.testing.assert_array_equal(out.material.texture_maps["albedo"].as_tensor().numpy(), TEXTURE)


def _split_sphere_with_holes(tmp_path):
    """A UV sphere read from OBJ (split at its seam) with one hole across the seam and one away from it;
    the holes' centres."""
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=20, create_uv_map=True)
    assert o3d.io.write_triangle_mesh(str(tmp_path / "sphere.obj"), sphere)
    mesh = o3d.io.read_triangle_mesh(str(tmp_path / "sphere.obj"), enable_post_processing=False)
    V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    uvs = np.asarray(mesh.triangle_uvs).reshape(-1, 3, 2)
    groups: dict = {}
    for i, p in enumerate(V.tolist()):
        groups.setdefault(tuple(p), []).append(i)
    seam = [g for g in groups.values() if len(g) == 2]
    on_seam = V[seam[len(seam) // 2][0]]
    away = on_seam * [-1, -1, 1]  # the same latitude, half way round
    centres = V[T].mean(axis=1)
    cut = (np.linalg.norm(centres - on_seam, axis=1) < 0.3) | (np.linalg.norm(centres - away, axis=1) < 0.3)
    holed = o3d.geometry.TriangleMesh(mesh)
    holed.triangles = o3d.utility.Vector3iVector(T[~cut].astype(np.int32))
    holed.triangle_uvs = o3d.utility.Vector2dVector(uvs[~cut].reshape(-1, 2))
    holed.triangle_material_ids = o3d.utility.IntVector(np.asarray(mesh.triangle_material_ids)[~cut])
    return holed, on_seam, away


def _plain_weld(V):
    index: dict = {}
    split = np.array([index.setdefault(tuple(p), len(index)) for p in V.tolist()])
    welded = np.zeros((len(index), 3))
    welded[split] = V
    return welded, split


def _boundary_edges(T):
    count: dict = {}
    for t in T.tolist():
        for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            count[frozenset(e)] = count.get(frozenset(e), 0) + 1
    return sum(c == 1 for c in count.values())


def test_seams_are_not_holes_and_uvs_follow_the_chart(tmp_path, capsys):
    mesh, on_seam, away = _split_sphere_with_holes(tmp_path)
    V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    n, m = len(V), len(T)
    welded, split = _plain_weld(V)
    # what Open3D's counts see (the seam is a boundary) and what fill_holes must see (two holes)
    summary = o3d_lsmesh.topology_summary(mesh)
    assert summary["boundary_edges"] == _boundary_edges(T)
    assert summary["seam_edges"] == _boundary_edges(T) - _boundary_edges(split[T]) > 0
    out = o3d_lsmesh.fill_holes(mesh)
    W, F = np.asarray(out.vertices), np.asarray(out.triangles)
    np.testing.assert_array_equal(W[:n], V)
    np.testing.assert_array_equal(F[:m], T)
    # the fill of the split mesh is the fill of the welded mesh (plain weld), in the split layout
    ref_v, ref_t = o3d_lsmesh.fill_holes((welded, split[T]))
    np.testing.assert_allclose(W[n:], ref_v[len(welded) :], rtol=0, atol=1e-12)
    to_welded = np.concatenate([split, np.arange(len(welded), len(ref_v))])
    np.testing.assert_array_equal(to_welded[F], ref_t)
    assert _boundary_edges(to_welded[F]) == 0  # closed: both holes filled, the seam untouched
    # (the patch across the seam meets the loop's two sides through one copy of each seam vertex)
    assert o3d_lsmesh.topology_summary(out)["seam_edges"] >= summary["seam_edges"]
    # UVs: the old triangles' unchanged; the hole away from the seam continues its chart (each loop
    # corner has the UV its vertex has), the hole across the seam takes one UV of a loop corner
    uvs = np.asarray(out.triangle_uvs).reshape(-1, 3, 2)
    np.testing.assert_array_equal(uvs[:m], np.asarray(mesh.triangle_uvs).reshape(-1, 3, 2))
    uv_of = {}
    for t, corners in zip(T.tolist(), uvs[:m].tolist(), strict=True):
        for v, uv in zip(t, corners, strict=True):
            uv_of.setdefault(v, uv)
    centres = W[F[m:]].mean(axis=1)
    near_away = np.linalg.norm(centres - away, axis=1) < np.linalg.norm(centres - on_seam, axis=1)
    assert near_away.any() and (~near_away).any()
    new_uvs, new_tris = uvs[m:], F[m:]
    loop_uvs = [uv_of[v] for v in np.unique(new_tris[near_away]) if v < n]
    for t, corners in zip(new_tris[near_away].tolist(), new_uvs[near_away].tolist(), strict=True):
        for v, uv in zip(t, corners, strict=True):
            if v < n:
                assert uv == uv_of[v]
            else:  # inside the loop's UV box
                assert np.all(uv >= np.min(loop_uvs, axis=0) - 1e-12) and np.all(
                    uv <= np.max(loop_uvs, axis=0) + 1e-12
                )
    torn = new_uvs[~near_away].reshape(-1, 2)
    assert (torn == torn[0]).all()
    seam_loop = {
        tuple(uv)
        for t, c in zip(T.tolist(), uvs[:m].tolist(), strict=True)
        for v, uv in zip(t, c, strict=True)
        if v in set(new_tris[~near_away].ravel().tolist())
    }
    assert tuple(torn[0]) in seam_loop
    # the command line counts the holes fill_holes sees
    assert o3d.io.write_triangle_mesh(str(tmp_path / "holed.obj"), mesh)
    capsys.readouterr()  # (Open3D's own messages)
    assert main(["fill", str(tmp_path / "holed.obj"), str(tmp_path / "out.obj"), "--json", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["holes_before"], report["holes_after"]) == (2, 0)
    # a tensor mesh read from it (split at the seam too) gets the same fill
    tensor = o3d.t.io.read_triangle_mesh(str(tmp_path / "holed.obj"))
    out_t = o3d_lsmesh.fill_holes(tensor)
    n_t, m_t = len(tensor.vertex.positions), len(tensor.triangle.indices)
    assert (len(out_t.vertex.positions) - n_t, len(out_t.triangle.indices) - m_t) == (len(W) - n, len(F) - m)
    np.testing.assert_array_equal(
        out_t.triangle.texture_uvs.numpy()[:m_t], tensor.triangle.texture_uvs.numpy()
    )


def test_textured_obj_filled_and_written_back_keeps_its_texture(tmp_path, capsys):
    """#37's acceptance: the output OBJ's UVs, material and texture are there, through the command line."""
    V, T = _holed_box()
    mesh = _textured(V, T, np.zeros(len(T)))
    mesh.textures = [o3d.geometry.Image(TEXTURE)]
    mesh.vertex_colors = o3d.utility.Vector3dVector()
    assert o3d.io.write_triangle_mesh(str(tmp_path / "in.obj"), mesh)
    given = o3d.io.read_triangle_mesh(str(tmp_path / "in.obj"), enable_post_processing=False)
    assert main(["fill", str(tmp_path / "in.obj"), str(tmp_path / "out.obj"), "--quiet"]) == 0, (
        capsys.readouterr().err
    )
    assert "map_Kd out_0.png" in (tmp_path / "out.mtl").read_text()
    out = o3d.io.read_triangle_mesh(str(tmp_path / "out.obj"), enable_post_processing=False)
    W, F = np.asarray(out.vertices), np.asarray(out.triangles)
    m = len(T)
    assert len(F) > m
    # (Open3D writes faces grouped by material: one material here, so in order)
    np.testing.assert_array_equal(F[:m], np.asarray(given.triangles))
    uvs = np.asarray(out.triangle_uvs).reshape(-1, 3, 2)
    np.testing.assert_array_equal(uvs[:m], np.asarray(given.triangle_uvs).reshape(-1, 3, 2))
    np.testing.assert_allclose(uvs[m:], _affine(W[F[m:]]), rtol=0, atol=1e-5)  # (6 digits in OBJ)
    np.testing.assert_array_equal(
        np.asarray(out.triangle_material_ids), np.asarray(given.triangle_material_ids)[0]
    )
    images = [np.asarray(t) for t in out.textures if not t.is_empty()]
    assert len(images) == 1
    np.testing.assert_array_equal(images[0], TEXTURE)
    # a format that cannot hold them says so
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as in a shell (the suite turns warnings into errors)
        assert main(["fill", str(tmp_path / "in.obj"), str(tmp_path / "out.ply"), "--quiet"]) == 0
    assert "out.ply': the .ply output has no texture coordinates or textures" in capsys.readouterr().err


def test_obj_writable_fills_or_drops_empty_texture_slots(tmp_path):
    V, T = grid(3, 3)
    mesh = _textured(V, T, np.array([1, 1, 3, 3, 1, 3, 1, 1]))
    mesh.textures = [
        o3d.geometry.Image(),
        o3d.geometry.Image(TEXTURE),
        o3d.geometry.Image(),
        o3d.geometry.Image(TEXTURE[1:]),
    ]
    fixed = obj_writable(mesh)
    # slot 0 unused and empty: dropped; slot 2 empty and unused: dropped; ids renumbered 1 -> 0, 3 -> 1
    np.testing.assert_array_equal(np.asarray(fixed.triangle_material_ids), [0, 0, 1, 1, 0, 1, 0, 0])
    assert [np.asarray(t).shape for t in fixed.textures] == [TEXTURE.shape, TEXTURE[1:].shape]
    mesh.triangle_material_ids = o3d.utility.IntVector([0, 1, 3, 3, 1, 3, 1, 2])
    fixed = obj_writable(mesh)  # every slot in use: the empty ones become white
    np.testing.assert_array_equal(
        np.asarray(fixed.triangle_material_ids), np.asarray(mesh.triangle_material_ids)
    )
    assert [np.asarray(t).tolist() for t in fixed.textures[::2]] == [[[[255, 255, 255]]]] * 2
    assert mesh.textures[0].is_empty()  # the input is left alone
    assert o3d.io.write_triangle_mesh(str(tmp_path / "w.obj"), fixed)
    assert sorted(p.name for p in tmp_path.glob("w_*.png")) == [f"w_{i}.png" for i in range(4)]
    full = _textured(V, T, np.zeros(len(T)))
    assert obj_writable(full) is full  # nothing to fix


def test_textures_not_written_is_an_error(tmp_path, capsys, monkeypatch):
    V, T = _holed_box()
    mesh = _textured(V, T, np.zeros(len(T)))
    assert o3d.io.write_triangle_mesh(str(tmp_path / "in.obj"), mesh)
    # a writer that writes the OBJ alone (as Open3D does when it cannot write an image)
    real = o3d.io.write_triangle_mesh

    def geometry_alone(path, mesh, **_):
        return real(path, o3d.geometry.TriangleMesh(mesh.vertices, mesh.triangles))

    monkeypatch.setattr(o3d.io, "write_triangle_mesh", geometry_alone)
    capsys.readouterr()
    assert main(["fill", str(tmp_path / "in.obj"), str(tmp_path / "out.obj"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "out.obj' but not its material and textures out.mtl, out_0.png, out_1.png" in err, err


def test_unwritten_attributes_name_what_each_format_drops(tmp_path):
    # Open3D's PLY/STL/OFF/glTF writers hold no UVs or textures; its OBJ writer no textures without UVs
    from o3d_lsmesh._o3d.io import unwritten_attributes, write_mesh_file

    V, T = grid(3, 3)
    textured = _textured(V, T, np.zeros(len(T), dtype=int))
    untextured_uvs = o3d.geometry.TriangleMesh(textured)
    untextured_uvs.textures = []
    bare_texture = o3d.geometry.TriangleMesh(textured)
    bare_texture.triangle_uvs = o3d.utility.Vector2dVector()
    plain = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    for suffix in (".ply", ".stl", ".off", ".gltf"):
        assert unwritten_attributes(textured, suffix)[-1:] == ["texture coordinates or textures"]
        assert unwritten_attributes(untextured_uvs, suffix)[-1:] == ["texture coordinates or textures"]
        assert unwritten_attributes(plain, suffix) == []
    assert unwritten_attributes(textured, ".obj") == []
    assert unwritten_attributes(untextured_uvs, ".obj") == []
    assert unwritten_attributes(bare_texture, ".OBJ") == ["textures"]
    assert unwritten_attributes((V, T), ".ply") == []  # arrays hold no attributes
    # vertex colours: named lost exactly where the file read back has none (STL)
    coloured = o3d.geometry.TriangleMesh(plain)
    coloured.vertex_colors = o3d.utility.Vector3dVector(np.random.default_rng(0).random((len(V), 3)))
    for suffix in (".ply", ".stl", ".off", ".gltf", ".obj"):
        write_mesh_file(coloured, tmp_path / f"c{suffix}")
        kept = o3d.io.read_triangle_mesh(str(tmp_path / f"c{suffix}")).has_vertex_colors()
        assert ("vertex colours" in unwritten_attributes(coloured, suffix)) == (not kept), suffix


def test_an_unknown_value_at_a_rim_is_unknown_inside_its_patch_alone():
    # a NaN in a per-vertex attribute (a scan's missing confidence) at one hole's rim: that hole's new
    # vertices get NaN in that column, every other value is what it is without the NaN (the fill ran)
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=16)
    V, T = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    centroids = V[T].mean(axis=1)
    T = T[np.abs(centroids[:, 2]) < 0.85]  # two caps cut off: two holes
    values = np.c_[V[:, 0], V[:, 1] + 2.0, V[:, 2]]
    top = int(np.flatnonzero(np.abs(V[:, 2] - V[T][..., 2].max()) < 1e-12)[0])  # a vertex on the top rim

    def filled(attribute):
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(V)
        mesh.triangle.indices = o3d.core.Tensor(T)
        mesh.vertex["confidence"] = o3d.core.Tensor(attribute)
        out = o3d_lsmesh.fill_holes(mesh)
        return out.vertex.positions.numpy(), out.vertex["confidence"].numpy()

    positions, want = filled(values)
    unknown = values.copy()
    unknown[top, 1] = np.nan
    same_positions, got = filled(unknown)
    np.testing.assert_array_equal(same_positions, positions)
    new = np.arange(len(V), len(positions))
    upper = new[positions[new, 2] > 0]
    assert len(upper) and len(upper) < len(new)
    assert np.isnan(got[upper, 1]).all()  # the top hole's new vertices: no value in that column
    known = np.isfinite(got)
    assert known.sum() == got.size - len(upper) - 1  # ... and nowhere else (the rim vertex's own NaN kept)
    np.testing.assert_array_equal(got[known], want[known])


def test_a_tensor_mesh_with_narrow_indices_gets_indices_that_hold_its_new_vertices():
    # uint8 indices at 256 vertices: the fill's new vertices (256 and up) wrapped to 0.. in the input's dtype
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    V, T = np.asarray(sphere.vertices), np.asarray(sphere.triangles).astype(np.int64)
    T = T[V[T].mean(axis=1)[:, 2] < 0.8]  # a hole around the top pole
    V = np.vstack([V, 1000.0 + np.arange(256 - len(V))[:, None] * np.ones(3)])  # unreferenced up to 255
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(V)
    mesh.triangle.indices = o3d.core.Tensor(T.astype(np.uint8))
    out = o3d_lsmesh.fill_holes(mesh)
    reference = o3d_lsmesh.fill_holes((V, T))  # the array path: int64 throughout
    assert len(reference[0]) > 256
    np.testing.assert_array_equal(out.triangle.indices.numpy(), reference[1])


def test_integer_and_empty_vertex_attributes_are_extended_exactly():
    # integers went through float64: a constant uint64 sentinel (its max) came out 0 on the new vertices,
    # int64 max as int64 min, 2**53 + 1 as 2**53. Small integers are the float attribute's values rounded
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=16)
    V, T = np.asarray(sphere.vertices), np.asarray(sphere.triangles).astype(np.int64)
    T = T[V[T].mean(axis=1)[:, 2] < 0.85]  # a hole around the top pole
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(V)
    mesh.triangle.indices = o3d.core.Tensor(T)
    constants = {"u64": np.iinfo(np.uint64).max, "i64": np.iinfo(np.int64).max, "odd": 2**53 + 1}
    for key, value in constants.items():
        mesh.vertex[key] = o3d.core.Tensor(
            np.full(len(V), value, dtype=np.uint64 if key == "u64" else np.int64)
        )
    label = np.rint(40 * V[:, 0] - 20).astype(np.int8)  # negative and positive
    mesh.vertex["label"] = o3d.core.Tensor(label)
    mesh.vertex["as_float"] = o3d.core.Tensor(label.astype(np.float64))
    mesh.vertex["none"] = o3d.core.Tensor(np.zeros((len(V), 0)))  # no value a vertex (it crashed)
    out = o3d_lsmesh.fill_holes(mesh)
    n = len(V)
    assert len(out.vertex.positions) > n and out.vertex["none"].shape == (len(out.vertex.positions), 0)
    for key, value in constants.items():
        assert (out.vertex[key].numpy()[n:] == value).all(), key
    np.testing.assert_array_equal(
        out.vertex["label"].numpy()[n:], np.rint(out.vertex["as_float"].numpy()[n:])
    )
