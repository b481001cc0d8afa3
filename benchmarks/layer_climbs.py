"""How often loading a dataset climbs back up a layer: ``python benchmarks/layer_climbs.py [DATASET]``.

``--legs``: the dataset walked through each leg of an identification (:data:`LEGS`, :func:`walk_path`),
read from the source: loading (its path), the single-model fit and the model choice (the dataset).

``rideid.load_dataset(DATASET)`` (default: the built-in scenario simulated
with 1 % noise, written to a temporary folder) runs under a profiler hook
that records which function each call enters and each return comes back to.
Every rideid function has the layer of its package (``LAYERS``, as
``tests/test_layers.py`` orders them). Counted:

* **climbs**: the distinct places (caller function, the lower-layer package
  it called into) where the call path comes back up a layer: a function
  called code of a lower layer and carries on afterwards. A loader whose
  layers each call only downwards, once per job, climbs little.
  Counted apart: those below the loader's own layer (code under the
  orchestrator that waits on a lower layer and carries on), those in the
  data layer, and the functions of the data layer that run the model's
  simulation (:data:`SIMULATION`).
* **layer path**: the layers the executing code visits, in time order,
  repeats merged, with the number of upward steps along it.
* **static**: the rideid functions the loader's source reaches (calls by
  name, ``module.function`` included; methods left out), followed
  depth-first in source order, each once, and the number of times the next
  one lives in a higher layer than the one before it (``--static``: this
  count alone, nothing run).

Module-level code run by first imports is left out (the loader's calls only).
"""

from __future__ import annotations

import argparse
import ast
import sys
import tempfile
from pathlib import Path

import rideid

#: the layers, lowest first (tests/test_layers.py checks the import graph against the same order)
LAYERS = [
    ("rideid.errors", "rideid.csvio"), ("rideid.model",), ("rideid.data",), ("rideid.conditioning",),
    ("rideid.verify",), ("rideid.synth",), ("rideid.estimate",), ("rideid.design", "rideid.report", "rideid.studies"),
    ("rideid",), ("rideid.cli", "rideid.__main__"),
]


def layer_of(module: str) -> int | None:
    best, where = -1, None
    for i, prefixes in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best:
                best, where = len(p), i
    return where


#: the model's simulation: what running the model means
SIMULATION = ("rideid.model.batch", "rideid.model.kernel", "rideid.model.kernel_nl", "rideid.model.simulate",
              "rideid.model.nonlinear", "rideid.model.contact")


def trace(path):
    """``(climbs, path, upward steps, simulation callers)``: climbs {(caller, lower package): count}; path: the
    layer names visited in order; simulation callers: the functions outside rideid.model that entered it."""
    stack, visits, climbs, sim_callers = [], [], {}, set()

    def where(frame):
        mod = frame.f_globals.get("__name__", "")
        if frame.f_code.co_name == "<module>":
            return None
        lay = layer_of(mod)
        return None if lay is None else (lay, mod, f"{mod}.{frame.f_code.co_qualname}")

    def hook(frame, event, arg):
        if event == "call":
            w = where(frame)
            if w is not None and w[1] in SIMULATION:
                caller = next((s for s in reversed(stack) if s is not None and not s[1].startswith("rideid.model")),
                              None)
                if caller is not None:
                    sim_callers.add(caller[2])
            stack.append(w)
            if w is not None:
                visits.append(w)
        elif event == "return" and stack:
            w = stack.pop()
            up = next((s for s in reversed(stack) if s is not None), None)
            if w is not None and up is not None and w[0] < up[0]:
                pkg = ".".join(w[1].split(".")[:2])
                climbs[(up[2], pkg)] = climbs.get((up[2], pkg), 0) + 1
            if up is not None:
                visits.append(up)

    sys.setprofile(hook)
    try:
        rideid.load_dataset(path)
    finally:
        sys.setprofile(None)
    names = {i: "/".join(p.split(".")[-1] for p in prefixes) for i, prefixes in enumerate(LAYERS)}
    seq = []
    for lay, _, _ in visits:
        if not seq or seq[-1] != lay:
            seq.append(lay)
    return climbs, [names[i] for i in seq], sum(1 for a, b in zip(seq, seq[1:]) if b > a), sim_callers


