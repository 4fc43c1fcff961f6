"""The documentation site builds offline with warnings as errors (its gallery's examples run
during the build, each drawing its figure), covers every public module in its API reference,
and the examples of "Bring the pieces into Python" run as printed, each on its own."""

import re
import shutil
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
    # a section's title above a constant (``# -- write-ahead journals ----``) is not its text
    from snn_antenna.core import files
    assert "YOURS" not in source_comments.module_constants(Path(files.__file__).read_text())


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


# -- every page at a desktop's and a phone's width ------------------------------------------------
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

#: the widths a page must read cleanly at: a desktop's and a phone's (CSS pixels)
WIDTHS = {"desktop": {"width": 1400, "height": 900}, "phone": {"width": 390, "height": 844}}

# What a reader cannot read in the article: a table, code block, figure or formula wider
# than the article unless a box between them scrolls sideways (a scroll bar), one cut by a box
# that hides what overflows, an image that did not load, and a page that scrolls sideways.
OVERFLOW_JS = """() => {
  const problems = [];
  const root = document.querySelector('article.bd-article') || document.querySelector('main')
    || document.body;
  const doc = document.documentElement;
  if (doc.scrollWidth > doc.clientWidth + 1)
    problems.push(`the page scrolls sideways (${doc.scrollWidth} px in ${doc.clientWidth} px)`);
  const overflowX = el => getComputedStyle(el).overflowX;
  const bounds = root.getBoundingClientRect();
  const name = el => el.tagName.toLowerCase() + (el.className && typeof el.className === 'string'
    ? '.' + el.className.trim().split(/\\s+/).join('.') : '') + ' "'
    + (el.textContent || el.getAttribute('src') || '').trim().slice(0, 50) + '"';
  for (const el of root.querySelectorAll(
      'table, pre, img, figure, svg, mjx-container, .math, iframe, video, canvas, code, dl')) {
    const r = el.getBoundingClientRect();
    if (r.width === 0 && r.height === 0) continue;
    if (el.tagName === 'IMG' && !(el.complete && el.naturalWidth > 0)) {
      problems.push(`an image that is not shown: ${name(el)}`);
      continue;
    }
    const spills = el.scrollWidth > el.clientWidth + 1;
    if (['hidden', 'clip'].includes(overflowX(el)) && spills)
      problems.push(`cut without a scroll bar: ${name(el)}`);
    if (['auto', 'scroll'].includes(overflowX(el))) continue;      // it scrolls itself
    // what it shows reaches as far as its content when that spills out of its box
    const right = spills && overflowX(el) === 'visible'
      ? Math.max(r.right, r.left + el.scrollWidth) : r.right;
    let box = el.parentElement, verdict = null;
    while (box && box !== root) {
      const style = overflowX(box), b = box.getBoundingClientRect();
      if (style === 'auto' || style === 'scroll') { verdict = 'scrolls'; break; }
      if ((style === 'hidden' || style === 'clip')
          && (right > b.right + 1 || r.left < b.left - 1)) {
        verdict = 'cut'; break;
      }
      box = box.parentElement;
    }
    if (verdict === 'cut') problems.push(`cut without a scroll bar: ${name(el)}`);
    else if (verdict === null && (right > bounds.right + 1 || r.left < bounds.left - 1))
      problems.push(`wider than the page (${Math.round(right - r.left)} px in `
                    + `${Math.round(bounds.width)} px): ${name(el)}`);
  }
  return problems;
}"""


def overflow_problems(site: Path, pages: list[Path]) -> dict[str, list[str]]:
    """Each page's overflow problems at each of :data:`WIDTHS`, by ``page @ width``."""
    playwright = pytest.importorskip("playwright.sync_api")
    found = {}
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                    args=["--no-sandbox"])
        try:
            for width, viewport in WIDTHS.items():
                tab = browser.new_page(viewport=viewport)
                tab.route("http*://**", lambda route: route.abort())   # offline, as built
                for page in pages:
                    tab.goto(page.as_uri(), wait_until="load")
                    problems = tab.evaluate(OVERFLOW_JS)
                    if problems:
                        found[f"{page.relative_to(site)} @ {width}"] = problems
                tab.close()
        finally:
            browser.close()
    return found


@pytest.mark.slow    # the site's build, then every page twice in Chromium
@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
def test_every_page_reads_cleanly_at_a_desktops_and_a_phones_width(site):
    pages = sorted(p for p in site.rglob("*.html")
                   if not p.relative_to(site).parts[0].startswith(("_", "genindex", "search")))
    assert len(pages) > 30
    found = overflow_problems(site, pages)
    assert not found, "pages that do not read cleanly:\n" + "\n".join(
        f"{page}: {'; '.join(problems[:3])}" for page, problems in sorted(found.items())[:20])


@pytest.mark.slow    # Chromium: seconds, beside the site's own check
@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
def test_the_width_check_finds_a_cut_table_and_a_wide_code_block(tmp_path):
    """A wide table in a box that hides its overflow, and a code block that neither wraps nor
    scrolls, are caught at a phone's width; the same in a scrolling box is not."""
    row = "<tr>" + "<td>a_long_cell_value</td>" * 12 + "</tr>"
    page = tmp_path / "page.html"
    page.write_text(
        "<!doctype html><meta name='viewport' content='width=device-width'>"
        "<article class='bd-article'>"
        f"<div style='overflow-x:hidden'><table>{row}</table></div>"
        "<pre style='overflow:visible;white-space:pre'>" + "x" * 200 + "</pre>"
        f"<div style='overflow-x:auto'><table>{row}</table></div></article>")
    found = overflow_problems(tmp_path, [page])
    phone = found["page.html @ phone"]
    assert any("cut without a scroll bar: table" in p for p in phone)
    assert any("wider than the page" in p and p.endswith('"' + "x" * 50 + '"') for p in phone)
    assert sum("table" in p for p in phone) == 1          # the scrolling one is fine
