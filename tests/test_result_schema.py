"""result.json is typed and versioned (SPEC §13): schema_version, plan, settings, assessments; the files written
before (schema version 1, no schema_version) still read, their assessments built from the old keys."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest

import rideid
from rideid import settings
from rideid.data.schema.result import SCHEMA_VERSION
from rideid.errors import DataError
from rideid.estimate.records import (ASSESSMENTS, VERDICTS, AdequacyAssessment, BoundsAssessment, DrawingAssessment,
                                     LevelAssessment, MaterialityAssessment, SensorHintsAssessment,
                                     SmallAngleAssessment, assessments_of, plan_of)
from rideid.estimate.result import jsonable
from rideid.estimate.sections import SECTIONS, TABLES, FindingRecord, ModelSection, PolishSection

NEW_KEYS = ("schema_version", "plan", "settings", "assessments")


@pytest.fixture(scope="module")
def fitted(sim_dataset, tmp_path_factory):
    """The built-in car fitted (a short search) from a copy of its dataset that sets one setting in [settings],
    with another set from Python: ``(result, folder written)``."""
    ds_dir = tmp_path_factory.mktemp("set") / "ds"
    shutil.copytree(sim_dataset, ds_dir)
    with open(ds_dir / "dataset.toml", "a") as f:
        f.write('\n[settings]\n"adequacy.alpha" = 0.05\n')
    ds = rideid.load_dataset(ds_dir)
    with settings.using("materiality", material_shift=2.0):
        res = rideid.identify(ds, seed=1, generations=6, population=16, model="base")
    out = tmp_path_factory.mktemp("fit")
    res.save(out)
    return res, out


def test_result_json_records_the_version_the_plan_and_every_setting_used(fitted):
    res, out = fitted
    doc = json.loads((out / "result.json").read_text())
    assert doc["schema_version"] == SCHEMA_VERSION == 2
    # every setting, the dataset's and Python's in force, the rest at their defaults; none left changed after
    assert doc["settings"] == res.settings and len(doc["settings"]) == len(settings.REGISTRY)
    assert doc["settings"]["adequacy.alpha"] == 0.05 and doc["settings"]["materiality.material_shift"] == 2.0
    assert doc["settings"]["roadfit.band"] == [0.2, 25.0]
    assert settings.changed() == {}
    # the adequacy test ran with the dataset's alpha: the registry is read when the code runs
    assert res.adequacy["alpha"] == 0.05 and res.assessments[0].alpha == 0.05
    # the plan: the car's free parameters over all runs, total_mass held (the built-in runs have given starts)
    blocks = doc["plan"]["blocks"]
    assert [b["kind"] for b in blocks] == ["car"]
    assert blocks[0]["unknowns"] == res.names and "total_mass" in blocks[0]["fixed"]
    assert blocks[0]["runs"] == [r.id for r in rideid.data.schema.load_manifest(res.dataset).runs]
    # one assessment per declared kind, in order, each with its verdict and reason; the old keys still written
    kinds = [a["kind"] for a in doc["assessments"]]
    assert kinds == [a.kind for a in ASSESSMENTS] == ["adequacy", "materiality", "small_angles", "sensor_hints",
                                                      "level", "drawing", "roads", "bounds", "setup",
                                                      "error_bar_shape"]
    assert all(a["verdict"] in VERDICTS and isinstance(a["reason"], str) and a["reason"] for a in doc["assessments"])
    ad = doc["assessments"][0]
    assert ad["verdict"] == ("pass" if doc["adequacy"]["adequate"] else "fail") and ad["pairs"] == 100
    sa = doc["assessments"][2]
    assert sa["largest_roll_deg"] == doc["adequacy"]["small_angle"]["largest_roll_deg"]
    assert sa["verdict"] == ("warn" if doc["adequacy"]["small_angle"]["optimistic"] else "pass")
    assert doc["assessments"][-3] == {"kind": "bounds", "verdict": "pass", "at_bound": [],
                                      "reason": "no free parameter ended at a search bound"}
    assert doc["assessments"][-2] == {"kind": "setup", "verdict": "pass", "runs": [],
                                      "reason": "the data contradicted no declared set-up value at load"}
    shape = doc["assessments"][-1]
    assert shape["kind"] == "error_bar_shape" and shape["ratio"] == doc["polish"]["shape"]["ratio"]
    assert shape["verdict"] in ("pass", "not assessed") and shape["optimistic"] == []
    for key in ("adequacy", "model", "parameters", "starts", "checks"):
        assert key in doc


def test_load_reads_the_typed_records_back(fitted):
    res, out = fitted
    back = rideid.load_result(out)
    assert back.assessments == res.assessments and back.plan == res.plan and back.settings == res.settings
    assert type(back.assessments[0]) is AdequacyAssessment


def test_one_assessment_by_its_kind(fitted):
    res, out = fitted
    assert res.assessment("adequacy") is res.assessments[0]
    roads = rideid.load_result(out).assessment("roads")
    assert roads.verdict == "not assessed" and "no run on an unknown road" in roads.reason  # track runs only
    with pytest.raises(KeyError, match="no assessment 'road' .*roads"):
        res.assessment("road")


def test_a_file_without_a_schema_version_is_version_1_and_gets_its_assessments_from_the_old_keys(fitted, tmp_path):
    res, out = fitted
    doc = json.loads((out / "result.json").read_text())
    old = {k: v for k, v in doc.items() if k not in NEW_KEYS}
    (tmp_path / "result.json").write_text(json.dumps(old))
    back = rideid.load_result(tmp_path)
    assert back.assessments == res.assessments  # the same records, from adequacy and details
    assert back.plan is None and back.settings is None
    assert back.to_dict()["schema_version"] == 2 and back.to_dict()["assessments"] == doc["assessments"]


@pytest.mark.parametrize("version, message", [
    (3, "schema_version 3 was written by a newer rideid; this one reads up to 2 (upgrade rideid)"),
    ("2", "schema_version must be a positive integer, got '2'"),
    (0, "schema_version must be a positive integer, got 0"),
])
def test_a_schema_version_this_rideid_cannot_read_is_one_line(fitted, tmp_path, version, message):
    doc = json.loads((fitted[1] / "result.json").read_text())
    (tmp_path / "result.json").write_text(json.dumps({**doc, "schema_version": version}))
    with pytest.raises(DataError) as e:
        rideid.load_result(tmp_path)
    assert str(e.value) == f"{tmp_path / 'result.json'}: {message}"


def _res(adequacy=None, details=None, tracks=None, roads=None, starts=None, names=("k_sf",)):
    return SimpleNamespace(adequacy=adequacy, details=details or {"k_sf": {"value": 1.0}}, tracks=tracks,
                           roads=roads, starts=starts or {}, names=list(names), known={"total_mass": 1400.0})


def test_each_verdict_follows_what_the_result_holds():
    none = assessments_of(_res())
    assert [a.verdict for a in none] == ["not assessed"] * 7 + ["pass", "pass", "not assessed"]
    runs = {"r1": {"body_az_fl": {"structure": True, "level": 5.0}, "roll_rate": {"structure": False, "level": 1.0}}}
    bad = _res({"adequate": False, "reasons": ["the road input explains part of the residual"], "runs": runs,
                "alpha": 0.01, "advice": "try auto",
                "sensor_hints": [{"channel": "axle_az_fl", "highpass_hz": 0.5, "message": "axle_az_fl: AC?"}],
                "materiality": {"material": True, "reason": "moves k_sf by 3 std_total", "threshold": 1.0,
                                "largest_shift": {"parameter": "k_sf", "in_std_total": 3.0},
                                "pairs_left_out": ["r1/body_az_fl"]}},
               details={"k_sf": {"value": 1.0, "at_bound": True}, "m_s": {"value": 1.0, "fixed": True,
                                                                          "at_bound": True}})
    a = {x.kind: x for x in assessments_of(bad)}
    assert a["adequacy"] == AdequacyAssessment("fail", "the road input explains part of the residual", False, 2,
                                               ["r1/body_az_fl"], 0.01, None, False, "try auto")
    assert a["materiality"] == MaterialityAssessment("fail", "moves k_sf by 3 std_total", True, 1.0, "k_sf", 3.0,
                                                     ["r1/body_az_fl"])
    assert a["sensor_hints"] == SensorHintsAssessment("warn", "axle_az_fl: AC?", ["axle_az_fl"], [0.5], None)
    assert a["level"].verdict == "not assessed"  # the caveat qualifies an adequate verdict only
    assert a["bounds"] == BoundsAssessment("fail", a["bounds"].reason, ["k_sf"])  # a fixed one is no finding
    good = _res({"adequate": True, "reasons": ["fine"], "runs": runs, "level_caveat": "loud",
                 "tracks_caveat": "drawn", "small_angle": {"largest_roll_deg": 2.3, "largest_pitch_deg": 1.0,
                                                           "threshold_deg": 1.0, "optimistic": ["k_sf"],
                                                           "note": "rolls 2.3 deg"}})
    a = {x.kind: x for x in assessments_of(good)}
    assert a["level"] == LevelAssessment("warn", "loud", 1, 2)
    assert a["drawing"] == DrawingAssessment("warn", "drawn", [], [])
    assert a["small_angles"].verdict == "warn" and a["small_angles"].optimistic == ["k_sf"]
    assert SmallAngleAssessment.from_dict(a["small_angles"].to_dict()) == a["small_angles"]
    with pytest.raises(ValueError, match="verdict 'ok' is not one of pass, warn, fail, not assessed"):
        BoundsAssessment("ok", "")


def test_a_set_up_value_the_data_mended_is_an_assessment_and_the_caveat_of_an_adequate_verdict():
    """The ``setup`` record reads the load's speed warnings in ``checks``: warn, naming each run with its declared
    speed and the data's; on an adequate verdict its reason is also ``adequacy.setup_caveat`` (with_caveats), which
    the adequacy record, the terminal and the report read; a verdict that is not adequate gets no caveat."""
    from dataclasses import dataclass, field, replace

    from rideid.estimate.records import SetupAssessment, with_caveats

    @dataclass(frozen=True)
    class Result:  # what the records read of an IdentificationResult
        adequacy: dict | None
        checks: list
        details: dict = field(default_factory=lambda: {"k_sf": {"value": 1.0}})
        tracks: dict | None = None
        roads: dict | None = None

    slip = {"severity": "warning", "check": "speed", "message": "run 'H': declared speed 10.1 m/s ...", "run": "H",
            "channel": "speed", "fix": {"speed": 10.0012, "std": 0.0101, "declared": 10.1}}
    note = {**slip, "severity": "note", "run": "T"}
    res = Result({"adequate": True, "reasons": ["fine"], "runs": {}}, [slip, note])
    rec = SetupAssessment.from_result(res)
    caveat = ("a declared speed the data contradict: H (declared 10.1, the data 10.001 m/s); the fit took the data's "
              "speed; check the test log (a speed typed wrong may not be the only slip of that run)")
    assert rec == SetupAssessment("warn", caveat, [{"run": "H", "declared": 10.1, "speed": 10.0012}])
    assert SetupAssessment.from_dict(rec.to_dict()) == rec
    held = with_caveats(res)
    assert held.adequacy == {**res.adequacy, "setup_caveat": caveat} and "setup_caveat" not in res.adequacy
    a = {x.kind: x for x in assessments_of(held)}
    assert a["adequacy"].verdict == "warn" and a["adequacy"].reason == f"fine; but {caveat}"
    bad = replace(res, adequacy={"adequate": False, "reasons": ["structure"]})
    assert with_caveats(bad) is bad and SetupAssessment.from_result(bad).verdict == "warn"
    assert with_caveats(replace(res, checks=[note])).adequacy == res.adequacy


def test_the_plan_has_a_block_per_nuisance():
    tracks = {"W": {"method": "as built: the drawing times an amplitude factor plus unevenness whose spectrum ...",
                    "runs": {"w1": {"amplitude_factor": 1.02, "motion": {"speed_m_s": 10.0}}, "w2": {"fitted": "no"}}},
              "H": {"rejected": "implausible", "runs": {"h1": {"amplitude_factor": 1.5}}}}
    roads = {"u1": {"file": "road/u1.csv"}, "u2": {"file": "road/u2.csv", "motion": {"speed_m_s": 8.0}}}
    plan = plan_of(_res(tracks=tracks, roads=roads, starts={"s1": {"value": 1.0}, "u1": {"value": 0.0}}),
                   ["w1", "w2", "h1", "s1", "u1", "u2"])
    assert [(b.name, b.unknowns, b.runs) for b in plan.blocks] == [
        ("car", ["k_sf"], ["w1", "w2", "h1", "s1", "u1", "u2"]), ("run w1", ["speed", "start"], ["w1"]),
        ("run s1", ["start"], ["s1"]), ("track W", ["amplitude_factor", "unevenness"], ["w1"]),
        ("road u1", ["road"], ["u1"]), ("road u2", ["road", "speed"], ["u2"])]
    assert plan.blocks[0].fixed == ["total_mass"]
    assert type(plan).from_dict(plan.to_dict()) == plan


def test_an_adequate_verdict_with_runs_not_assessed_or_a_loud_residual_is_not_green():
    """SPEC §12-13, never confidently wrong: a verdict that covers only some runs (the others on unknown roads), or
    whose residual is far above the sensor noise, is adequate on what was tested but not a clean verdict: the
    adequacy record says warn and why, and the report's summary and verdict box (amber, not green) say so."""
    from rideid.estimate.assess.adequacy import caveats
    from rideid.report.html import summary_section

    clean = {"adequate": True, "reasons": ["no road-driven structure"], "runs": {}}
    assert caveats(clean) == [] and caveats(None) == [] and caveats({**clean, "adequate": False,
                                                                     "not_assessed": ["B40"]}) == []
    mixed = {**clean, "not_assessed": ["B40", "C25"], "note": "the verdict covers the runs on known tracks"}
    held = caveats(mixed)
    assert len(held) == 1 and "2 run(s) not assessed (B40, C25" in held[0]
    assert len(caveats({**mixed, "level_caveat": "the residual is loud"})) == 2
    rec = {x.kind: x for x in assessments_of(_res(mixed))}["adequacy"]
    assert rec.verdict == "warn" and rec.adequate and "not assessed (B40, C25" in rec.reason
    assert {x.kind: x for x in assessments_of(_res(clean))}["adequacy"].verdict == "pass"
    # the report: the summary's verdict line and the box's colour
    context = {"res": {"model": {}}, "adequacy": mixed, "known": {"total_mass": 1400.0}, "params": [],
               "fit_rows": [], "n_runs": 3, "data_warnings": []}
    summary = summary_section(SimpleNamespace(dampers=None, tracks=None, roads=None, uncertainty=None), context)
    verdict = dict((label, text) for label, text, _ in summary["summary"])["Verdict"]
    assert verdict.startswith("MODEL ADEQUATE ON WHAT WAS TESTED, NOT A CLEAN VERDICT (1 caveat, below)")
    assert summary["verdict_caveats"] == held  # the verdict box: amber (report.html.j2, verdict-warn)


