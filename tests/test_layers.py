"""The import graph of rideid: layers, no cycles, internal imports at the top, a light command line.

Every module's imports are read with ``ast`` (those at the top and those
inside functions), resolved to rideid modules, and checked against the
layers below, lowest first. A module may import from its own layer and the
ones below it, never from one above; no chain of imports, even through
function-level ones, comes back to where it started.
"""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

#: the layers, lowest first: a module imports only from its own layer and those below
LAYERS = [
    ("rideid.errors", "rideid.csvio", "rideid.settings", "rideid.profiling"),  # settings: read by every layer
    ("rideid.model",),                     # physics and kernels over arrays: no files
    ("rideid.data",),                      # schemas, readers, units, pure checks, the Dataset: no simulation
    ("rideid.conditioning",),              # start alignment and nominal-car checks; load_dataset
    ("rideid.verify",),                    # the independent MuJoCo car, built from model parameters and data schemas
    ("rideid.synth",),                     # scenario simulation (7-DOF, nonlinear or MuJoCo) and writing datasets
    ("rideid.estimate",),                  # cost, search, identification, uncertainty, adequacy
    ("rideid.design", "rideid.report", "rideid.studies", "rideid.exporter"),
    ("rideid",),                           # the public API (rideid/__init__.py), resolved lazily
    ("rideid.cli", "rideid.__main__"),
]

#: modules allowed internal imports inside functions, each with its reason (empty once they are moved)
LATE_ALLOWED: dict[str, str] = {}

#: import edges allowed to break the layering, each with its reason
EDGES_ALLOWED: dict[tuple[str, str], str] = {}


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for p in sorted((SRC / "rideid").rglob("*.py")):
        parts = list(p.relative_to(SRC).with_suffix("").parts)
        pkg = parts[-1] == "__init__"
        if pkg:
            parts = parts[:-1]
        out[".".join(parts)] = (p, pkg)
    return out


MODULES = _modules()


def _targets(mod: str, pkg: bool, node) -> list[str]:
    """The rideid modules an import statement loads (a name imported from a package may be a submodule)."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names if a.name.split(".")[0] == "rideid"]
    else:
        if node.level:
            base = mod.split(".") if pkg else mod.split(".")[:-1]
            base = ".".join(base[:len(base) - (node.level - 1)] + ([node.module] if node.module else []))
        else:
            base = node.module or ""
            if base.split(".")[0] != "rideid":
                return []
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
    out = []
    for n in names:
        while n not in MODULES and "." in n:
            n = n.rsplit(".", 1)[0]
        if n in MODULES and n != mod:
            out.append(n)
    return out


@functools.cache
def _graph():
    """``(edges, late)``: module -> {imported module: line}; late: (module, line, target) inside functions."""
    edges, late = {m: {} for m in MODULES}, []
    for mod, (path, pkg) in MODULES.items():
        tree = ast.parse(path.read_text(), str(path))
        inside = set()
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                inside.update(id(n) for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom)))
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for t in _targets(mod, pkg, node):
                    edges[mod].setdefault(t, node.lineno)
                    if id(node) in inside:
                        late.append((mod, node.lineno, t))
    # the package root's names, imported on first use by module name (rideid/__init__.py): edges too
    root = ast.parse(MODULES["rideid"][0].read_text())
    for node in root.body:
        if isinstance(node, ast.Assign) and node.targets[0].id in ("_PUBLIC", "_COMMAND_LINE"):
            # _by_name({module: names}, {module: {alias: its name there}})
            modules, aliases = (ast.literal_eval(arg) for arg in node.value.args)
            for module in [*modules, *aliases]:
                assert module in MODULES, f"rideid.{node.targets[0].id}: no module {module}"
                edges["rideid"].setdefault(module, node.lineno)
    return edges, late




def _edges() -> dict:
    """module -> {imported module: line} (:func:`_graph`, parsed once, by the worker that runs these tests)."""
    return _graph()[0]


def _late() -> list:
    """(module, line, target) of the imports inside functions."""
    return _graph()[1]


def _layer(mod: str) -> int:
    best, where = -1, None
    for i, prefixes in enumerate(LAYERS):
        for p in prefixes:
            if (mod == p or mod.startswith(p + ".")) and len(p) > best:
                best, where = len(p), i
    assert where is not None, f"{mod} is in no layer: add it to LAYERS"
    return where


def test_every_module_is_in_a_layer_and_the_graph_is_read():
    assert len(MODULES) > 60
    for m in MODULES:
        _layer(m)
    # the graph is really read: known edges of each kind are there
    assert "rideid.model.simulate" in _edges()["rideid.conditioning.nominal"]
    assert "rideid.data.dataset" in _edges()["rideid.conditioning.load"]
    assert "rideid.verify.hifi" in _edges()["rideid.synth.scenario"]
    assert "rideid.conditioning.load" in _edges()["rideid"]  # through the lazy table


def test_no_import_from_a_higher_layer():
    up = [f"{m}:{line} imports {t} (layer {_layer(t)} above {_layer(m)})"
          for m, ts in _edges().items() for t, line in ts.items()
          if _layer(t) > _layer(m) and (m, t) not in EDGES_ALLOWED]
    assert up == []


def test_data_neither_simulates_nor_reaches_up():
    """data/ uses the model's parameters and tables, never its simulators; nor anything above it."""
    sims = {"rideid.model.batch", "rideid.model.kernel", "rideid.model.kernel_nl", "rideid.model.nonlinear",
            "rideid.model.backend", "rideid.model.simulator", "rideid.model.kernel_contact"}
    bad = [(m, t) for m, ts in _edges().items() if m.startswith("rideid.data") for t in ts
           if t in sims or _layer(t) > _layer("rideid.data")]
    assert bad == []


