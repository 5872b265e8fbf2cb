"""The documentation site builds (API reference from the docstrings) and names every public
name; the public API documents its units."""

import inspect
import os
import re
import shutil
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

import dischargelab as dl

REPO = Path(__file__).resolve().parents[1]
PUBLIC_FUNCTIONS = ["read", "fit", "load", "predict", "endurance", "validate"]


def inventory(path: Path) -> dict[str, str]:
    """Sphinx's objects.inv: object name -> its role (``py:function``, ``std:doc`` ...)."""
    header, _, body = path.read_bytes().partition(b"zlib.\n")
    assert header.startswith(b"# Sphinx inventory version 2"), header[:60]
    names = {}
    for line in zlib.decompress(body).decode("utf-8").splitlines():
        name, role = line.split(" ", 2)[:2]
        names[name] = role
    return names


def public_names(page: str) -> tuple[set[str], set[str], set[str]]:
    """From docs/python.md: the ``dl.X`` functions, the result and error classes named in
    backticks, and ``Class.member`` for the members its table lists after a class."""
    functions = set(re.findall(r"\bdl\.([a-z_]\w*)", page))
    classes = set(re.findall(r"`([A-Z][a-z]+(?:[A-Z][a-z]*)*)`", page))
    classes |= set(re.findall(r"\bdl\.([A-Z]\w*)", page))
    members = set()
    for row in re.findall(r"^\|.*\|$", page, re.M):
        for cell in row.split("|"):
            owner = re.match(r"\s*`([A-Z]\w+)`", cell)
            if owner:
                members.update(f"{owner[1]}.{m}" for m in re.findall(r"`\.(\w+)", cell))
    return functions, classes, members


@pytest.fixture(scope="module")
def built_site(tmp_path_factory) -> Path:
    """The documentation site built from a copy of docs/ (the gallery and the guides' example
    commands not run: `make docs` runs them), warnings as errors: its objects.inv."""
    try:
        import myst_parser  # noqa: F401
        import numpydoc  # noqa: F401
        import pydata_sphinx_theme  # noqa: F401
        import sphinx  # noqa: F401
        import sphinx_gallery  # noqa: F401
    except ImportError as exc:
        if os.environ.get("CI"):
            pytest.fail(f"the docs extra is required in CI (make docs installs it): {exc}")
        pytest.skip(f"the docs extra is not installed: {exc}")
    root = tmp_path_factory.mktemp("site")
    shutil.copytree(REPO / "docs", root / "docs",
                    ignore=shutil.ignore_patterns("_build", "generated", "gallery",
                                                  "sg_execution_times.rst"))
    for name in ("src", "examples"):
        (root / name).symlink_to(REPO / name)
    # a page just added, that no toctree names yet, joins the user guide
    (root / "docs" / "new-page.md").write_text("# A new page\n\nJust added.\n")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                           "html", "-D", "plot_gallery=0", "-D", "guide_commands_run=0",
                           str(root / "docs"),
                           str(root / "html")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return root / "html"


@pytest.mark.slow
def test_every_public_name_in_python_md_resolves_in_the_api_reference(built_site):
    names = inventory(built_site / "objects.inv")
    functions, classes, members = public_names((REPO / "docs" / "python.md").read_text())
    assert {"read", "fit", "load", "predict", "endurance", "validate"} <= functions
    assert {"FitResult", "Battery", "Prediction", "DataError"} <= classes
    assert "FitResult.report" in members and "Battery.with_pack" in members
    for name in sorted(functions):
        assert names.get(f"dischargelab.{name}") == "py:function", name
    documented: dict[str, list[str]] = {}          # class name -> its full names
    for full, role in names.items():
        if role in ("py:class", "py:exception"):
            documented.setdefault(full.rsplit(".", 1)[-1], []).append(full)
    for name in sorted(classes):
        assert name in documented, f"{name} is not in the API reference"
    for name in sorted(members):
        cls, member = name.split(".")
        assert any(f"{full}.{member}" in names for full in documented[cls]), \
            f"{name} is not in the API reference"
    # every page of docs/ is in the site, and the site loads nothing from elsewhere
    for page in (REPO / "docs").glob("*.md"):
        assert (built_site / f"{page.stem}.html").exists(), page.name
    assert (built_site / "generated" / "dischargelab.fit.html").exists()
    assert 'href="new-page.html"' in (built_site / "guide.html").read_text(encoding="utf-8")


@pytest.mark.parametrize("name", PUBLIC_FUNCTIONS)
def test_public_functions_have_numpydoc_sections_and_type_hints(name):
    func = getattr(dl, name)
    doc = inspect.getdoc(func)
    assert doc and "Parameters\n----------" in doc and "Returns\n-------" in doc, name
    hints = inspect.signature(func).parameters
    assert all(p.annotation is not inspect.Parameter.empty
               for p in hints.values() if p.kind is not p.VAR_KEYWORD), name


def test_physical_parameters_state_their_units():
    doc = inspect.getdoc(dl.predict)
    for param in ("current", "power", "cutoff, cutoff_pack", "ambient", "soc"):
        block = re.search(rf"^{re.escape(param)} :.*\n((?:    .*\n)+)", doc + "\n", re.M)
        assert block and "[" in block.group(1), param


def test_readme_is_a_landing_page_whose_links_resolve():
    """At most 220 lines, exactly the two set-up commands, and every relative link (pages,
    the picture) points at a file of the repository, so it works on the forge unbuilt."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 220
    setup = re.search(r"## Set up and run.*?```\n(.*?)```", text, re.S)
    assert setup, "no set-up block"
    commands = [line.split("#")[0].strip() for line in setup.group(1).splitlines()]
    assert commands == ["make demo", "make test"]
    links = re.findall(r"\]\((?!https?:)([^)#]+)", text)
    assert any(link.endswith(".png") for link in links)
    for link in links:
        assert (REPO / link).exists(), link
