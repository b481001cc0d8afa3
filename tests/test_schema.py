"""The schema package: one place for every file format, two frozen manifest types, a clean layering."""

import ast
import copy
import dataclasses
import pickle
import tomllib
from pathlib import Path

import pytest
import tomli_w

import rideid
from rideid.data.schema import (CsvOptions, DatasetManifest, Manifest, RunSpec, Scenario, parse_channel_map,
                                parse_dataset_manifest)

SRC = Path(rideid.__file__).parent


def _imports(path: Path, module: str, top_level_only: bool = False):
    """``(imported module, name, top level?)`` of every ``from rideid... import`` in a file."""
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom) or node.module == "__future__":
            continue
        if top_level_only and id(node) not in top:
            continue
        if node.level:
            base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
        else:
            base = node.module or ""
        if base.split(".")[0] == "rideid":
            for a in node.names:
                yield base, a.name, id(node) in top


def _modules():
    for p in sorted(SRC.rglob("*.py")):
        parts = list(p.relative_to(SRC.parent).with_suffix("").parts)
        yield p, ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_the_schema_package_imports_only_errors_csvio_and_the_model():
    # rideid.settings: the names and kinds a dataset's [settings] table may give (the lowest layer)
    allowed = ("rideid.errors", "rideid.csvio", "rideid.settings", "rideid.model", "rideid.data.schema")
    for p, mod in _modules():
        if mod.startswith("rideid.data.schema"):
            for base, name, _ in _imports(p, mod):
                target = f"{base}.{name}"
                assert base.startswith(allowed) or target.startswith(allowed), f"{mod} imports {target}"


def test_no_import_cycle_at_load_time_and_no_private_name_across_modules():
    mods = dict((m, p) for p, m in _modules())
    graph = {}
    for mod, p in mods.items():
        edges = set()
        for base, name, _ in _imports(p, mod, top_level_only=True):
            target = f"{base}.{name}" if f"{base}.{name}" in mods else base
            # importing a.b.c runs a/__init__ and a/b/__init__ first, unless they are this module's own packages
            parts = target.split(".")
            for t in (".".join(parts[:i]) for i in range(1, len(parts) + 1)):
                if t in mods and t != mod and not mod.startswith(t + "."):
                    edges.add(t)
            assert not (name.startswith("_") and not name.startswith("__")), f"{mod} imports {base}.{name}"
        graph[mod] = edges

    _assert_acyclic(graph)


def _assert_acyclic(graph):
    """Depth-first search of ``{module: imported modules}``; fails naming the first cycle found."""
    state = {}

    def visit(m, path):
        state[m] = "open"
        for t in graph[m]:
            assert state.get(t) != "open", "import cycle: " + " -> ".join(path + [t])
            if t not in state:
                visit(t, path + [t])
        state[m] = "done"

    for m in graph:
        if m not in state:
            visit(m, [m])


def test_a_scenario_and_a_dataset_manifest_are_distinct_types(default_scenario, sim_dataset):
    man = rideid.load_dataset(sim_dataset).manifest
    assert isinstance(default_scenario, Scenario) and not isinstance(default_scenario, DatasetManifest)
    assert isinstance(man, DatasetManifest) and not isinstance(man, Scenario)
    assert isinstance(man, Manifest) and isinstance(default_scenario, Manifest)
    assert not hasattr(man, "truth") and not hasattr(default_scenario, "channel_map")
    # what they share is the same: the dataset written from the scenario keeps its car, tracks and run ids
    assert man.geometry == default_scenario.geometry and dict(man.known) == dict(default_scenario.known)
    assert [r.id for r in man.runs] == [r.id for r in default_scenario.runs]
    assert man.runs[0].file == f"runs/{man.runs[0].id}.csv" and default_scenario.runs[0].file is None


def test_parsed_files_are_frozen_and_change_only_by_replace(default_scenario):
    sc = default_scenario
    with pytest.raises(dataclasses.FrozenInstanceError):
        sc.runs = sc.runs[:1]
    with pytest.raises(TypeError, match="read-only"):
        sc.truth["m_s"] = 1.0
    with pytest.raises(TypeError, match="read-only"):
        sc.known.update(total_mass=1.0)
    with pytest.raises(TypeError, match="read-only"):
        sc.runs[0].options["start"] = 1.0
    with pytest.raises(AttributeError):
        sc.runs.append(sc.runs[0])

    m_s = sc.truth["m_s"]
    sub = dataclasses.replace(sc, runs=[r for r in sc.runs if r.track == sc.runs[0].track],
                              truth={**sc.truth, "m_s": 2 * m_s})
    assert isinstance(sub, Scenario) and isinstance(sub.runs, tuple) and 0 < len(sub.runs) < len(sc.runs)
    assert sub.truth["m_s"] == 2 * m_s and sc.truth["m_s"] == m_s  # the original is untouched
    with pytest.raises(TypeError, match="read-only"):
        sub.truth["m_s"] = 1.0
    # copies stay read-only (a MappingProxyType would neither deep-copy nor pickle)
    back = copy.deepcopy(sc)
    assert back.truth == sc.truth and back.runs == sc.runs and back.truth is not sc.truth
    with pytest.raises(TypeError, match="read-only"):
        back.truth["m_s"] = 1.0
    run = pickle.loads(pickle.dumps(sc.runs[0]))
    assert run == sc.runs[0]
    with pytest.raises(TypeError, match="read-only"):
        run.options["start"] = 1.0


