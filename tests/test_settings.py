"""The registry of tuning constants (rideid.settings): every setting documented, reasoned and pinned; every
module-level number of estimate/ registered or said to be no tuning constant; read at use time; settable from
Python and from a dataset's [settings] table, with one-line errors."""

from __future__ import annotations

import ast
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rideid
from rideid import settings
from rideid.errors import ArgumentError, DataError

ROOT = Path(__file__).resolve().parents[1]


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(doc: Path) -> set[str]:
    return {_slug(line.lstrip("#")) for line in doc.read_text().splitlines() if line.startswith("#")}


@pytest.mark.parametrize("name", sorted(settings.REGISTRY))
def test_every_setting_has_unit_meaning_reason_and_a_test_that_exists(name):
    s = settings.REGISTRY[name]
    assert re.fullmatch(r"[a-z_]+\.[a-z0-9_]+", s.name), s.name
    assert s.unit and s.meaning, name
    doc, _, anchor = s.reason.partition("#")
    assert doc.startswith("docs/") and (ROOT / doc).is_file(), s.reason
    assert anchor in _anchors(ROOT / doc), f"{name}: no heading '#{anchor}' in {doc}"
    path, _, test = s.test.partition("::")
    assert (ROOT / path).is_file(), s.test
    assert re.search(rf"^def {re.escape(test)}\(", (ROOT / path).read_text(), re.M), s.test
    module = s.name.split(".")[0]
    homes = ("estimate", "conditioning")
    assert any(next((ROOT / "src/rideid" / pkg).rglob(f"{module}.py"), None) for pkg in homes), name


