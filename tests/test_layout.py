"""The package's layout shows its data flow, and imports follow it.

core → report → sources → preprocess → networks → readout → evaluation → engine → studies →
bridge (wire → emulate → online → view) → cli. ``core`` (errors, bounds, specs, files, output
folders, provenance, stores, run log, recordings and their ground truth) and ``report`` (the
page, its style, figures, statistics) are what every stage may use. A module may import from
its own stage or an earlier one, never from a later one, and no two modules import each other,
directly or through others (imports inside functions count: a lazy import is still a
dependency). Nothing in the package lies flat at its root but the stages, ``preprocess`` and
``cli``.

Read-outs are blind by construction: no module of ``snn_antenna.readout`` imports
``snn_antenna.core.truth`` (where a recording's labels live), reads an attribute named
``truth`` or names one of the bench's labels (``truth.BENCH_LABELS``) in its code.
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "snn_antenna"

# Stages in data-flow order; a module belongs to the first prefix it matches.
STAGES = [
    ("core", ["snn_antenna", "snn_antenna.core"]),
    ("report", ["snn_antenna.report"]),
    ("sources", ["snn_antenna.sources"]),
    ("preprocess", ["snn_antenna.preprocess"]),
    ("networks", ["snn_antenna.networks"]),
    ("readout", ["snn_antenna.readout"]),
    ("evaluation", ["snn_antenna.evaluation"]),
    ("engine", ["snn_antenna.engine"]),
    ("studies", ["snn_antenna.studies"]),
    ("bridge.wire", ["snn_antenna.bridge", "snn_antenna.bridge.wire"]),
    ("bridge.emulate", ["snn_antenna.bridge.emulate"]),
    ("bridge.online", ["snn_antenna.bridge.online"]),
    ("bridge.view", ["snn_antenna.bridge.view"]),
    ("bridge.cli", ["snn_antenna.bridge.cli"]),
    # recordings into data sets: reads `record` folders (bridge.wire) and cuts contacts by the
    # event processing's onset rule (readout)
    ("data", ["snn_antenna.data"]),
    ("cli", ["snn_antenna.cli"]),
]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def stage_of(module: str) -> int:
    best = None
    for index, (_, prefixes) in enumerate(STAGES):
        for prefix in prefixes:
            if module == prefix or module.startswith(prefix + ".") and prefix != "snn_antenna":
                if best is None or len(prefix) > best[1]:
                    best = (index, len(prefix))
    assert best is not None, f"{module} belongs to no stage: add it to STAGES"
    return best[0]


def import_graph() -> dict[str, set[str]]:
    """Module → the package modules it imports (at the top or inside functions)."""
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[:len(base) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                candidates = [f"{target}.{a.name}" for a in node.names] + [target]
            elif isinstance(node, ast.Import):
                candidates = [a.name for a in node.names]
            else:
                continue
            for candidate in candidates:
                if candidate in modules:
                    targets.add(candidate)
                    break
        targets.discard(name)
        graph[name] = targets
    return graph


def test_every_module_belongs_to_a_stage():
    stages = {name: stage_of(name) for name in import_graph()}
    assert len(stages) > 50 and set(stages.values()) == set(range(len(STAGES)))


def test_imports_point_along_the_data_flow():
    graph = import_graph()
    against = [f"{src} ({STAGES[stage_of(src)][0]}) imports {dst} ({STAGES[stage_of(dst)][0]})"
               for src, targets in graph.items() for dst in sorted(targets)
               if stage_of(dst) > stage_of(src)]
    assert not against, "imports against the data flow:\n" + "\n".join(against)


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}               # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(node):
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt == "snn_antenna":         # the package's __init__ (its version) only
                continue
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def test_no_import_cycles():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_the_checks_catch_what_they_forbid():
    """The graph walk sees real edges, and both checks fire on a planted violation."""
    graph = import_graph()
    assert "snn_antenna.networks.neurons" in graph["snn_antenna.networks.resonators"]
    assert "snn_antenna.engine.standalone" in graph["snn_antenna.engine.evaluators"]
    planted = {**graph, "snn_antenna.networks.neurons":
               graph["snn_antenna.networks.neurons"] | {"snn_antenna.networks.resonators"}}
    assert find_cycle(planted) is not None
    assert stage_of("snn_antenna.studies.quickstart") > stage_of("snn_antenna.readout.contacts")


# -- read-outs are blind -----------------------------------------------------------------------
def peeks(path: Path) -> list[str]:
    """Where a module's code reaches ground truth: an import of ``snn_antenna.core.truth``, an
    attribute named ``truth``, a bench label looked up (``ds["material"]``,
    ``ds.sel(repetition=0)``) or read as an attribute (``ds.material``; ``distance_cm`` is
    also a decoded distance's name, so only its look-ups count)."""
    from snn_antenna.core.truth import BENCH_LABELS

    attributes = {"truth"} | set(BENCH_LABELS) - {"distance_cm"}
    selectors = {"sel", "isel", "where", "query", "drop_sel", "assign_coords", "groupby"}
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        where = f"{path.name}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.ImportFrom):
            names = [node.module or ""] + [a.name for a in node.names]
            if any(n == "truth" or n.endswith(".truth") for n in names):
                found.append(f"{where} imports truth")
        elif isinstance(node, ast.Import):
            if any(a.name.endswith(".truth") for a in node.names):
                found.append(f"{where} imports truth")
        elif isinstance(node, ast.Attribute) and node.attr in attributes:
            found.append(f"{where} reads .{node.attr}")
        elif (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
              and node.slice.value in BENCH_LABELS):
            found.append(f"{where} looks up the label {node.slice.value!r}")
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr in selectors):
            labels = [k.arg for k in node.keywords if k.arg in BENCH_LABELS]
            labels += [a.value for a in node.args
                       if isinstance(a, ast.Constant) and a.value in BENCH_LABELS]
            if labels:
                found.append(f"{where} selects by {labels}")
    return found