def test_a_dataset_manifest_round_trips_through_its_toml_document(default_scenario):
    sc = default_scenario
    runs = [RunSpec(r.id, r.track, r.speed, file=f"runs/{r.id}.mf4",
                    options={"start": 1.25, "window": (0.5, 9.0)} if i == 0 else {},
                    checks={"track": "off"} if i == 1 else {})
            for i, r in enumerate(sc.runs)]
    man = DatasetManifest(**{**sc.shared(), "runs": runs, "name": "logged"},
                          channel_map=parse_channel_map({"time": "t", "body_az_fl": {"name": "a1", "unit": "g"},
                                                         "roll_rate": {"name": "gx", "unit": "deg/s", "sign": -1}},
                                                        "test"),
                          preprocess={"gravity_included": True, "lead_in": (0.0, 1.0)},
                          csv_options=CsvOptions(delimiter=";", decimal=","),
                          csv_table={"delimiter": ";", "decimal": ","},
                          checks={"wiring": "warn"})
    doc = tomllib.loads(tomli_w.dumps(man.to_dataset_doc()))  # plain TOML, nothing read-only leaks into it
    back = parse_dataset_manifest(doc, man.path)
    # tracks compare by their tables (a used track caches its wheel paths)
    assert [t.to_table() for t in back.tracks.values()] == [t.to_table() for t in man.tracks.values()]
    assert dataclasses.replace(back, tracks=man.tracks) == man
    assert back.is_measured(back.runs[1]) and back.runs[0].options["window"] == (0.5, 9.0)
    assert back.channel_map["roll_rate"].sign == -1.0 and back.csv_options.decimal == ","


def test_a_loaded_dataset_cannot_be_changed(sim_dataset):
    """identify and the report get a dataset nobody can change under them; the steps return new ones."""
    import dataclasses

    import pytest

    import rideid
    ds = rideid.load_dataset(sim_dataset)
    with pytest.raises(dataclasses.FrozenInstanceError):
        ds.findings = ()
    with pytest.raises(TypeError, match="read-only"):
        ds.data["T_LL"] = None
    other = ds.with_data(dict(ds.data))
    assert other is not ds and other.data == ds.data


def test_no_import_cycle_even_through_imports_inside_functions():
    """The modules form a layered graph: no module reaches itself, counting the imports inside functions
    (those run when the packages are loaded, so only the imported module itself is an edge)."""
    mods = dict((m, p) for p, m in _modules())
    graph = {mod: {f"{b}.{n}" if f"{b}.{n}" in mods else b for b, n, _ in _imports(p, mod)} - {mod}
             for mod, p in mods.items()}
    graph = {m: {t for t in ts if t in mods} for m, ts in graph.items()}
    _assert_acyclic(graph)


