"""How often loading a dataset climbs back up a layer: ``python benchmarks/layer_climbs.py [DATASET]``.

``--legs``: the dataset walked through each leg of an identification (:data:`LEGS`, :func:`walk_path`),
read from the source: loading (its path), the single-model fit and the model choice (the dataset), a study's
task (the dataset's path, loaded, then fitted); the walk follows functions, classes and methods, and the
dataset into what a call returns as a dataset. ``--legs --verbose``: each upward step, with the function
before it, the next one and the function whose call reached the next one.

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
import functools
import sys
import tempfile
from pathlib import Path

import rideid

#: the layers, lowest first (tests/test_layers.py checks the import graph against the same order)
LAYERS = [
    ("rideid.errors", "rideid.csvio", "rideid.settings", "rideid.profiling"), ("rideid.model",), ("rideid.data",),
    ("rideid.conditioning",), ("rideid.verify",), ("rideid.synth",), ("rideid.estimate",),
    ("rideid.design", "rideid.report", "rideid.studies", "rideid.exporter"), ("rideid",),
    ("rideid.cli", "rideid.__main__"),
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
    """Every rideid module's top-level functions and classes (their methods as ``Class.method``) and the names
    its imports bind."""

    def __init__(self):
        self.modules = _modules()
        self.defs, self.classes, self.names = {}, {}, {}
        for mod, (p, pkg) in self.modules.items():
            tree = ast.parse(p.read_text(), str(p))
            self.defs[mod] = {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
            self.classes[mod] = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}
            for c in self.classes[mod].values():
                self.defs[mod].update({f"{c.name}.{n.name}": n for n in c.body
                                       if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))})
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

    def _resolve(self, mod: str, name: str, table: dict, depth: int = 0):
        """``(module, name)`` where ``name`` of ``mod`` is defined in ``table`` (module -> its definitions),
        following imports, or None."""
        if depth > 5 or mod not in self.modules:
            return None
        if name in table[mod]:
            return mod, name
        b = self.names[mod].get(name)
        if b is None or b[0] == "module":
            return None
        return self._resolve(b[1], b[2], table, depth + 1)

    def resolve(self, mod: str, name: str):
        """``(module, function)`` the name ``name`` of ``mod`` calls, or None (not a rideid function)."""
        return self._resolve(mod, name, self.defs)

    def resolve_class(self, mod: str, name: str):
        """``(module, class)`` the name ``name`` of ``mod`` stands for, or None (not a rideid class)."""
        return self._resolve(mod, name, self.classes)

    def method(self, cls, name: str, depth: int = 0):
        """``(module, "Class.method")`` of the method ``name`` of the class ``cls`` (its rideid bases searched
        too), or None."""
        if cls is None or depth > 5:
            return None
        mod, c = cls
        if f"{c}.{name}" in self.defs[mod]:
            return mod, f"{c}.{name}"
        for base in self.classes[mod][c].bases:
            if isinstance(base, ast.Name):
                hit = self.method(self.resolve_class(mod, base.id), name, depth + 1)
                if hit is not None:
                    return hit
        return None

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


@functools.cache
def _source() -> _Source:
    """The source read once (the walks only read it)."""
    return _Source()


def _passes(node, names) -> bool:
    """Whether the expression ``node`` uses one of ``names`` (a name or a collection of names), other than in a
    message (an f-string: what it says of the value is not the value)."""
    names = {names} if isinstance(names, str) else names
    if isinstance(node, ast.JoinedStr):
        return False
    if isinstance(node, ast.Name):
        return node.id in names
    return any(_passes(n, names) for n in ast.iter_child_nodes(node))


#: the value a leg follows: a dataset (a name bound to what a call returns as one carries it on, and its methods
#: are followed with it as ``self``)
DATASET = ("rideid.data.dataset", "Dataset")


class _Walk:
    """The walk of :func:`walk_path`: the order of (module, function, parameter), each with its caller."""

    def __init__(self, src: _Source):
        self.src, self.seen, self.order, self.caller = src, set(), [], {}

    def annotation(self, mod: str, node):
        """The rideid class an annotation names (``Dataset``, ``"Dataset"``), or None."""
        if node is None:
            return None
        text = node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else ast.unparse(node)
        return self.src.resolve_class(mod, text.strip("\"'")) if text.strip("\"'").isidentifier() else None

    def target(self, mod: str, fn: str, call: ast.Call, objects: dict, tracked: dict):
        """``(module, function, self's name or None)`` a call goes to: a function (by name or through a module),
        a class's ``__init__``, or a method of a class (called on it, on an instance the function made, on
        ``self``, or on a tracked dataset); None where the source does not say."""
        f, src = call.func, self.src
        if isinstance(f, ast.Name):
            hit = src.resolve(mod, f.id)
            if hit is not None:
                return (*hit, None)
            return self._bound(src.method(src.resolve_class(mod, f.id), "__init__"))
        if not (isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name)):
            return None
        name = f.value.id
        b = src.names[mod].get(name)
        if b is not None and b[0] == "module":
            hit = src.resolve(b[1], f.attr)
            return None if hit is None else (*hit, None)
        cls = objects.get(name) or tracked.get(name)
        if cls is None and name == "self" and "." in fn:
            cls = (mod, fn.split(".")[0])
        if cls is not None:
            return self._bound(src.method(cls, f.attr))
        # a class called by its name: a class or static method (its first parameter stays)
        hit = src.method(src.resolve_class(mod, name), f.attr)
        return None if hit is None else (*hit, None)

    def _bound(self, hit):
        """A method called on an instance: its first parameter is the instance (None for a static method)."""
        if hit is None:
            return None
        node = self.src.defs[hit[0]][hit[1]]
        static = any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in node.decorator_list)
        first = None if static or not node.args.args else node.args.args[0].arg
        return (*hit, first)

    def returns(self, hit) -> tuple | None:
        """The rideid class of what the call ``hit`` returns: the class a ``__init__`` makes, else the function's
        return annotation (None where it has none)."""
        m, f = hit[:2]
        node = self.src.defs[m][f]
        if f.endswith(".__init__"):
            return m, f.split(".")[0]
        return self.annotation(m, node.returns)

    def visit(self, key, kind, caller=None):
        """Be the parameter ``key[2]`` of ``key[0].key[1]`` (a value of the class ``kind``, or None where unknown)
        and follow the calls that pass it on."""
        if key in self.seen:
            return
        self.seen.add(key)
        self.order.append(key)
        self.caller[key] = caller
        m, f, name = key
        node = self.src.defs[m][f]
        tracked, objects = {name: kind}, {}
        # in the order they run: a call's arguments before it (by where each call ends)
        calls = sorted((n for n in ast.walk(node) if isinstance(n, ast.Call)),
                       key=lambda n: (n.end_lineno, n.end_col_offset))
        assigns = {id(n.value): n for n in ast.walk(node) if isinstance(n, ast.Assign)}
        for c in calls:
            hit = self.target(m, f, c, objects, tracked)
            passed = _passes(c, tracked)
            if hit is not None and passed:
                self.follow(hit, c, tracked, key)
            a = assigns.get(id(c))
            if a is not None and hit is not None:
                # what the call returns: an object whose methods are followed, a dataset carried on when the
                # call was given the dataset
                made = self.returns(hit)
                for t in a.targets:
                    if isinstance(t, ast.Name) and made is not None:
                        if passed and made == DATASET:
                            tracked[t.id] = made
                        else:
                            objects[t.id] = made

    def follow(self, hit, call: ast.Call, tracked: dict, key):
        """Visit the parameters of ``hit`` the call passes a tracked name to (a method's ``self`` when called on
        one), each as its annotation's class or, passed as it is, the tracked name's."""
        m, f, first = hit
        a = self.src.defs[m][f].args
        pos = [x.arg for x in a.posonlyargs + a.args]
        every = {x.arg for x in a.posonlyargs + a.args + a.kwonlyargs}
        if first is not None:
            pos = pos[1:]
            recv = call.func.value if isinstance(call.func, ast.Attribute) else None
            if isinstance(recv, ast.Name) and recv.id in tracked:
                self.visit((m, f, first), tracked[recv.id], key)
        kinds = {x.arg: self.annotation(m, x.annotation) for x in a.posonlyargs + a.args + a.kwonlyargs}
        for i, arg in enumerate(call.args):
            if i < len(pos) and _passes(arg, tracked):
                self.visit((m, f, pos[i]), kinds.get(pos[i]) or self._kind(arg, tracked), key)
        for kw in call.keywords:
            if kw.arg in every and _passes(kw.value, tracked):
                self.visit((m, f, kw.arg), kinds.get(kw.arg) or self._kind(kw.value, tracked), key)

    @staticmethod
    def _kind(arg, tracked):
        return tracked.get(arg.id) if isinstance(arg, ast.Name) else None


def walk_path(mod: str, fn: str, param: str, kind=None):
    """``(steps, upward steps)``: be the parameter ``param`` of ``mod.fn`` (a value of the class ``kind``, e.g.
    :data:`DATASET`; default its annotation) and follow the calls that pass it on (as any part of a positional or
    keyword argument, to the rideid function, class or method the call resolves to, under that function's own
    name for it), depth-first in the order the calls run (a call's arguments before it), each (function,
    parameter) once. Followed: functions by name or
    through a module, classes (their ``__init__``) and methods (called on the class, on an instance the function
    made, on ``self``, or on the dataset itself, which is then their ``self``); a name bound to what a call
    given the dataset returns as a dataset (its annotation) carries it on. The upward steps are those where the
    next function lives in a higher layer than the one before it."""
    order, steps, _ = _walk(mod, fn, param, kind)
    return order, steps


def _walk(mod, fn, param, kind=None):
    """:func:`walk_path` with the upward steps themselves: ``(order, count, [(before, next, next's caller)])``."""
    w = _Walk(_source())
    if kind is None:
        args = w.src.defs[mod][fn].args
        kind = next((w.annotation(mod, x.annotation) for x in args.posonlyargs + args.args + args.kwonlyargs
                     if x.arg == param), None)
    w.visit((mod, fn, param), kind)
    lays = [layer_of(m) for m, _, _ in w.order]
    ups = [(a, b, w.caller[b]) for a, b, la, lb in zip(w.order, w.order[1:], lays, lays[1:]) if lb > la]
    return w.order, len(ups), ups


def static_path(mod: str, fn: str):
    """``(functions, upward steps)``: the rideid functions reached from ``mod.fn``, depth-first in source order
    (each once), and how often the next one lives in a higher layer than the one before it."""
    src, seen, order = _source(), set(), []

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


#: the legs of an identification, walked by ``--legs``: (module, function, parameter, the class of its value or
#: None): loading (the dataset's path), the single-model fit and the model choice (the dataset), a study's task
#: (the dataset's path, which it loads, then fits)
LEGS = (("rideid.conditioning.load", "load_dataset", "path", None),
        ("rideid.estimate.fit.identify", "identify", "ds", DATASET),
        ("rideid.estimate.choice.model_choice", "identify", "ds", DATASET),
        ("rideid.studies.task", "run_task", "dataset_path", None))


def _name(key) -> str:
    m, f, param = key
    return f"{m}.{f}({param}) [{'/'.join(x.split('.')[-1] for x in LAYERS[layer_of(m)])}]"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", help="dataset folder (default: the built-in scenario, simulated)")
    ap.add_argument("--static", action="store_true", help="the static count only (nothing is run)")
    ap.add_argument("--legs", action="store_true",
                    help="walk the dataset through every leg of an identification (LEGS): upward steps per leg")
    ap.add_argument("--verbose", action="store_true",
                    help="with --legs: each upward step (the function before, the next, the call that reached it)")
    args = ap.parse_args(argv)
    if args.legs:
        for mod, fn, param, kind in LEGS:
            order, steps, ups = _walk(mod, fn, param, kind)
            print(f"{mod}:{fn}:{param}: {len(order)} steps, climbs back up a layer {steps} times")
            for before, after, caller in ups if args.verbose else ():
                print(f"  {_name(before)} -> {_name(after)}, called by {_name(caller)}")
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
