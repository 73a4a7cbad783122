"""The executed gallery: each example runs with ``--out`` and its pictures become the page's figures.

The examples write their pictures with ``render()`` (Open3D's renderer, not
matplotlib), so the gallery's own matplotlib scraper would find nothing:
``reset_argv`` hands every example ``--out PICTURES`` and :func:`png_scraper`
moves each PNG an example block wrote there into the gallery's image paths.
"""

from __future__ import annotations

from pathlib import Path

PICTURES = Path(__file__).resolve().parent / "_build" / "gallery_pictures"


def reset_argv(gallery_conf: dict, script_vars: dict) -> list[str]:
    PICTURES.mkdir(parents=True, exist_ok=True)
    for stale in PICTURES.glob("*.png"):
        stale.unlink()
    return ["--out", str(PICTURES)]


def png_scraper(block: object, block_vars: dict, gallery_conf: dict) -> str:
    from sphinx_gallery.scrapers import figure_rst

    written = sorted(PICTURES.glob("*.png"))
    moved = []
    for path, target in zip(written, block_vars["image_path_iterator"]):
        Path(target).write_bytes(path.read_bytes())
        path.unlink()
        moved.append(target)
    return figure_rst(moved, gallery_conf["src_dir"])