def test_the_reports_verdict_carries_the_caveats_the_terminal_warns_of():
    """The report's adequacy context (rideid.report.estimate_sections.adequacy_rows) keeps what the terminal warns
    of (runs not assessed, the residual level, the tracks as drawn), so its summary and verdict box say it too."""
    from rideid.estimate.assess.adequacy import caveats
    from rideid.report.estimate_sections import adequacy_rows

    adq = {"adequate": True, "reasons": ["fine"], "runs": {}, "level_caveat": "loud", "not_assessed": ["B40"],
           "note": "the verdict covers the runs on known tracks"}
    rows = adequacy_rows({"adequacy": adq})
    assert rows["level_caveat"] == "loud" and rows["not_assessed"] == ["B40"]
    assert caveats(rows) == caveats(adq) and len(caveats(rows)) == 2


def test_the_kept_candidate_is_named_by_its_tracks_after_a_gross_first_fit():
    """``model.candidates`` after a gross first fit holds one extension twice, as drawn and as built: the label
    names the tracks, and the candidate kept is the one on the tracks ``model.first_fit`` says (not the first of that
    name); an ordinary candidate (no ``tracks``) is named by its extensions, base by 'base'; a first fit that
    stopped the choice (``first_fit`` null) keeps its own entry."""
    from rideid.estimate.records import candidate_label, kept_candidate
    bars = ["anti_roll_bars"]
    cands = [{"extensions": bars, "tracks": "as drawn"}, {"extensions": bars + ["powertrain"], "tracks": "as drawn"},
             {"extensions": bars + ["powertrain"], "tracks": "as built"}]
    model = {"extensions": bars + ["powertrain"], "candidates": cands, "first_fit": {"tracks": "as built"}}
    assert [candidate_label(c) for c in cands] == [
        "anti_roll_bars (as drawn)", "anti_roll_bars + powertrain (as drawn)", "anti_roll_bars + powertrain (as built)"]
    assert kept_candidate(model) == 2
    assert kept_candidate(dict(model, first_fit={"tracks": "as drawn"})) == 1
    assert kept_candidate({"extensions": bars, "candidates": cands[:2], "first_fit": None}) == 0
    plain = [{"extensions": []}, {"extensions": bars}]
    assert [candidate_label(c) for c in plain] == ["base", "anti_roll_bars"]
    assert kept_candidate({"extensions": [], "candidates": plain}) == 0
    assert kept_candidate({"extensions": ["tire_damping"], "candidates": plain}) is None
    # the report's model section: the note states the choice's gate only where a criterion was weighed
    from rideid.report.estimate_sections import model_rows
    for c, crit in zip(plain, (130.0, 12.0)):
        c.update(cost=1e-4, criterion=crit, parameters={"m_s": 900.0}, std_robust={"m_s": 1.0})
    assert model_rows({"model": {"extensions": bars, "candidates": plain}})["weighed"] is True
    for c in cands:
        c.update(cost=1e-4, criterion=None, parameters={"m_s": 900.0}, std_robust={"m_s": 1.0})
    section = model_rows({"model": dict(model, first_fit=None)})
    assert section["weighed"] is False and [h["chosen"] for h in section["heads"]] == [False, False, True]


