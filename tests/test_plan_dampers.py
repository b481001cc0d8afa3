"""rideid plan with damper curves (SPEC §7 with §8): the nonlinear car's Fisher information, knot excitation per run."""

import contextlib
import io
import json

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.cli import main
from rideid.data.scenario import load_scenario, run_times
from rideid.data.schema import read_toml
from rideid.estimate.problem.dampers import MIN_SAMPLES, knot_counts
from rideid.model.nonlinear import DEFAULT_KNOTS, NonlinearLayout, curve_names, simulate_nonlinear
from rideid.model.simulator import make_simulator
from rideid.model.params import ALL_NAMES
from rideid.model.simulate import prepare_run

POS = (0.025, 0.05, 0.1, 0.2, 0.4)
VEL = [-k for k in reversed(POS)] + list(POS)
#: keys of plan.json for a linear car (no "dampers")
LINEAR_KEYS = {"scenario", "free", "nominal", "known", "derived", "model", "noise", "criterion", "budget", "targets",
               "robust", "sensitivities", "precision_definitions", "candidates", "all_runs", "selected",
               "greedy_path", "sensitivity_map_comparison", "notes", "declared"}


def digressive(c1, c2, knee=0.1, rebound=2.0):
    """Forces at the default knots: slope c1 up to the knee, c2 beyond; rebound 2x compression (2:1)."""
    pos = [c1 * min(v, knee) + c2 * max(v - knee, 0.0) for v in POS]
    return [-rebound * f for f in reversed(pos)] + pos


FRONT, REAR = digressive(1200, 400), digressive(1100, 370)


def scenario(tmp, runs, dampers=True, extensions=None):
    """The built-in scenario with a 2:1 digressive [dampers] table, a gentle chassis twist (10 mm bumps at
    2 m/s) and the candidate runs ``runs`` (ids)."""
    doc = read_toml(rideid.default_scenario_path())
    if dampers:
        doc["dampers"] = {"velocity": VEL, "front": FRONT, "rear": REAR}
        del doc["truth"]["c_sf"], doc["truth"]["c_sr"]
    if extensions is not None:
        doc["model"] = {"extensions": extensions}
    doc["tracks"].append({"id": "twist_gentle", "kind": "chassis_twist", "start": 1.0, "height": 0.01,
                          "bump_length": 1.6, "spacing": 4.0, "bumps": 2, "first": "left"})
    gentle = {"id": "G", "track": "twist_gentle", "speed": 2.0, "fs": 200.0, "duration": 4.5}
    doc["runs"] = [r for r in [gentle] + doc["runs"] if r["id"] in runs]
    path = tmp / f"sc_{'_'.join(runs)}{'_dm' if dampers else ''}.toml"
    path.write_text(tomli_w.dumps(doc))
    return path


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plan_dampers")
    sc = scenario(tmp, ["G", "T_HH", "H_HH"])
    out = tmp / "plan"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["plan", str(sc), "--out", str(out), "--budget-runs", "2"]) == 0
    return json.loads((out / "plan.json").read_text()), out, buf.getvalue()


