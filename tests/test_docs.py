"""The documentation site builds offline with warnings as errors (its gallery's examples run
during the build, each drawing its figure), covers every public module in its API reference,
and the examples of "Bring the pieces into Python" run as printed, each on its own."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

from doc_blocks import blocks, run_python

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PACKAGE = ROOT / "snn_antenna"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("sphinx")
    pytest.importorskip("pydata_sphinx_theme")
    pytest.importorskip("myst_parser")
    pytest.importorskip("sphinx_gallery")
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
        "install",
        "tutorial",
        "troubleshooting",
        "developer",
        "gallery/index",
        "guide/quickstart",
        "guide/tuning_sweep",
        "guide/gating_threshold",
        "guide/baseline_comparison",
        "guide/model_selection",
        "guide/bank_tuning",
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
def test_the_api_pages_describe_each_setting_and_the_cited_constants(site):
    gate = (site / "api" / "generated" / "snn_antenna.networks.gate.html").read_text()
    assert "in units of the preferred-speed spacing" in gate     # a field's comment
    neurons = (site / "api" / "generated" / "snn_antenna.networks.neurons.html").read_text()
    assert "neurons.MAX_STABLE_K_DT" in neurons and "stays finite for every" in neurons


def test_a_fields_and_a_constants_comment_become_their_api_description():
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import source_comments
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    from snn_antenna.networks import gate, neurons

    section = source_comments.parameters_section(gate.SpeedGate)
    at = section.index("tuning_width : float, default ``1.0``")
    assert "preferred-speed spacing" in section[at + 1]
    # a field without a comment has its type and default and no invented description
    at = section.index("n_speed_neurons : int, default ``7``")
    assert not section[at + 1].startswith("    ")
    constants = source_comments.module_constants(Path(neurons.__file__).read_text())
    assert constants["MAX_STABLE_K_DT"].startswith("Largest k·dt")
    assert constants["V_PEAK"] == "spike cut-off, the model's threshold"
    assert "PRESETS" not in constants          # no comment beside it: nothing to show


@pytest.mark.slow    # a minute of Sphinx: .ci/run builds the site on every submission
def test_every_guide_image_and_page_link_resolves(site):
    for page in site.rglob("*.html"):
        html = page.read_text()
        for src in re.findall(r'<img[^>]+src="([^"]+)"', html):
            if not src.startswith(("http", "data:")):
                assert (page.parent / src).is_file(), f"{page.name}: image {src} is missing"


@pytest.mark.slow    # a minute of Sphinx: .ci/run builds the site on every submission
def test_the_gallery_runs_every_example_at_build_and_shows_its_figure(site):
    scripts = sorted((DOCS / "examples").glob("plot_*.py"))
    assert len(scripts) >= 8
    for script in scripts:
        page = (site / "gallery" / f"{script.stem}.html").read_text()
        assert re.search(rf'<img[^>]+src="[^"]*sphx_glr_{script.stem}_\d+\.png"', page), \
            f"{script.name}: no figure on its page"
        # and it can be downloaded as a script and as a notebook
        assert "sphx-glr-download-python" in page and "sphx-glr-download-jupyter" in page
    # and the API page of a module an example uses lists that example
    neurons = (site / "api" / "generated" / "snn_antenna.networks.neurons.html").read_text()
    assert "plot_1_neuron_tuning" in neurons


# What each block of the Python guide leaves behind, checked in its own interpreter: the
# comment beside the first block says the k = 0.34 neuron fires on 6 of the 7 cycles.
PYTHON_GUIDE_CHECKS = [
    "assert list(result.spike_counts) == [0, 6, 0]",
    "assert rates.sizes['neuron_hz'] == 24",
    "assert outcome.data.spike_count.shape == (2, 3)",
    "assert summary['provenance']['snn_antenna_version']",
]


@pytest.mark.parametrize("index", range(len(PYTHON_GUIDE_CHECKS)))
def test_each_python_example_runs_on_its_own_from_any_folder(index, tmp_path):
    code = [b.code for b in blocks(DOCS / "guide" / "python.md") if b.language == "python"]
    assert len(code) == len(PYTHON_GUIDE_CHECKS)
    done = run_python(code[index] + "\n" + PYTHON_GUIDE_CHECKS[index], tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert list(tmp_path.iterdir()) == []          # nothing written where it ran