def test_the_sections_are_typed_records_read_as_result_json_holds_them(fitted):
    """model, adequacy, polish, uncertainty, correlation, data_quality, vehicle (and, with their groups, dampers and
    bump_stops): each a record of declared fields (rideid.estimate.sections) holding the keys the file has, in its
    order; read by attribute or as the dict it is written as."""
    res, out = fitted
    doc = json.loads((out / "result.json").read_text())
    back = rideid.load_result(out)
    assert res.dampers is None and "dampers" not in doc and res.bump_stops is None  # the linear car: not written
    for name, cls in SECTIONS.items():
        if name in ("dampers", "bump_stops"):
            continue
        for sec in (getattr(res, name), getattr(back, name)):
            assert type(sec) is cls, name
            assert list(sec) == list(doc[name]) and jsonable(dict(sec)) == doc[name], name
            assert all(getattr(sec, k) is sec[k] for k in sec)
            assert set(sec) <= set(cls.declared_keys())
    assert res.model.extensions == res.model["extensions"] == []
    assert res.adequacy.adequate is doc["adequacy"]["adequate"]
    # a key not written is absent, as from the file: not in the mapping, None as an attribute
    assert "first_fit" not in res.model and res.model.first_fit is None and res.model.get("first_fit", 7) == 7
    with pytest.raises(KeyError):
        res.model["first_fit"]
    # a stage that writes a key nobody declared is stopped where the result is built
    with pytest.raises(TypeError, match=r"result section 'adequacy': undeclared key\(s\) 'verdict' .*AdequacySection"):
        replace(res, adequacy={**res.adequacy, "verdict": "ok"})
    # a dict given becomes the record; `but` adds a key at the end, the record it came from unchanged
    again = replace(res, model={"extensions": ["anti_roll_bars"], "selection": "given"})
    assert type(again.model) is ModelSection and again.model.selection == "given"
    noted = res.model.but(note="why")
    assert list(noted)[-1] == "note" and noted.note == "why" and "note" not in res.model
    # a file's section with a key this version does not declare reads without it (a newer version's is refused
    # by its schema_version)
    assert "extra" not in ModelSection.of({"extensions": [], "extra": 1}, strict=False)


