"""Sphinx configuration of the dischargelab documentation site (``make docs``).

Markdown pages (MyST) from this folder, the API reference from the numpydoc docstrings
(autodoc + autosummary + numpydoc), and a gallery made by running ``examples/`` at build
time (sphinx-gallery). The build is offline: no intersphinx, no remote assets; warnings
are errors (``-W`` in the Makefile).
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(HERE / "_ext"))

import dischargelab  # noqa: E402

project = "dischargelab"
author = "dischargelab developers"
copyright = "dischargelab developers"
release = dischargelab.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "guide_commands",          # the guides' {example-commands} blocks run on the example set
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "gallery/*.ipynb", "gallery/*.py", "gallery/*.zip",
                    "gallery/*.md5", "gallery/*.json", "gallery/sg_execution_times.rst"]
# The pages are also read on the forge as plain Markdown: headings give anchors there and here.
myst_heading_anchors = 3
myst_enable_extensions = ["deflist"]
# numpydoc References sections list sources without citing each in the text; the gallery's
# configuration holds callables (the environment is rebuilt each time, which `make docs` does)
suppress_warnings = ["ref.citation", "config.cache"]

# ---- API reference -------------------------------------------------------------------------
autosummary_generate = True
autodoc_default_options = {"members": True, "inherited-members": False}
autodoc_typehints = "none"           # numpydoc's Parameters section says the types
numpydoc_show_class_members = False  # autodoc documents the members itself
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()
add_module_names = False

# ---- gallery: examples/ run at build time, their figures captured ---------------------------
GALLERY_OUT = HERE / "_build" / "gallery-out"


def _example_argv(gallery_conf, script_vars):
    """Each example writes its files into its own folder under _build (never the checkout)."""
    name = Path(script_vars["src_file"]).stem
    out = GALLERY_OUT / name
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    return ["--out", str(out)]


class WrittenFiles:
    """Scraper: the PNG figures an example wrote into its --out folder, and its HTML
    report as a download (the examples save and close their figures themselves)."""

    def __repr__(self) -> str:  # sphinx-gallery keys its cache on this
        return "WrittenFiles"

    def __call__(self, block, block_vars, gallery_conf):
        from sphinx_gallery.scrapers import figure_rst

        out = GALLERY_OUT / Path(block_vars["src_file"]).stem
        images = []
        for png in sorted(out.rglob("*.png")):
            target = Path(next(block_vars["image_path_iterator"]))
            shutil.copyfile(png, target)
            images.append(str(target))
        rst = figure_rst(images, gallery_conf["src_dir"]) if images else ""
        for page in sorted(out.rglob("*.html")):
            where = "/" + page.relative_to(HERE).as_posix()      # from the source folder
            rst += (f"\n\nThe page it wrote: :download:`{page.name} <{where}>` "
                    "(self-contained; open it in a browser).\n\n")
        return rst


sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "gallery",
    "filename_pattern": r".*\.py$",       # every example runs
    "reset_argv": _example_argv,
    "image_scrapers": (WrittenFiles(),),
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_signature": False,
    "write_computation_times": False,     # its page loads tables from a CDN
}

# ---- HTML -----------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"dischargelab {release}"
html_static_path = ["_static"]
html_css_files = ["site.css"]
html_show_sourcelink = False
html_theme_options = {
    "navbar_align": "left",
    "show_toc_level": 2,
    "navigation_with_keys": False,
    "footer_start": ["copyright"],
    "footer_end": [],
    "secondary_sidebar_items": ["page-toc"],
    "header_links_before_dropdown": 6,
}
html_context = {"default_mode": "auto"}     # light or dark, as the reader's system says
html_sidebars = {"index": [], "method": [], "benchmarks": []}


# ---- pages other people add -----------------------------------------------------------------
TOCTREE = re.compile(r"```\{toctree\}(.*?)```", re.S)


def listed_pages() -> set[str]:
    """Every page named in a toctree of this folder's Markdown pages."""
    names = set()
    for page in HERE.rglob("*.md"):
        if "_build" in page.parts:
            continue
        for block in TOCTREE.findall(page.read_text(encoding="utf-8")):
            names.update(line.strip() for line in block.splitlines()
                         if line.strip() and not line.strip().startswith(":"))
    return names


def unlisted_pages() -> list[str]:
    """Markdown pages of this folder that no toctree names (a page just added)."""
    listed = listed_pages()
    return sorted(p.stem for p in HERE.glob("*.md") if p.stem not in listed | {"index"})


#: A Markdown link out of this folder (``[text](../DESIGN.md#x)``): it works on the forge,
#: where the repository's files are; in the site it becomes the file's name.
REPOSITORY_LINK = re.compile(r"\[([^\]]+)\]\(\.\./([^)#\s]+)(#[^)\s]*)?\)")


def repository_links(app, docname, source):
    """Links from a page to the repository's own files name the file instead."""
    source[0] = REPOSITORY_LINK.sub(lambda m: f"{m[1]} (`{m[2]}` in the repository)",
                                    source[0])


def add_new_pages(app, docname, source):
    """A page nobody has placed yet joins the user guide, at its end."""
    if docname != "guide":
        return
    extra = unlisted_pages()
    if extra:
        source[0] += ("\n\n```{toctree}\n:caption: More\n:maxdepth: 1\n\n"
                      + "\n".join(extra) + "\n```\n")


#: A script, stylesheet, font or image the reader's browser would fetch from elsewhere.
REMOTE_ASSET = re.compile(
    r"<(?:script|link|img|source|iframe)\b[^>]*\b(?:src|href)=[\"'](?:https?:)?//", re.I)


def no_remote_assets(app, exception):
    """The site must read offline: refuse a page that loads anything from elsewhere."""
    if exception is not None or app.builder.format != "html":
        return
    bad = [str(page.relative_to(app.outdir)) for page in Path(app.outdir).rglob("*.html")
           if REMOTE_ASSET.search(page.read_text(encoding="utf-8", errors="replace"))]
    if bad:
        from sphinx.errors import ExtensionError

        raise ExtensionError(f"pages load remote assets (no CDN: the site reads offline): "
                             f"{', '.join(sorted(bad)[:10])}")


def setup(app):
    app.connect("build-finished", no_remote_assets)
    app.connect("source-read", repository_links)
    app.connect("source-read", add_new_pages)
