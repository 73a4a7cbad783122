"""The README's API tour runs as written, on a generated mesh instead of scan.ply, with a small
raycast picture and 300 encoded controls (the renderer and encoder have their own tests)."""

from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"
SMALL_PICTURE = ', backend="raycast", width=96, height=96'


def test_readme_tour_runs(tmp_path):
    text = README.read_text()
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    assert 'o3d.io.read_triangle_mesh("scan.ply")' in code
    code = code.replace(
        'mesh = o3d.io.read_triangle_mesh("scan.ply")',
        "from o3d_lsmesh.app.shapes import demo_mesh\nmesh = demo_mesh(4)",
    )
    code = code.replace('"before_after.png"', repr(str(tmp_path / "before_after.png")) + SMALL_PICTURE)
    assert "encode_geometry(mesh, 1000," in code
    code = code.replace("encode_geometry(mesh, 1000,", "encode_geometry(mesh, 300,")
    namespace: dict = {}
    try:
        exec(compile(code, str(README), "exec"), namespace)
    finally:
        import o3d_lsmesh

        o3d_lsmesh.unregister()
    assert (tmp_path / "before_after.png").stat().st_size > 1000
    before = np.asarray(namespace["mesh"].vertices)
    assert np.abs(np.asarray(namespace["edited"].vertices) - before).max() > 0
    assert len(namespace["out"].triangles) <= 5000


def test_readme_has_no_repeated_paragraph():
    paragraphs = [p.strip() for p in README.read_text().split("\n\n") if len(p.strip()) > 80]
    repeated = {p[:60] for p in paragraphs if paragraphs.count(p) > 1}
    assert not repeated
    for paragraph in paragraphs:
        sentences = [s.strip() for s in paragraph.replace("\n", " ").split(". ") if len(s.strip()) > 40]
        assert len(sentences) == len(set(sentences)), paragraph[:80]
