"""Damper knees found by the data (SPEC §8, issue 38): the knee of a fitted curve and its error bar,
the knee grid replacing the default knots, a user's knots winning, the report marking the knees."""

import numpy as np
import pytest

from rideid.estimate.problem.cost import ParameterSpace, curve_knots
from rideid.estimate.problem.dampers import KNEE_GRID, KNEE_SIGNIFICANCE, format_dampers, knee_of, knees
from rideid.estimate.problem.build import finds_knees
from rideid.model.nonlinear import DEFAULT_KNOTS
from rideid.model.params import Geometry

GEOM = Geometry(2.579, 1.387, 1.364, 0.30)
V = np.array(KNEE_GRID)


def broken(v, c1, c2, b):
    return c1 * np.minimum(v, b) + c2 * np.maximum(v - b, 0.0)


@pytest.mark.parametrize("b", [0.0371, 0.06, 0.1234, 0.16, 0.25])
def test_knee_of_recovers_a_broken_line_anywhere_between_the_knots(b):
    k, c1, c2 = knee_of(V, broken(V, 2000.0, 600.0, b))
    assert k[0] == pytest.approx(b, abs=1e-5)
    assert c1[0] == pytest.approx(2000.0, rel=1e-4) and c2[0] == pytest.approx(600.0, rel=1e-3)


def _space():
    return ParameterSpace({"total_mass": 1093.3}, GEOM, extensions=("damper_curves",), damper_knots=KNEE_GRID)


def _row(space, front, rear):
    P = space.full(np.array([space._nominal_row()[[space.col[n] for n in space.names]]]))[0]
    v = np.asarray(space.layout.knots)
    for prefix, f in (("F_f", front), ("F_r", rear)):
        for j, vj in enumerate(v):
            P[space.col[f"{prefix}{j + 1}"]] = f(vj)
    return P


def test_knee_std_robust_agrees_with_the_delta_method():
    """The draws' spread of the knee against the linearised propagation of the same covariance (finite
    differences of knee_of), on a curve bending at 0.11 m/s in compression, 0.14 in rebound."""
    space = _space()
    P = _row(space, lambda v: broken(v, 2400, 700, 0.11) if v > 0 else -2 * broken(-v, 2400, 700, 0.14),
             lambda v: 1800 * v)
    names = list(space.knot_names)
    sd = np.abs([P[space.col[n]] for n in names]) * 0.002 + 0.5
    cov = np.diag(sd ** 2)
    out = knees(space, P, cov, names)
    K = len(KNEE_GRID)
    for side, idx, sign, b in (("compression", range(K, 2 * K), 1, 0.11), ("rebound", range(K - 1, -1, -1), -1, 0.14)):
        e = out["front"][side]
        assert e["velocity"] == pytest.approx(sign * b, abs=1e-5)
        F = np.abs([P[space.col[names[j]]] for j in idx])
        s = sd[list(idx)]
        grad = np.array([(knee_of(V, F + h)[0][0] - knee_of(V, F - h)[0][0]) / (2 * s[j])
                         for j in range(K) for h in [np.eye(K)[j] * s[j]]])
        delta = np.sqrt(np.sum((grad * s) ** 2))
        assert e["std_robust"] == pytest.approx(delta, rel=0.15), (side, e["std_robust"], delta)
    # the straight rear axle: no knee, the slope ratio 1 within its error bar
    for side in ("compression", "rebound"):
        e = out["rear"][side]
        assert e["velocity"] is None and "no significant bend" in e["note"]
        assert abs(e["slope_ratio"] - 1) <= KNEE_SIGNIFICANCE * e["slope_ratio_std_robust"]


def test_knees_leave_out_knots_not_excited():
    space = _space()
    K = len(KNEE_GRID)
    # compression: only the first two grid knots excited -> no knee can be placed
    frozen = [f"F_f{j + 1}" for j in range(K + 2, 2 * K)]
    sp = space.with_frozen(frozen)
    P = sp.full(np.array([_row(space, lambda v: broken(abs(v), 2400, 700, 0.11) * np.sign(v),
                                lambda v: 1800 * v)[[space.col[n] for n in sp.names]]]))[0]
    out = knees(sp, P, None, list(sp.names))
    assert out["front"]["compression"]["velocity"] is None and out["front"]["compression"]["excited_knots"] == 2
    assert out["front"]["rebound"]["excited_knots"] == K


