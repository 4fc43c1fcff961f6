"""The documentation site builds offline with warnings as errors, covers every public module in
its API reference, and the examples of "Bring the pieces into Python" run as printed."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PACKAGE = ROOT / "snn_antenna"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("sphinx")
    pytest.importorskip("pydata_sphinx_theme")
    pytest.importorskip("myst_parser")
    out = tmp_path_factory.mktemp("site")
    # the API pages are generated into docs/api/generated (ignored by git) and rebuilt each time
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-q",
            "-E",
            "-b",
            "html",
            "-d",
            str(out / "doctrees"),
            str(DOCS),
            str(out / "html"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert done.returncode == 0, f"the site does not build:\n{done.stderr[-4000:]}"
    return out / "html"


@pytest.mark.slow    # a minute of Sphinx: .ci/run builds the site on every submission
def test_the_site_builds_with_warnings_as_errors(site):
    for page in [
        "index",
        "guide/quickstart",
        "guide/tuning_sweep",
        "guide/gating_threshold",
        "guide/baseline_comparison",
        "guide/speed_accuracy",
        "guide/bridge",
        "guide/exploration",
        "guide/python",
        "guide/cluster",
        "guide/files",
        "results",
        "reference",
        "materials",
        "live",
        "contributing",
        "changelog",
    ]:
        assert (site / f"{page}.html").is_file(), page


@pytest.mark.slow    # a minute of Sphinx: .ci/run builds the site on every submission
def test_the_api_reference_covers_every_public_module(site):
    modules = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for p in PACKAGE.rglob("*.py")
        if not p.name.startswith("_") or p.name == "__init__.py"
    }
    modules = {m for m in modules if not any(part.startswith("_") for part in m.split("."))}
    pages = {p.stem for p in (site / "api" / "generated").glob("*.html")}
    assert modules - pages == set(), f"modules without an API page: {sorted(modules - pages)}"
    text = (site / "api" / "generated" / "snn_antenna.networks.neurons.html").read_text()
    assert "k_for_frequency" in text  # members are documented, not just listed


@pytest.mark.slow    # a minute of Sphinx: .ci/run builds the site on every submission
def test_every_guide_image_and_page_link_resolves(site):
    for page in site.rglob("*.html"):
        html = page.read_text()
        for src in re.findall(r'<img[^>]+src="([^"]+)"', html):
            if not src.startswith(("http", "data:")):
                assert (page.parent / src).is_file(), f"{page.name}: image {src} is missing"


def test_the_python_examples_run_as_printed(monkeypatch):
    monkeypatch.chdir(ROOT)  # they read docs/results/ like a user's checkout
    text = (DOCS / "guide" / "python.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 3
    namespace: dict = {}
    for code in blocks:
        exec(compile(code, "docs/guide/python.md", "exec"), namespace)
    assert namespace["rates"].sizes["neuron_hz"] == 24
    assert namespace["outcome"].data.spike_count.shape == (2, 3)
    assert namespace["summary"]["provenance"]["snn_antenna_version"]
