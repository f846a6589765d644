"""mkdocs hooks: add the pages generated from the code (docs/gen_pages.py) and the gallery
(docs/gen_gallery.py, which runs the examples) to the site, and the API pages to the nav.

Nothing is written into docs/: the pages exist only in the build (``mkdocs build`` or
``mkdocs serve``). ``SLIPSTEP_DOCS_GALLERY=0`` skips running the examples (the gallery pages
then say so), for quick edits of the prose.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import time
from pathlib import Path

from mkdocs.structure.files import File

HERE = Path(__file__).resolve().parent


def _load(name: str):
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def on_config(config):
    """Replace the ``API reference`` and ``Gallery`` entries of the nav by the generated pages."""
    gen = _load("gen_pages")
    gallery = _load("gen_gallery")
    nav = config["nav"] or []
    for item in nav:
        if isinstance(item, dict) and "API reference" in item:
            item["API reference"] = gen.api_nav()
        if isinstance(item, dict) and "Gallery" in item:
            item["Gallery"] = gallery.gallery_nav()
    extra = _unlisted_pages(config["docs_dir"], nav)
    if extra:  # a page someone added without a nav entry still gets one (and a note in the build log)
        nav.append({"More": [{_title(Path(config["docs_dir"]) / page): page} for page in extra]})
        print(f"INFO    -  slipstep: pages not in mkdocs.yml's nav, listed under 'More': {extra}", file=sys.stderr)
    return config


def _leaves(nav):
    for item in nav:
        for value in item.values() if isinstance(item, dict) else [item]:
            yield from _leaves(value) if isinstance(value, list) else [value]


def _unlisted_pages(docs_dir: str, nav) -> list[str]:
    listed = set(_leaves(nav))
    pages = [p.relative_to(docs_dir).as_posix() for p in sorted(Path(docs_dir).rglob("*.md"))]
    return [p for p in pages if p not in listed]


def _title(path: Path) -> str:
    for line in path.read_text().splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return path.stem.replace("_", " ").capitalize()


def on_files(files, config):
    gen = _load("gen_pages")
    gallery = _load("gen_gallery")
    start = time.perf_counter()
    pages = gen.all_pages()
    run_examples = os.environ.get("SLIPSTEP_DOCS_GALLERY", "1") != "0"
    pages.update(gallery.gallery_pages(run=run_examples))
    for uri, content in pages.items():
        existing = files.get_file_from_path(uri)
        if existing is not None:
            files.remove(existing)
        files.append(File.generated(config, uri, content=content))
    print(
        f"INFO    -  slipstep: {len(pages)} generated pages and figures in {time.perf_counter() - start:.1f} s",
        file=sys.stderr,
    )
    return files