def test_plan_json_has_excitation_per_run_and_crlb_per_knot(planned):
    d, out, terminal = planned
    names = curve_names(10)
    assert "c_sf" not in d["free"] and "c_sr" not in d["free"] and all(n in d["free"] for n in names)
    assert "damper_curves" in d["model"]["extensions"]
    assert "nonlinear" in d["sensitivities"]["method"] and d["sensitivities"]["substeps"]["G"] >= 1
    dm = d["dampers"]
    assert dm["velocity"] == pytest.approx(VEL) and dm["nominal"]["front"] == pytest.approx(FRONT)
    for c in d["candidates"]:
        e = c["dampers"]
        assert sorted(e["excited"] + e["not_excited"]) == sorted(names)
        for axle in ("front", "rear"):
            assert len(e[axle]["samples_beyond_previous_knot"]) == 10 and len(e[axle]["excited"]) == 10
    for block in ("selected", "all_runs"):
        for axle in ("front", "rear"):
            b = dm[block][axle]
            for k in ("crlb_std", "crlb_relative", "identify_std", "excited"):
                assert len(b[k]) == 10
            for j, n in enumerate(b["names"]):
                if b["excited"][j]:
                    assert b["crlb_std"][j] > 0 and b["crlb_relative"][j] == pytest.approx(
                        b["crlb_std"][j] / abs(dm["nominal"][axle][j]))
                    assert d[block]["crlb"][n]["std"] == pytest.approx(b["crlb_std"][j])
    # the gentle run reaches the innermost knots only; the harsh twist every knot
    by = {c["id"]: c["dampers"] for c in d["candidates"]}
    assert len(by["T_HH"]["excited"]) == 20 and by["T_HH"]["not_excited"] == []
    assert len(by["G"]["excited"]) <= 6
    for axle in ("front", "rear"):
        g, h = by["G"][axle]["samples_beyond_previous_knot"], by["T_HH"][axle]["samples_beyond_previous_knot"]
        for j in (0, 1, 2, 7, 8, 9):  # beyond +-0.05 m/s
            assert g[j] < MIN_SAMPLES <= h[j], (axle, j, g[j], h[j])
        assert not any(by["G"][axle]["excited"][j] for j in (0, 1, 2, 7, 8, 9))
    text = (out / "plan.md").read_text()
    assert "Damper curves" in text and "| G | F_f1, F_f2" in text
    assert "damper knots run G: not excited F_f1" in terminal and "damper knots run T_HH: all excited" in terminal


def _independent_fisher(sc_path, run_id, free, exclude, step=1e-5):
    """Relative Fisher matrix of one run, from the nonlinear simulator directly (1 % of RMS white noise)."""
    sc = load_scenario(sc_path)
    run = next(r for r in sc.runs if r.id == run_id)
    ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, run_times(run))
    layout = NonlinearLayout(knots=DEFAULT_KNOTS)
    base = {n: float(sc.truth.get(n, 0.0)) for n in ALL_NAMES} | dict(zip(curve_names(10), FRONT + REAR))
    keep = [n for n in free if n not in exclude]

    def row(vals):
        v = dict(base, **vals)
        v["m_s"] = sc.known["total_mass"] - 2 * v["m_uf"] - 2 * v["m_ur"]  # the anchor, as identify applies it
        return [v[n] for n in layout.names]

    rows = [row({})] + [row({n: base[n] * (1 + s * step)}) for s in (1, -1) for n in keep]
    y = make_simulator(sc.geometry, [ri], layout).outputs(np.array(rows))[0]
    d = len(keep)
    J = (y[1:1 + d] - y[1 + d:]) / (2 * step)  # d y / d (x / x0)
    rms = np.sqrt(np.mean(y[0] ** 2, axis=0))
    F = np.einsum("itc,jtc,c->ij", J, J, 1 / (0.01 * rms) ** 2)
    return keep, F, base, sc, ri