# ---------------------------------------------------------------------------
# The static measure: the functions reached from the loader, depth-first in source order

SRC = Path(rideid.__file__).resolve().parents[1]


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for p in sorted((SRC / "rideid").rglob("*.py")):
        parts = list(p.relative_to(SRC).with_suffix("").parts)
        pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if pkg else parts)] = (p, pkg)
    return out


class _Source:
    """Every rideid module's top-level functions and the names its imports bind."""

    def __init__(self):
        self.modules = _modules()
        self.defs, self.names = {}, {}
        for mod, (p, pkg) in self.modules.items():
            tree = ast.parse(p.read_text(), str(p))
            self.defs[mod] = {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
            names = {}
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom):
                    if node.level:
                        base = mod.split(".") if pkg else mod.split(".")[:-1]
                        base = base[:len(base) - (node.level - 1)] + ([node.module] if node.module else [])
                        base = ".".join(base)
                    else:
                        base = node.module or ""
                    for a in node.names:
                        full = f"{base}.{a.name}"
                        names[a.asname or a.name] = ("module", full) if full in self.modules else ("attr", base, a.name)
                elif isinstance(node, ast.Import):
                    for a in node.names:
                        if a.asname and a.name in self.modules:
                            names[a.asname] = ("module", a.name)
            self.names[mod] = names

    def resolve(self, mod: str, name: str, depth: int = 0):
        """``(module, function)`` the name ``name`` of ``mod`` calls, or None (not a rideid function)."""
        if depth > 5 or mod not in self.modules:
            return None
        if name in self.defs[mod]:
            return mod, name
        b = self.names[mod].get(name)
        if b is None or b[0] == "module":
            return None
        return self.resolve(b[1], b[2], depth + 1)

    def callees(self, mod: str, fn: str):
        """The rideid functions ``fn`` calls (nested functions included), in source order."""
        calls = sorted((n for n in ast.walk(self.defs[mod][fn]) if isinstance(n, ast.Call)),
                       key=lambda n: (n.lineno, n.col_offset))
        out = []
        for c in calls:
            f, hit = c.func, None
            if isinstance(f, ast.Name):
                hit = self.resolve(mod, f.id)
            elif isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
                b = self.names[mod].get(f.value.id)
                if b is not None and b[0] == "module":
                    hit = self.resolve(b[1], f.attr)
            if hit is not None:
                out.append(hit)
        return out


def _passes(node, name: str) -> bool:
    return any(isinstance(n, ast.Name) and n.id == name for n in ast.walk(node))


def walk_path(mod: str, fn: str, param: str):
    """``(steps, upward steps)``: be the parameter ``param`` of ``mod.fn`` and follow the calls that pass it
    on (as any part of a positional or keyword argument, to the rideid function the call resolves to, under
    that function's own name for it), depth-first in source order, each (function, parameter) once; the
    upward steps are those where the next function lives in a higher layer than the one before it."""
    src, seen, order = _Source(), set(), []

    def params(m, f):
        a = src.defs[m][f].args
        return [x.arg for x in a.posonlyargs + a.args], {x.arg for x in a.posonlyargs + a.args + a.kwonlyargs}

    def visit(key):
        if key in seen:
            return
        seen.add(key)
        order.append(key)
        m, f, name = key
        calls = sorted((n for n in ast.walk(src.defs[m][f]) if isinstance(n, ast.Call)),
                       key=lambda n: (n.lineno, n.col_offset))
        for c in calls:
            hit = None
            if isinstance(c.func, ast.Name):
                hit = src.resolve(m, c.func.id)
            elif isinstance(c.func, ast.Attribute) and isinstance(c.func.value, ast.Name):
                b = src.names[m].get(c.func.value.id)
                if b is not None and b[0] == "module":
                    hit = src.resolve(b[1], c.func.attr)
            if hit is None:
                continue
            pos, every = params(*hit)
            for i, a in enumerate(c.args):
                if i < len(pos) and _passes(a, name):
                    visit((*hit, pos[i]))
            for kw in c.keywords:
                if kw.arg in every and _passes(kw.value, name):
                    visit((*hit, kw.arg))

    visit((mod, fn, param))
    lays = [layer_of(m) for m, _, _ in order]
    return order, sum(1 for a, b in zip(lays, lays[1:]) if b > a)


