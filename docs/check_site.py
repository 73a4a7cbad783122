"""Open the built site in headless Chromium and check that it renders.

Asserts, on the DOM as the browser built it:

* every name in ``o3d_lsmesh.__all__`` has its page under ``api/`` with the
  object's anchor (``id="o3d_lsmesh.<name>"``; for a module, its functions'
  anchors);
* the gallery index has one thumbnail per ``examples/NN_*.py`` and every
  example page shows a picture;
* every algorithm page shows its figure;
* every equation (``.math``) on these pages was typeset by MathJax, without
  a TeX error;
* every ``<img>`` on these pages was decoded by the browser (``complete`` and
  ``naturalWidth > 0``) and its file exists in the build;
* every link on these pages to a page of the site names a file that exists in
  the build (the user guide, the CLI reference, the benchmark reports included).

The pages are served over a local HTTP server (one origin, so a check page can
read the pages it loads in iframes: one browser start for the whole site).

Usage: ``python docs/check_site.py [docs/_build/html]``;
``python docs/check_site.py --self-test`` checks the checker on a tiny site
with a missing anchor, a corrupt and a missing image. Exit status 1 with a
list of failures, 0 with a one-line summary.
"""

from __future__ import annotations

import functools
import http.server
import inspect
import json
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import urllib.parse
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

CHECK_PAGE = "_site_check.html"

COLLECT = """
<script>
window.addEventListener("load", async () => {
  const out = [];
  for (const frame of document.querySelectorAll("iframe")) {
    const doc = frame.contentDocument;
    const win = frame.contentWindow;
    // MathJax typesets after the load event: wait for it where the page has equations.
    if (win && win.MathJax && win.MathJax.startup && win.MathJax.startup.promise) {
      try { await win.MathJax.startup.promise; } catch (e) {}
    }
    out.push({
      page: frame.getAttribute("src"),
      url: frame.contentWindow ? frame.contentWindow.location.href : "",
      loaded: doc !== null && doc.readyState === "complete" && doc.body !== null,
      title: doc ? doc.title : "",
      ids: doc ? [...doc.querySelectorAll("[id]")].map(e => e.id).filter(i => i.startsWith("o3d_lsmesh")) : [],
      images: doc ? [...doc.images].map(img => ({
        src: img.getAttribute("src"), url: img.src, ok: img.complete && img.naturalWidth > 0,
        width: img.naturalWidth})) : [],
      links: doc ? [...doc.querySelectorAll("a[href]")].map(a => a.href) : [],
      math: doc ? doc.querySelectorAll("span.math, div.math").length : 0,
      typeset: doc ? doc.querySelectorAll("mjx-container").length : 0,
      mathErrors: doc ? doc.querySelectorAll("mjx-merror").length : 0,
    });
  }
  const pre = document.createElement("pre");
  pre.id = "site-check-result";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>
"""


def find_chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise SystemExit("check_site: no chromium on PATH (Debian: apt-get install chromium)")


def expected_pages(build: Path) -> dict[str, dict]:
    """Page path -> what it must contain: ``ids`` (anchors) and ``min_images``."""
    import o3d_lsmesh

    pages: dict[str, dict] = {}
    for name in o3d_lsmesh.__all__:
        obj = getattr(o3d_lsmesh, name)
        if inspect.ismodule(obj):
            # What automodule :members: documents: the module's __all__, else what it defines itself.
            public = getattr(obj, "__all__", None) or [
                n
                for n in dir(obj)
                if not n.startswith("_") and getattr(getattr(obj, n), "__module__", None) == obj.__name__
            ]
            ids = [
                f"{obj.__name__}.{n}" for n in public if callable(getattr(obj, n)) and getattr(obj, n).__doc__
            ]
        else:
            ids = [f"o3d_lsmesh.{name}"]
        pages[f"api/{name}.html"] = {"ids": ids, "min_images": 0}
    examples = sorted((REPO / "examples").glob("[0-9][0-9]_*.py"))
    pages["auto_examples/index.html"] = {"ids": [], "min_images": len(examples)}
    for path in examples:
        pages[f"auto_examples/{path.stem}.html"] = {"ids": [], "min_images": 1}
    # a method's page shows it at work; the pages on the package's insides (index: "Inside the package") need not
    inside = {"connectivity", "solvers", "attributes", "rendering"}
    for path in sorted((HERE / "algorithms").glob("*.rst")):
        pages[f"algorithms/{path.stem}.html"] = {"ids": [], "min_images": int(path.stem not in inside)}
    pages["architecture.html"] = {"ids": [], "min_images": 0}
    for page in ("index.html", "choosing.html", "api/index.html", "install.html", "cli.html", "batch.html"):
        pages[page] = {"ids": [], "min_images": 0}
    for page in ("limits.html", "citing.html", "benchmarks_summary.html"):
        pages[page] = {"ids": [], "min_images": 0}
    pages["tour.html"] = {"ids": [], "min_images": 2}
    for path in sorted((HERE / "benchmarks").glob("*.md")):
        pages[f"benchmarks/{path.stem}.html"] = {"ids": [], "min_images": 0}
    missing = [p for p in pages if not (build / p).is_file()]
    if missing:
        raise SystemExit("check_site: pages missing from the build: " + ", ".join(missing))
    return pages