def test_the_problem_does_not_reach_into_the_fit_the_model_choice_or_the_assessments():
    """estimate/problem/ (the problem and its blocks) is below the fit, the model choice and the assessments that
    solve and judge it: a block's share of the error bars is made of the score series of problem/scores.py, which
    the fit's uncertainty composes, and the least improvement that counts is the cost's (problem/cost.py); before,
    problem/blocks.py imported the fit's uncertainty module and problem/bumps.py the adequacy test's."""
    up = [(m, t) for m, ts in _edges().items() if m.startswith("rideid.estimate.problem") for t in ts
          if t.startswith(("rideid.estimate.fit", "rideid.estimate.choice", "rideid.estimate.assess"))]
    assert up == []
    assert "rideid.estimate.problem.scores" in _edges()["rideid.estimate.fit.uncertainty"]


def test_no_import_cycle_even_through_function_level_imports():
    graph = {m: {t for t in ts if (m, t) not in EDGES_ALLOWED} for m, ts in _edges().items()}
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycles.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert cycles == []


def test_internal_imports_are_at_the_top():
    late = [f"{m}:{line} imports {t} inside a function" for m, line, t in _late() if m not in LATE_ALLOWED]
    assert late == []


def test_the_command_line_imports_only_the_public_api():
    assert set(_edges()["rideid.cli"]) == {"rideid"}
    r = subprocess.run([sys.executable, "-c", "import rideid.cli; import sys; "
                        "print('numba' in sys.modules, 'scipy' in sys.modules, 'numpy' in sys.modules)"],
                       capture_output=True, text=True, env={"PYTHONPATH": str(SRC), "PATH": ""}, check=True)
    assert r.stdout.split() == ["False", "False", "False"]


def test_the_lazy_root_has_every_public_name():
    import rideid

    assert set(rideid._PUBLIC) | {"__version__"} == set(rideid.__all__)
    assert set(rideid.__all__) <= set(dir(rideid))
    for name in list(rideid._PUBLIC) + list(rideid._COMMAND_LINE):
        assert getattr(rideid, name) is not None, name
    assert rideid.load_dataset.__module__ == "rideid.conditioning.load"
    assert rideid.load_result.__name__ == "load"
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        rideid.not_a_name  # noqa: B018


def test_no_library_module_switches_the_matplotlib_backend():
    # design/planner.py and report/html.py: restructured in parallel (their owners draw on plain Figures)
    allowed = {"rideid.design.planner", "rideid.report.html"}
    calls = []
    for m, (path, _) in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use"
                    and isinstance(node.func.value, ast.Name) and node.func.value.id == "matplotlib"
                    and m not in allowed):
                calls.append(f"{m}:{node.lineno}")
    assert calls == []
    code = ("import matplotlib, sys, tempfile; matplotlib.use('svg'); import rideid; "
            "from rideid.report.sensitivity_files import heatmaps; "
            "files = heatmaps(rideid.sensitivity_maps(rideid.default_scenario()), tempfile.mkdtemp()); "
            "print(matplotlib.get_backend(), 'matplotlib.pyplot' in sys.modules, "
            "[f.stat().st_size > 1000 for f in files])")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                       env={"PYTHONPATH": str(SRC), "PATH": "", "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    assert r.stdout.strip().split(maxsplit=2) == ["svg", "False", "[True, True, True]"]


def _layer_climbs():
    import benchmark_module

    return benchmark_module.load("layer_climbs")


#: the upward steps issue 50 allows a leg (a dataset followed through the calls); measured: loading 3, identify 3,
#: the model choice 10, a study's task 10 (``python benchmarks/layer_climbs.py --legs --verbose`` prints every step
#: and the call that made it)
MAX_CLIMBS = 10


def test_the_layer_walk_follows_calls_and_each_leg_climbs_at_most_ten_times():
    """``benchmarks/layer_climbs.py --legs``: each leg of an identification walked from the source (functions,
    classes, methods, the dataset carried into what a call returns as one)."""
    lc = _layer_climbs()
    assert [tuple(x) for x in lc.LAYERS] == [tuple(x) for x in LAYERS]
    legs = {leg[:2]: lc._walk(*leg) for leg in lc.LEGS}
    # the walk follows methods (the dataset's own, a class made in the function) and a study's path into its fit
    assert ("rideid.estimate.problem.cost", "CostFunction.__init__", "ds") in legs["rideid.estimate.fit.identify",
                                                                                   "identify"][0]
    assert ("rideid.data.dataset", "Dataset.subset", "self") in legs["rideid.estimate.choice.model_choice",
                                                                       "identify"][0]
    study = legs["rideid.studies.task", "run_task"][0]
    assert ("rideid.conditioning.load", "load_dataset", "path") in study
    assert ("rideid.estimate.choice.model_choice", "identify", "ds") in study
    for leg, (order, steps, ups) in legs.items():
        assert len(order) >= 40, leg  # the walk reaches the fit (50 steps for identify, measured)
        assert steps == len(ups) <= MAX_CLIMBS, (leg, ups)
