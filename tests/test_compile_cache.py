"""An estimate charges a compile only to a network that is not compiled yet: a standalone
project found on disk (``engine.standalone.is_built``) or a cython network this interpreter
ran before (``networks.runtime_cache``) costs its code generation alone."""
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.engine import cost, rates
from snn_antenna.engine.codings import structure
from snn_antenna.engine.standalone import BUILT_MARKER, is_built, structure_key
from snn_antenna.networks import runtime_cache
from snn_antenna.networks.resonators import OFFLINE_NETWORK, ResonatorArray
from snn_antenna.studies import runner


@pytest.fixture
def empty_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SNN_ANTENNA_CACHE", str(tmp_path))
    # the load the table was measured at, through every estimate of a test
    monkeypatch.setattr(rates, "competing_load", lambda: rates.TABLE_LOAD)
    return tmp_path


def fake_build(cache, structure_, binary=True, slot=0):
    """A project directory as ``standalone.project`` leaves it after its build."""
    folder = cache / "brian2_standalone" / f"{structure_key(structure_)}ff-{slot}"
    folder.mkdir(parents=True)
    (folder / BUILT_MARKER.format(structure_key(structure_))).write_text("built\n")
    if binary:
        (folder / "main").write_text("")
    return folder


def test_a_project_counts_as_compiled_only_with_its_marker_and_its_binary(empty_cache):
    array = ResonatorArray(n_neurons=6)
    mine, other = structure(array, 400, 1000.0, 3), structure(array, 400, 1000.0, 4)
    assert not is_built(mine)
    fake_build(empty_cache, mine, binary=False)         # a build that did not finish
    assert not is_built(mine)
    fake_build(empty_cache, mine, slot=1)
    assert is_built(mine) and not is_built(other)


def test_a_compiled_network_costs_its_code_generation_not_a_compile(empty_cache):
    table = rates.rates()
    run = (1.0, 0.1, 240, "codings")
    cold = cost.job_estimate("x", [run + (cost.Build("p", False),)])
    warm = cost.job_estimate("x", [run + (cost.Build("p", True),)])
    assert cold.seconds - warm.seconds == pytest.approx(
        table["compile_s"]["codings"].value - table["rebuild_s"]["codings"].value)
    assert "compiling" in cold.describe() and "compiling" not in warm.describe()
    # runs of one network share its build; two networks are two builds
    twice = cost.job_estimate("x", [run + (cost.Build("p", False),)] * 3)
    two = cost.job_estimate("x", [run + (cost.Build("p", False),),
                                  run + (cost.Build("q", False),)])
    assert two.parts["compiling"] == pytest.approx(2 * twice.parts["compiling"])
    # a numpy network compiles nothing
    assert cost.build_seconds("numpy", cost.Build("p", False)) == 0.0


def gating_quick():
    spec = specs.load("studies/gating_threshold.toml", [], quick=True)
    return runner("gating_threshold").plan(spec)


def test_the_gating_estimate_is_lower_with_its_codings_project_compiled(empty_cache):
    plan = gating_quick()
    cold = plan.estimate()
    parts, sw = plan.parts, plan.parts.sweep
    fake_build(empty_cache, structure(parts.array, round(sw.scene_s * parts.scene.rate_hz),
                                      parts.scene.rate_hz, sw.codings_per_run))
    warm = gating_quick().estimate()
    table = rates.rates()
    saved = table["compile_s"]["codings"].value - table["rebuild_s"]["codings"].value
    assert cold.seconds - warm.seconds == pytest.approx(saved)
    assert "compiled before" in warm.describe()


def test_the_quickstart_estimate_is_lower_once_its_network_ran_on_cython(empty_cache):
    spec = specs.load("studies/quickstart.toml", [], quick=True)
    plan = runner("quickstart").plan(spec)
    assert plan.parts.array.target == "cython"
    cold = plan.estimate().seconds
    runtime_cache.note(OFFLINE_NETWORK, "snn_antenna.networks.resonators", "cython")
    warm = runner("quickstart").plan(spec).estimate().seconds
    assert cold - warm == pytest.approx(
        rates.rates()["compile_s"]["cython"].value)
    # numpy leaves no marker: it compiles nothing
    assert ResonatorArray(target="numpy").compiled()


def test_the_tuning_sweep_estimate_is_lower_with_its_project_compiled(empty_cache):
    from snn_antenna.engine.standalone import sweep_elements, sweep_structure

    spec = specs.load("studies/tuning_sweep.toml", [], quick=False)
    plan = runner("tuning_sweep").plan(spec)
    assert plan.parts.neuron.engine == "standalone"
    cold = plan.estimate()
    chunk = plan.parts.settings.chunk_points
    neuron = plan.parts.neuron.for_grid(plan.parts.grid, plan.parts.grid.block_shape(chunk))
    fake_build(empty_cache, sweep_structure(neuron, sweep_elements(neuron,
                                                                    neuron.group_size)))
    warm = runner("tuning_sweep").plan(spec).estimate()
    assert warm.seconds < cold.seconds and "compiled before" in warm.describe()


def test_the_tuning_estimate_asks_for_the_project_its_chunks_compile(monkeypatch):
    """The structure the estimate looks for is the one a chunk of the run builds."""
    import numpy as np

    from snn_antenna.engine import standalone

    compiled = []

    def project(structure_, build):
        compiled.append(structure_)
        raise RuntimeError("built nothing")
    monkeypatch.setattr(standalone, "project", project)
    plan = runner("tuning_sweep").plan(specs.load("studies/tuning_sweep.toml", [],
                                                  quick=False))
    chunk = plan.parts.settings.chunk_points
    neuron = plan.parts.neuron.for_grid(plan.parts.grid, plan.parts.grid.block_shape(chunk))
    points = {name: np.full(neuron.group_size, 1.0)
              for name in ("k", "a", "b", "c", "d", "input_hz", "I")}
    with pytest.raises(RuntimeError, match="built nothing"):
        standalone.standalone_counts(neuron, points)
    asked = []
    monkeypatch.setattr(cost, "is_built", lambda s: asked.append(s) or False)
    plan.estimate()
    assert compiled and compiled[0] in asked


def test_the_exploration_estimate_is_lower_once_its_loop_ran_on_cython(empty_cache):
    from snn_antenna.studies.exploration.plan import LOOP_MODULE, loop_network, loop_target

    spec = specs.load("studies/exploration.toml", [], quick=False)
    plan = runner("exploration").plan(spec)
    assert loop_target(plan.parts.configured) == "cython"
    cold = plan.estimate().seconds
    for name in plan.parts.configured:
        runtime_cache.note(loop_network(name), LOOP_MODULE, "cython")
    warm = runner("exploration").plan(spec).estimate().seconds
    from snn_antenna.studies.exploration.plan import LOOP_PART_COMPILES

    assert cold - warm == pytest.approx(len(plan.parts.configured) * LOOP_PART_COMPILES
                                        * rates.rates()["compile_s"]["cython"].value)