def run_browser(build: Path, pages: list[str], timeout: float) -> list[dict]:
    handler = functools.partial(_QuietHandler, directory=str(build))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    frames = "\n".join(f'<iframe src="/{p}" width="1280" height="2400"></iframe>' for p in pages)
    check = build / CHECK_PAGE
    check.write_text(
        f"<!DOCTYPE html><html><head><title>site check</title></head><body>\n{frames}\n{COLLECT}</body></html>\n"
    )
    profile = tempfile.mkdtemp(prefix="o3d_lsmesh_chromium_")
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/{CHECK_PAGE}"
        cmd = [
            find_chromium(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--disable-dev-shm-usage",
            f"--user-data-dir={profile}",
            "--virtual-time-budget=30000",
            "--dump-dom",
            url,
        ]
        done = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=timeout)
    finally:
        server.shutdown()
        check.unlink(missing_ok=True)
        shutil.rmtree(profile, ignore_errors=True)
    found = re.search(r'<pre id="site-check-result">(.*?)</pre>', done.stdout, re.DOTALL)
    if not found:
        raise SystemExit(
            f"check_site: chromium returned no result (exit {done.returncode}):\n{done.stderr[-2000:]}"
        )
    import html

    return json.loads(html.unescape(found.group(1)))


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format, *args):
        pass


def check(
    build: Path, *, pages: dict[str, dict] | None = None, timeout: float = 180.0
) -> tuple[list[str], int, int, int]:
    """Failures (empty when the site renders), page count, image count, typeset equation count."""
    pages = expected_pages(build) if pages is None else pages
    results = run_browser(build, list(pages), timeout)
    failures: list[str] = []
    seen = {r["page"].lstrip("/"): r for r in results}
    for page, want in pages.items():
        got = seen.get(page)
        if got is None or not got["loaded"]:
            failures.append(f"{page}: did not load in the browser")
            continue
        for anchor in want["ids"]:
            if anchor not in got["ids"]:
                failures.append(f"{page}: no element with id {anchor!r}")
        if len(got["images"]) < want["min_images"]:
            failures.append(f"{page}: {len(got['images'])} images, expected at least {want['min_images']}")
        if got["typeset"] < got["math"] or got["mathErrors"]:
            failures.append(
                f"{page}: {got['typeset']} of {got['math']} equations typeset by MathJax, "
                f"{got['mathErrors']} with errors"
            )
        for image in got["images"]:
            if not image["ok"]:
                failures.append(f"{page}: image {image['src']} did not render")
            path = urllib.parse.urlparse(image["url"]).path
            if not (build / urllib.parse.unquote(path).lstrip("/")).is_file():
                failures.append(f"{page}: image file {image['src']} missing from the build")
        for link in got.get("links", []):
            url = urllib.parse.urlparse(link)
            if url.scheme not in ("http", "https") or url.netloc != urllib.parse.urlparse(got["url"]).netloc:
                continue  # another site (none is reached from here) or a mailto
            target = urllib.parse.unquote(url.path).lstrip("/")
            if not (build / target).is_file() and not (build / target / "index.html").is_file():
                failures.append(f"{page}: broken link to {target}")
    n_images = sum(len(r["images"]) for r in results)
    n_math = sum(r["typeset"] for r in results)
    return failures, len(pages), n_images, n_math


def self_test() -> None:
    """The checker catches what it claims to: a missing anchor, an undecodable and a missing image, a broken link."""
    with tempfile.TemporaryDirectory(prefix="o3d_lsmesh_site_") as tmp:
        site = Path(tmp)
        shutil.copyfile(HERE / "images" / "01_denoise_scan.png", site / "good.png")
        (site / "corrupt.png").write_bytes(b"not a png")
        (site / "ok.html").write_text(
            '<html><body><dl><dt id="o3d_lsmesh.good">good</dt></dl><img src="good.png"></body></html>'
        )
        (site / "bad.html").write_text(
            '<html><body><dl><dt id="o3d_lsmesh.other">other</dt></dl>'
            '<img src="corrupt.png"><img src="gone.png"><a href="ok.html">fine</a>'
            '<a href="missing.html#x">broken</a></body></html>'
        )
        pages = {
            "ok.html": {"ids": ["o3d_lsmesh.good"], "min_images": 1},
            "bad.html": {"ids": ["o3d_lsmesh.wanted"], "min_images": 3},
        }
        failures, n_pages, n_images, _ = check(site, pages=pages, timeout=60.0)
    expected = [
        "bad.html: no element with id 'o3d_lsmesh.wanted'",
        "bad.html: 2 images, expected at least 3",
        "bad.html: image corrupt.png did not render",
        "bad.html: image gone.png did not render",
        "bad.html: image file gone.png missing from the build",
        "bad.html: broken link to missing.html",
    ]
    if sorted(failures) != sorted(expected) or (n_pages, n_images) != (2, 3):
        raise SystemExit(
            f"check_site: self-test failed: the checker reported {failures} on {n_pages} pages, "
            f"{n_images} images; expected {expected} on 2 pages, 3 images"
        )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--self-test"]:
        self_test()
        print(
            "check_site: self-test passed (missing anchor, corrupt and missing images, broken link are caught)"
        )
        return 0
    build = Path(argv[0] if argv else HERE / "_build" / "html").resolve()
    failures, n_pages, n_images, n_math = check(build)
    if failures:
        print("check_site: FAILED\n  " + "\n  ".join(failures))
        return 1
    print(
        f"check_site: {n_pages} pages loaded in Chromium, {n_images} images and {n_math} equations rendered, "
        f"every public name's page has its anchor ({build})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