def test_the_tables_entries_are_typed_records_too(fitted):
    """details (result.json ``parameters``), starts, roads, tracks, preprocessing, modal: name -> a record of
    declared fields, each read as the dict the file holds; checks a list of them."""
    res, out = fitted
    doc = json.loads((out / "result.json").read_text())
    back = rideid.load_result(out)
    for attr, cls in TABLES.items():
        key = "parameters" if attr == "details" else attr
        for table in (getattr(res, attr), getattr(back, attr)):
            if not doc.get(key):
                assert not table, attr
                continue
            assert list(table) == list(doc[key]) and all(type(e) is cls for e in table.values()), attr
            assert jsonable({k: dict(e) for k, e in table.items()}) == doc[key], attr
    # and the checks' findings, a list of records
    assert all(type(c) is FindingRecord for c in res.checks + back.checks)
    assert jsonable([dict(c) for c in back.checks]) == doc["checks"]
    k_sf = res.details["k_sf"]
    assert k_sf.value == k_sf["value"] == res.parameters["k_sf"] and k_sf.unit == "N/m" and k_sf.fixed is False
    assert k_sf.std_total == doc["parameters"]["k_sf"]["std_total"] and k_sf.reached is None
    assert res.modal["bounce"].frequency_hz == doc["modal"]["bounce"]["frequency_hz"]
    with pytest.raises(TypeError, match="result section 'parameters': undeclared key"):
        replace(res, details={**res.details, "k_sf": {**k_sf, "sigma": 1.0}})


