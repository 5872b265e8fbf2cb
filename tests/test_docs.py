"""The API reference builds from the docstrings, and the public API documents its units."""

import inspect
import re

import pytest

import dischargelab as dl

PUBLIC_FUNCTIONS = ["read", "fit", "load", "predict", "endurance", "validate"]


def test_api_reference_builds(tmp_path):
    pdoc = pytest.importorskip("pdoc")
    pdoc.render.configure(docformat="numpy")
    pdoc.pdoc("dischargelab", "dischargelab.models", "dischargelab.engine",
              output_directory=tmp_path)
    page = (tmp_path / "dischargelab.html").read_text()
    for name in PUBLIC_FUNCTIONS:
        assert f'id="{name}"' in page, name
    assert (tmp_path / "dischargelab" / "models.html").stat().st_size > 10_000


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