def _scenario_doc():
    return tomllib.loads(rideid.default_scenario_path().read_text())


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["vehicle"].update(wheel_base=2.7), "sc.toml: [vehicle]: unknown key 'wheel_base'; allowed: "
     "wheelbase, track_front, track_rear, tire_radius, cg_height"),
    (lambda d: d["vehicle"].pop("track_rear"), "sc.toml: [vehicle]: missing key 'track_rear'"),
    (lambda d: d["vehicle"].update(wheelbase="2.7"),
     "sc.toml: [vehicle] wheelbase: expected a finite number, got '2.7'"),
    (lambda d: d["vehicle"].update(wheelbase=True), "sc.toml: [vehicle] wheelbase: expected a finite number, got True"),
    (lambda d: d["vehicle"].update(tire_radius=0), "sc.toml: [vehicle] tire_radius: must be positive, got 0"),
    (lambda d: d["runs"][0].update(fs=-200), "sc.toml: runs[0] (id 'T_LL'): fs: must be positive, got -200"),
    (lambda d: d["runs"][0].pop("duration"), "sc.toml: runs[0] (id 'T_LL'): missing key 'duration'"),
    (lambda d: d["runs"][0].update(file="w.csv"), "sc.toml: runs[0] (id 'T_LL'): unknown key 'file' (a scenario run "
     "gives 'fs' and 'duration' instead of a file); allowed: id, track, road_class, road_seed, coherence, speed, fs, "
     "duration, moving, input, signal, amplitude, f_low, f_high, pattern, signal_seed"),
    (lambda d: d["model"].update(knots=[0.1]) if "model" in d else d.update(model={"knots": [0.1]}),
     "sc.toml: [model]: unknown key 'knots'; allowed: extensions, damper_knots"),
    (lambda d: d.update(truths={}), "sc.toml: unknown key 'truths'; allowed: name, vehicle, known, bounds, model, "
     "tracks, runs, truth, dampers, hifi"),
])
def test_declarative_sections_give_one_line_naming_file_section_and_key(tmp_path, edit, message):
    """Unknown, missing and mistyped keys, worded from the section tables (data/schema/keys.py)."""
    doc = _scenario_doc()
    assert doc["runs"][0]["id"] == "T_LL"
    edit(doc)
    with pytest.raises(rideid.DataError) as e:
        rideid.data.schema.parse_scenario(doc, tmp_path / "sc.toml")
    assert str(e.value) == str(tmp_path / message)


def test_section_reads_types_defaults_and_ranges_in_order():
    from rideid.data.schema import Key, Messages, Section
    sec = Section({"length": Key(required=True, unit="m", positive=True), "count": Key(whole=True, default=2.0),
                   "side": Key("string", default="left", choices=("left", "right")),
                   "angle": Key(unit="degrees", between=(-89.0, 89.0))},
                  Messages(missing="{where}: no {key}"), also=("id",))
    assert sec.read({"id": "x", "length": 3}, "f") == {"length": 3.0, "count": 2.0, "side": "left"}
    assert sec.allowed == ("id", "length", "count", "side", "angle")
    for tab, msg in [({"lenght": 1}, "f: unknown key 'lenght'; allowed: id, length, count, side, angle"),
                     ({}, "f: no length"),
                     # types are checked before ranges: the count's type error comes first
                     ({"length": -1, "count": "two"}, "f count: expected a finite number, got 'two'"),
                     ({"length": -1}, "f length: must be positive, got -1"),
                     ({"length": 1, "count": 2.5}, "f: key 'count' must be a non-negative whole number, got 2.5"),
                     ({"length": 1, "side": "up"}, "f: key 'side' must be \"left\" or \"right\", got 'up'"),
                     ({"length": 1, "angle": 90}, "f: key 'angle' must be between -89 and 89 degrees, got 90.0"),
                     ([1], "f must be a table")]:
        with pytest.raises(rideid.DataError) as e:
            sec.read(tab, "f")
        assert str(e.value) == msg
    with pytest.raises(ValueError, match="Key type 'float'"):
        Key("float")


def test_atomic_output_builds_on_the_output_file_system_with_mkdir_permissions(tmp_path, monkeypatch):
    """A new folder is the temporary one renamed, with the permissions mkdir gives under the umask (not
    mkdtemp's 0700); into an existing folder (perhaps a mount point of its own) the files move from a
    temporary folder inside it; what the caller's block raises goes on as it is, and nothing is left."""
    import os
    import tempfile

    from rideid.data.schema.common import atomic_output
    made = []
    real = tempfile.mkdtemp
    monkeypatch.setattr(tempfile, "mkdtemp", lambda **kw: made.append(Path(kw["dir"])) or real(**kw))
    old = os.umask(0o022)
    try:
        with atomic_output(tmp_path / "new") as tmp:
            (tmp / "a.txt").write_text("a")
    finally:
        os.umask(old)
    assert (tmp_path / "new").stat().st_mode & 0o777 == 0o755
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "keep.txt").write_text("k")
    with atomic_output(tmp_path / "mine") as tmp:
        (tmp / "b.txt").write_text("b")
    assert made == [tmp_path.resolve(), (tmp_path / "mine").resolve()]
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["b.txt", "keep.txt"]
    with pytest.raises(FileNotFoundError):  # the block's own error, not "cannot write the output folder"
        with atomic_output(tmp_path / "mine") as tmp:
            (tmp / "c.txt").write_text("c")
            open(tmp_path / "no-such-file")
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["b.txt", "keep.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "new"]
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(rideid.DataError, match="a_file/out: cannot write the output folder"):
        with atomic_output(tmp_path / "a_file" / "out"):
            pass