def readout_modules() -> list[Path]:
    return sorted((PACKAGE / "readout").rglob("*.py"))


def test_read_outs_never_reach_ground_truth():
    found = [p for path in readout_modules() for p in peeks(path)]
    assert not found, "a read-out reaches ground truth:\n" + "\n".join(found)


def test_the_blindness_check_catches_a_peek(tmp_path):
    """Each way of peeking is caught (a planted module), and the real read-outs are scanned."""
    assert len(readout_modules()) >= 7
    planted = tmp_path / "peek.py"
    for code in ("from ..truth import GroundTruth", "import snn_antenna.core.truth",
                 "from .. import truth", "x = recording.truth.contacts", "y = ds['material']",
                 "d = ds['distance_cm'].values", "z = features.repetition",
                 "w = ds.sel(position=3)", "g = ds.groupby('material')"):
        planted.write_text(code + "\n")
        assert peeks(planted), code
    planted.write_text("from .contacts import ContactDetector\nx = rates.sel(neuron_hz=8)\n"
                       "d = estimate.distance_cm\ntask = 'material'\n")
    assert not peeks(planted)


def test_the_package_root_holds_only_the_stages():
    """A module lies in the stage it serves: at the root only the package's own ``__init__``,
    ``preprocess`` (a stage of one module) and the command line."""
    flat = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert flat == ["__init__.py", "cli.py", "preprocess.py"], flat
    bridge = sorted(p.name for p in (PACKAGE / "bridge").glob("*.py"))
    assert bridge == ["__init__.py", "cli.py"], bridge


def test_the_bridge_never_imports_the_studies():
    """The live path stands beside the studies, not on them: what it shares with them (the
    gate's training examples, the spec rules) lives below both."""
    graph = import_graph()
    found = [f"{src} imports {dst}" for src, targets in graph.items()
             if src.startswith("snn_antenna.bridge") for dst in targets
             if dst.startswith("snn_antenna.studies")]
    assert not found, "\n".join(found)


# -- imports at the top --------------------------------------------------------------------------
def lazy_imports(source: str) -> list[int]:
    """The lines of package-internal imports inside a function that give no reason: a comment
    on the import's line or on the line above it says why it waits (a heavy library that a
    refusal on the command line should not load, an optional one)."""
    lines = source.splitlines()
    found = []
    for function in ast.walk(ast.parse(source)):
        if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(function):
            internal = (isinstance(node, ast.ImportFrom)
                        and (node.level > 0 or (node.module or "").startswith("snn_antenna"))
                        or isinstance(node, ast.Import)
                        and any(a.name.startswith("snn_antenna") for a in node.names))
            above = lines[node.lineno - 2].strip() if internal and node.lineno > 1 else ""
            if internal and "#" not in lines[node.lineno - 1] and not above.startswith("#"):
                found.append(node.lineno)
    return sorted(set(found))


def test_package_imports_stand_at_the_module_top():
    """A module's dependencies are read at its top; one that waits inside a function says why."""
    found = [f"{path.relative_to(PACKAGE.parent)}:{line}"
             for path in sorted(PACKAGE.rglob("*.py")) for line in lazy_imports(path.read_text())]
    assert not found, "package imports inside a function, with no reason given:\n" + \
        "\n".join(found)


def test_the_lazy_import_check_catches_one():
    planted = "import os\n\ndef f():\n    from .core import files\n    return files\n"
    assert lazy_imports(planted) == [4]
    assert lazy_imports(planted.replace("files\n    return", "files  # heavy\n    return")) == []
    assert lazy_imports("def f():\n    import numpy\n") == []          # not the package's