def test_knot_crlb_is_the_inverse_fisher_diagonal_of_the_simulator(tmp_path):
    """Plan of the gentle run alone: the knots it does not excite are "not excited" (null), the others' CRLB is
    sqrt(diag(F^-1)) with F computed here from the simulator, those knots left out."""
    sc_path = scenario(tmp_path, ["G"])
    res = rideid.plan(sc_path)
    d = res.to_dict()
    assert d["selected"]["runs"] == ["G"]
    off = d["dampers"]["selected"]["not_excited"]
    assert off == d["candidates"][0]["dampers"]["not_excited"] and len(off) >= 14
    # the excitation, independently: the car's suspension velocities on the run (kernel's sub-steps)
    keep, F, base, sc, ri = _independent_fisher(sc_path, "G", d["free"], off)
    _, X = simulate_nonlinear([base[n] if n != "m_s" else sc.truth["m_s"]
                               for n in NonlinearLayout(DEFAULT_KNOTS).names],
                              sc.geometry, ri, NonlinearLayout(knots=DEFAULT_KNOTS), return_states=True)
    x, y = sc.geometry.corner_xy(np.array([base["a"]]))
    qd = X[0, :, 7:]
    v = qd[:, 3:] - (qd[:, :1] - x[0] * qd[:, 1:2] + y[0] * qd[:, 2:3])
    for a, (axle, vv) in enumerate((("front", v[:, :2].ravel()), ("rear", v[:, 2:].ravel()))):
        c = knot_counts(DEFAULT_KNOTS, vv)
        names = curve_names(10)[10 * a:10 * (a + 1)]
        reached = [n for j, n in enumerate(names) if c[j] >= MIN_SAMPLES or j in (4, 5)]
        assert set(reached) == set(names) - set(off), axle
    crlb = np.sqrt(np.diag(np.linalg.inv(F)))
    # 1e-5: the plan splits the integrator's sub-steps at the knots where the nominal car's curves bend (pinned
    # for all its differences), this unpinned simulator at those where any row's does: both within 1e-4 of
    # the exact response, the CRLBs agree to about 1e-6
    for n, r in zip(keep, crlb):
        assert d["selected"]["crlb"][n]["relative"] == pytest.approx(r, rel=1e-5), n
        assert d["selected"]["crlb"][n]["std"] == pytest.approx(r * abs(base[n]), rel=1e-5), n
    K = 10
    for a, axle in enumerate(("front", "rear")):
        b = d["dampers"]["selected"][axle]
        for j, n in enumerate(b["names"]):
            if n in off:
                assert not b["excited"][j] and b["crlb_std"][j] is None and d["selected"]["crlb"][n]["std"] is None
            else:
                assert b["crlb_relative"][j] == pytest.approx(crlb[keep.index(n)], rel=1e-5)
                assert b["crlb_std"][j] == pytest.approx(crlb[keep.index(n)] * abs((FRONT + REAR)[a * K + j]),
                                                         rel=1e-5)
    assert any("not excited by G" in m for m in d["selected"]["messages"])
    assert "not excited" in res.summary()


def test_linear_damper_plan_json_unchanged(tmp_path):
    sc_path = scenario(tmp_path, ["H_LH", "W_H"], dampers=False)
    d = rideid.plan(sc_path).to_dict()
    assert set(d) == LINEAR_KEYS
    assert "c_sf" in d["free"] and not any(n.startswith("F_") for n in d["free"])
    assert all("dampers" not in c for c in d["candidates"])
    assert d["sensitivities"] == {"method": "central finite differences through the compiled kernel",
                                  "relative_step": 1e-5}


def test_damper_curves_extension_without_table_plans_linear_curves(tmp_path):
    """[model] extensions = ["damper_curves"] on a linear car: the knots' nominal forces are c_s v."""
    sc_path = scenario(tmp_path, ["W_H"], dampers=False, extensions=["damper_curves"])
    d = rideid.plan(sc_path).to_dict()
    c_sf = read_toml(rideid.default_scenario_path())["truth"]["c_sf"]
    assert d["dampers"]["nominal"]["front"] == pytest.approx([c_sf * v for v in DEFAULT_KNOTS])
    assert d["candidates"][0]["dampers"]["not_excited"] == d["dampers"]["selected"]["not_excited"]


def test_plan_of_a_car_with_bump_stops_says_it_plans_without_them(tmp_path):
    """Bump stops in the truth: the plan's model has none, and its note says so and where they are fitted."""
    from rideid.design.planner import BUMP_STOP_NOTE
    path = scenario(tmp_path, ["T_HH"])
    doc = read_toml(path)
    doc["truth"].update(bs_clear_f=0.05, bs_rate_f=5e4, bs_clear_r=0.05, bs_rate_r=5e4)
    path.write_text(tomli_w.dumps(doc))
    res = rideid.plan(path, noise=0.01)
    assert [n for n in res.notes if "bump stop" in n] == [BUMP_STOP_NOTE]
    assert "`rideid identify --model bump_stops` fits the stops" in BUMP_STOP_NOTE
    assert not any(n.startswith("bs_") for n in res.to_dict()["free"])