def _numeric(node) -> bool:
    """Whether a module-level value is a number, or numbers only (tuple, list, dict, arithmetic, a call)."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, (ast.Tuple, ast.List)):
        return bool(node.elts) and all(_numeric(e) for e in node.elts)
    if isinstance(node, ast.Dict):
        return bool(node.values) and all(_numeric(v) for v in node.values)
    if isinstance(node, ast.UnaryOp):
        return _numeric(node.operand)
    if isinstance(node, ast.BinOp):
        return _numeric(node.left) and _numeric(node.right)
    if isinstance(node, ast.Call):  # np.array([...]), float(...); a slice is an index range, no number
        return ast.unparse(node.func) != "slice" and bool(node.args) and all(_numeric(a) for a in node.args)
    return False


def test_every_module_level_number_of_estimate_is_a_setting_or_said_to_be_none():
    found = {}
    for path in sorted((ROOT / "src/rideid/estimate").rglob("*.py")):
        for node in ast.parse(path.read_text()).body:
            target = node.targets[0] if isinstance(node, ast.Assign) else getattr(node, "target", None)
            if isinstance(target, ast.Name) and getattr(node, "value", None) is not None and _numeric(node.value):
                found[f"{path.stem}.{target.id}"] = node.lineno
    unregistered = sorted(set(found) - set(settings.NOT_SETTINGS))
    assert unregistered == [], ("module-level numbers that are neither in rideid.settings nor in "
                                f"settings.NOT_SETTINGS: {unregistered}")
    assert sorted(set(settings.NOT_SETTINGS) - set(found)) == []  # no stale exemption
    assert all(len(why) > 20 for why in settings.NOT_SETTINGS.values())


def test_the_docs_table_is_the_registry():
    text = (ROOT / "docs/settings.md").read_text()
    assert settings.markdown_table() in text, "docs/settings.md: regenerate the table (python -m rideid.settings)"


def test_set_reset_and_using_restore_the_shipped_values():
    d = settings.defaults
    assert d["adequacy.alpha"] == settings.REGISTRY["adequacy.alpha"].default == 0.01
    settings.set_defaults("adequacy", alpha=0.05, lags=[0, 1, 2])
    try:
        assert d["adequacy.alpha"] == 0.05 and d["adequacy.lags"] == (0, 1, 2)
        assert settings.changed() == {"adequacy.alpha": 0.05, "adequacy.lags": [0, 1, 2]}
    finally:
        settings.reset_defaults()
    assert d["adequacy.alpha"] == 0.01 and settings.changed() == {}
    with pytest.raises(RuntimeError):
        with settings.using({"roadfit.band": (0.5, 20.0)}) as values:
            assert values["roadfit.band"] == (0.5, 20.0)
            raise RuntimeError
    assert d["roadfit.band"] == (0.2, 25.0)  # restored on the error too
    assert settings.current()["roadfit.band"] == [0.2, 25.0] and len(settings.current()) == len(settings.REGISTRY)


def test_bad_names_and_values_are_one_line_naming_the_setting():
    with pytest.raises(ArgumentError, match=r"unknown setting 'adequacy\.alfa' \(did you mean adequacy\.alpha"):
        settings.set_defaults({"adequacy.alfa": 0.05})
    with pytest.raises(ArgumentError, match="alpha: a keyword needs the module it belongs to"):
        settings.using(alpha=0.05).__enter__()
    with pytest.raises(ArgumentError, match=r"'adequacy\.ar_max' must be an integer \(default 10\), got 2\.5"):
        settings.set_defaults("adequacy", ar_max=2.5)
    with pytest.raises(ArgumentError, match=r"'roadfit\.band' must be a list of two finite numbers"):
        settings.set_defaults("roadfit", band=[1.0])
    with pytest.raises(ArgumentError, match=r"'adequacy\.alpha' must be a finite number"):
        settings.set_defaults("adequacy", alpha=float("nan"))
    with pytest.raises(KeyError, match="unknown setting"):
        settings.defaults["nope.nope"]
    assert "nope.nope" not in settings.defaults and settings.defaults.get("adequacy.alpha") == 0.01
    # nothing was changed by the refused calls (all are checked before any is set)
    with pytest.raises(ArgumentError):
        settings.set_defaults({"adequacy.alpha": 0.2, "adequacy.nope": 1})
    assert settings.changed() == {}


def test_the_code_reads_the_registry_when_it_runs():
    """Closed forms: the model choice's price per parameter is half the chi-square(2) quantile, -ln(level); the
    Ljung-Box statistic over the lags in force is the one with those lags given; the old names follow."""
    from rideid.estimate.assess import adequacy
    from rideid.estimate.choice import model_choice

    assert model_choice.penalty() == pytest.approx(-math.log(0.001), rel=1e-12)
    with settings.using("model_choice", penalty_level=0.01):
        assert model_choice.penalty() == pytest.approx(-math.log(0.01), rel=1e-12)
        assert "C = W + 4.61 k" in model_choice.CRITERION.format(model_choice.penalty(), 2 * model_choice.penalty())
    e = np.random.default_rng(3).standard_normal(400)
    q25, q5 = adequacy.ljung_box(e), adequacy.ljung_box(e, lags=5)
    assert q25 != q5
    with settings.using("adequacy", whiteness_lags=5):
        assert adequacy.ljung_box(e) == q5
        assert adequacy.WHITENESS_LAGS == 5  # the old name reads the registry
    assert adequacy.ljung_box(e) == q25 and adequacy.WHITENESS_LAGS == 25
    assert rideid.settings is settings  # reachable after a plain import rideid


def _dataset(tmp_path, table: str) -> Path:
    toml = tmp_path / "dataset.toml"
    toml.write_text('name = "s"\n[vehicle]\nwheelbase = 2.6\ntrack_front = 1.5\ntrack_rear = 1.5\ntire_radius = 0.3\n'
                    '[known]\ntotal_mass = 1400.0\n[[tracks]]\nid = "B"\nkind = "flat"\n'
                    '[[runs]]\nid = "r"\ntrack = "B"\nspeed = 10.0\nfile = "r.csv"\n'
                    + table)
    return toml


def test_a_dataset_sets_them_in_a_settings_table(tmp_path):
    from rideid.data.schema import load_manifest

    man = load_manifest(_dataset(tmp_path, '[settings]\nadequacy.alpha = 0.05\n"roadfit.band" = [0.5, 20]\n'
                                           '[settings.materiality]\nmaterial_shift = 2\n'))
    assert dict(man.settings) == {"adequacy.alpha": 0.05, "roadfit.band": (0.5, 20.0),
                                  "materiality.material_shift": 2.0}
    assert man.to_dataset_doc()["settings"]["roadfit.band"] == [0.5, 20.0]
    with pytest.raises(DataError) as e:
        load_manifest(_dataset(tmp_path, "[settings]\nadequacy.alfa = 0.05\n"))
    assert str(e.value) == (f"{tmp_path / 'dataset.toml'}: [settings]: unknown setting 'adequacy.alfa'; the settings "
                            "(module.name) are listed in docs/settings.md")
    with pytest.raises(DataError, match=r"\[settings\]: 'bumps\.min_samples' must be an integer"):
        load_manifest(_dataset(tmp_path, '[settings]\nbumps.min_samples = "many"\n'))


def test_the_command_line_refuses_an_unknown_setting_in_one_line(tmp_path):
    _dataset(tmp_path, "[settings]\nadequacy.alfa = 0.05\n")
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "rideid", "identify", str(tmp_path), "--out", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert p.returncode == 2, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("rideid: error")]
    where = tmp_path / "dataset.toml"
    assert "Traceback" not in p.stderr and lines == [f"rideid: error: {where}: [settings]: unknown setting "
                                                     "'adequacy.alfa'; the settings (module.name) are listed in "
                                                     "docs/settings.md"]
    assert not out.exists()


def test_a_datasets_settings_are_in_force_while_it_is_loaded(sim_dataset, tmp_path):
    """The built-in runs match their tracks with a correlation of 1.00; a [settings] table that asks for more than
    a correlation can give makes every run a mismatch when the dataset is loaded, and only while it is."""
    import shutil

    shutil.copytree(sim_dataset, tmp_path / "ds")
    with open(tmp_path / "ds" / "dataset.toml", "a") as f:
        f.write('\n[settings]\n"checks.match_min" = 1.5\n')
    with pytest.raises(DataError, match=r"run 'T_LL' does not match track 'twist_low' at speed 3 m/s: "
                                        r"correlation 1\.00 .*\(9 more error\(s\) of this kind\)"):
        rideid.load_dataset(tmp_path / "ds")
    assert settings.defaults["checks.match_min"] == 0.5