def test_the_grid_replaces_the_default_knots_unless_the_user_sets_knots():
    assert set(DEFAULT_KNOTS) <= set(curve_knots(KNEE_GRID))  # every default knot is a grid knot
    default = ParameterSpace({"total_mass": 1093.3}, GEOM, extensions=("damper_curves",))
    assert finds_knees(default)
    given = ParameterSpace({"total_mass": 1093.3}, GEOM, extensions=("damper_curves",), damper_knots=(0.05, 0.12))
    assert not finds_knees(given)
    bounded = ParameterSpace({"total_mass": 1093.3}, GEOM, {"F_f6": [10.0, 200.0]}, extensions=("damper_curves",))
    assert not finds_knees(bounded)
    assert not finds_knees(ParameterSpace({"total_mass": 1093.3}, GEOM))


def test_terminal_and_figure_show_the_knees():
    from rideid.report import html as H
    import matplotlib.pyplot as plt

    space = _space()
    P = _row(space, lambda v: np.sign(v) * broken(abs(v), 2400, 700, 0.12),
             lambda v: np.sign(v) * broken(abs(v), 2000, 500, 0.08))
    from rideid.estimate.problem.dampers import dampers_block
    names = list(space.names)
    cov = np.diag([1.0] * len(names))
    dm = dampers_block(space, P, cov, cov, names)
    assert dm["knots_from"].startswith("found") and "statistical only" in dm["grid_note"]
    text = format_dampers(dm)
    assert "knee front compression: +0.1200 m/s" in text and "knee rear rebound: -0.0800 m/s" in text
    assert "knees found" in H.knee_summary(dm) and "rear +0.080" in H.knee_summary(dm)
    fig = H.damper_curves_figure(dm, {"front": 1800.0, "rear": None})
    for ax, want in zip(fig.axes, (0.12, 0.08)):
        xs = sorted(abs(ln.get_xdata()[0]) for ln in ax.get_lines() if ln.get_color() == "tab:green")
        assert xs == pytest.approx([want, want], abs=1e-4)
        assert "knee found (± 2 std_robust)" in [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)
    from types import SimpleNamespace
    from rideid.report.figures import dampers_figure
    fig = dampers_figure(SimpleNamespace(dampers=dm))  # the notebook's figure: a dotted line per knee
    xs = sorted(round(ln.get_xdata()[0], 4) for ln in fig.axes[0].get_lines() if ln.get_linestyle() == ":")
    assert xs == [-0.12, -0.08, 0.08, 0.12]
    plt.close(fig)


def test_a_curve_that_bends_in_stages_lists_each_bend():
    """The van's valve opening in three stages (slopes 2400, 2100, 1000, 600 N s/m, bends at 0.05, 0.15,
    0.3 m/s, grid knots): each bend listed with its slope change; a straight curve lists none."""
    slopes, at = np.array([2400.0, 2100.0, 1000.0, 600.0]), np.array([0.05, 0.15, 0.3])

    def staged(v):
        edges = np.concatenate([[0.0], at, [np.inf]])
        return sum(s * np.clip(v - lo, 0, hi - lo) for s, lo, hi in zip(slopes, edges[:-1], edges[1:]))
    F = staged(V)
    cov = np.diag((0.001 * F + 0.2) ** 2)
    from rideid.estimate.problem.dampers import bends_of
    got = bends_of(V, F, cov)
    assert [b["velocity"] for b in got] == pytest.approx(list(at))
    assert [b["slope_change"] for b in got] == pytest.approx([-300.0, -1100.0, -400.0], rel=1e-9)
    assert all(b["std_robust"] > 0 for b in got)
    assert bends_of(V, 1800 * V, cov) == []