def _identifiers(row: str) -> set:
    """Every identifier inside the backticks of a docs table row (``a, b`` names both)."""
    return {w for span in re.findall(r"`([^`]*)`", row) for w in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", span)}


def test_every_declared_key_of_a_section_is_documented():
    """docs/formats.md's result.json table names each section's every key, and each table entry's (in backticks, in
    its row)."""
    rows = {}
    for line in (Path(__file__).resolve().parents[1] / "docs" / "formats.md").read_text().splitlines():
        if line.startswith("| ") and line.count("|") >= 3:  # the first table naming it: result.json's
            rows.setdefault(line.split("|")[1].strip(), line)
    for name, cls in [*SECTIONS.items(), *((cls.name, cls) for cls in (*TABLES.values(), FindingRecord))]:
        missing = [k for k in cls.declared_keys() if k not in _identifiers(rows[name])]
        assert not missing, (name, missing)


def test_a_record_nested_in_a_section_is_a_dict_in_its_to_dict(fitted):
    """``to_dict`` gives what json.dumps takes: a polish on the tracks as built nests the as-drawn one's record."""
    res, _ = fitted
    nested = res.polish.but(as_drawn=res.polish)
    assert type(nested.as_drawn) is PolishSection
    plain = nested.to_dict()
    assert type(plain["as_drawn"]) is dict and plain["as_drawn"]["nfev"] == res.polish.nfev
    assert json.loads(json.dumps(jsonable(plain)))["as_drawn"]["names"] == res.polish.names