def static_path(mod: str, fn: str):
    """``(functions, upward steps)``: the rideid functions reached from ``mod.fn``, depth-first in source order
    (each once), and how often the next one lives in a higher layer than the one before it."""
    src, seen, order = _Source(), set(), []

    def visit(key):
        if key in seen:
            return
        seen.add(key)
        order.append(key)
        for k in src.callees(*key):
            visit(k)

    visit((mod, fn))
    lays = [layer_of(m) for m, _ in order]
    return order, sum(1 for a, b in zip(lays, lays[1:]) if b > a)


#: the legs of an identification, walked by ``--legs`` (the dataset's path, then the dataset itself): loading,
#: the single-model fit, the model choice
LEGS = (("rideid.conditioning.load", "load_dataset", "path"), ("rideid.estimate.fit.identify", "identify", "ds"),
        ("rideid.estimate.choice.model_choice", "identify", "ds"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", help="dataset folder (default: the built-in scenario, simulated)")
    ap.add_argument("--static", action="store_true", help="the static count only (nothing is run)")
    ap.add_argument("--legs", action="store_true",
                    help="walk the dataset through every leg of an identification (LEGS): upward steps per leg")
    args = ap.parse_args(argv)
    if args.legs:
        for mod, fn, param in LEGS:
            order, steps = walk_path(mod, fn, param)
            print(f"{mod}:{fn}:{param}: {len(order)} steps, climbs back up a layer {steps} times")
        return 0
    order, steps = static_path(rideid.load_dataset.__module__, rideid.load_dataset.__name__)
    names = {i: "/".join(p.split(".")[-1] for p in prefixes) for i, prefixes in enumerate(LAYERS)}
    print(f"static: {len(order)} functions reached from load_dataset, depth-first in source order; "
          f"{steps} upward steps between consecutive ones")
    seq = []
    for m, _f in order:
        lay = names[layer_of(m)]
        if not seq or seq[-1][0] != lay:
            seq.append((lay, m.split(".")[-1]))
    print(f"  static layer path: {' > '.join(f'{lay}({m})' for lay, m in seq)}")
    if args.static:
        return 0
    path = args.dataset
    if path is None:
        tmp = tempfile.mkdtemp(prefix="rideid-climbs-")
        sc = rideid.default_scenario()
        data, _ = rideid.simulate_manifest(sc, noise=0.01, seed=1)
        path = rideid.write_dataset(sc, data, Path(tmp) / "dataset")
    rideid.load_dataset(path)  # first imports and compiled kernels out of the way
    climbs, seq, ups, sim_callers = trace(path)
    own = layer_of(rideid.load_dataset.__module__)
    below = {k: n for k, n in climbs.items() if layer_of(k[0]) < own}
    print(f"load_dataset ({rideid.load_dataset.__module__}) on {path}: climbs back up a layer at {len(climbs)} "
          f"places, {len(below)} of them below the loader's layer")
    for (caller, pkg), n in sorted(climbs.items()):
        print(f"  {caller} (after calling into {pkg}, {n}x){'  [below the loader]' if (caller, pkg) in below else ''}")
    data = layer_of("rideid.data")
    in_data = [k for k in climbs if layer_of(k[0]) == data]
    print(f"climbs in the data layer: {len(in_data)}")
    ran = sorted(f for f in sim_callers if layer_of(f) == data)
    print(f"functions of rideid.data that ran the model's simulation: {', '.join(ran) or 'none'}")
    print(f"layer path ({ups} upward steps): {' > '.join(seq[:40])}{' ...' if len(seq) > 40 else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
