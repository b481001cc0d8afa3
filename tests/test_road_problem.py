"""The road problem's numbers (rideid.estimate.problem.joint.JointProblem): its Hessian by second differences, every
evaluation on both cores, against a closed form."""

import numpy as np

import rideid
from rideid.estimate.problem.joint import JointProblem, second_differences


class _LogLinear:
    """A residual block linear in the logarithms of the free parameters: ``A log x - b`` (the problem's coordinates
    ``v`` are those logarithms, so half the cost's Hessian is ``A^T A`` exactly)."""

    order = 0
    reweighted = False

    def __init__(self, A, b):
        self.A, self.b = A, b

    def residuals(self, x, P, geom):
        return self.A @ np.log(x) - self.b


def test_the_hessian_is_the_closed_form_and_its_evaluations_run_side_by_side(both_cores):
    """Half the Hessian of ``sum e^2`` of two log-linear blocks (weights 1 and 2) is ``A1^T A1 + 4 A2^T A2`` to
    1e-6 (second differences of a quadratic: rounding alone), cross terms included; the costs at many points at
    once (on threads, each point's blocks in turn) are the residuals' own, bit for bit."""
    sc = rideid.default_scenario()
    space = rideid.ParameterSpace(sc.known, sc.geometry)
    x0 = np.array([sc.truth[n] for n in space.names])
    rng = np.random.default_rng(5)
    d = x0.size
    blocks = [_LogLinear(rng.standard_normal((30, d)), rng.standard_normal(30)),
              _LogLinear(rng.standard_normal((20, d)), rng.standard_normal(20))]
    prob = JointProblem(space, sc.geometry, blocks, [1.0, 2.0], [30, 20])
    v = prob.v(x0)
    want = blocks[0].A.T @ blocks[0].A + 4 * blocks[1].A.T @ blocks[1].A
    H = prob.hessian(v)
    np.testing.assert_allclose(H, want, rtol=0, atol=1e-6 * np.abs(want).max())
    assert np.abs(want - np.diag(np.diag(want))).max() > 1.0  # the cross terms are there to be checked
    V = v + 1e-2 * rng.standard_normal((7, d))
    assert np.array_equal(prob.costs(V), [float(np.sum(prob(z) ** 2)) for z in V])


class _AffineInKnots:
    """A road run's block with damper curves in miniature: residuals affine in the knot forces ``F`` (x units) with
    a car-dependent matrix, ``(A0 + sum_i log(c_i) A_i) F / 1e3 + B log c + 0.3 (B log c)^2 - b`` for the car's free
    parameters ``c`` (their logarithms are the problem's ``v``)."""

    order = 0
    reweighted = False
    affine_in_knots = True

    def __init__(self, rng, m, car, knots):
        self.car, self.knots = car, knots
        self.A = rng.standard_normal((len(car) + 1, m, len(knots)))
        self.B = rng.standard_normal((m, len(car)))
        self.b = rng.standard_normal(m)

    def residuals(self, x, P, geom):
        lc = np.log(x[self.car])
        M = self.A[0] + np.tensordot(lc, self.A[1:], axes=1)
        u = self.B @ lc
        return M @ x[self.knots] / 1e3 + u + 0.3 * u ** 2 - self.b


class _Drawn:
    """The runs on tracks as drawn in miniature: not affine in the knots (``tanh`` of every parameter's ``v``
    mixed), residuals of many rows at once (``residual_rows``) as the simulator's population gives them."""

    order = -np.inf
    reweighted = False

    def __init__(self, rng, m, to_v):
        self.C = rng.standard_normal((m, to_v(None).size)) / 4
        self.to_v = to_v

    def residual_rows(self, X):
        return np.tanh(self.to_v(X) @ self.C.T)

    def residuals(self, x, P, geom):
        return self.residual_rows(x[None])[0]


def test_the_knots_entries_of_the_hessian_are_the_whole_costs_second_differences(both_cores):
    """With damper curves on unknown roads the Hessian takes the road blocks' knot entries exactly (their residuals
    are affine in the knot forces: ``J^T J`` among the knots, with a knot force in logarithmic coordinates its
    gradient on the diagonal, and a difference of the knots' gradient across each car parameter) and the other
    blocks' by their own cost's second differences, the costs of the runs as drawn a population at a time: the
    same half Hessian as the whole cost's second differences, to their truncation (``h^2 / 12`` of the cost's
    fourth derivative along a knot force in logarithmic coordinates: 3e-7 of the largest entry here, 0.25 times
    that at half the step), with fewer costs of every block."""
    sc = rideid.default_scenario()
    space = rideid.ParameterSpace(sc.known, sc.geometry, extensions=("damper_curves",),
                                  damper_knots=(0.1, 0.3))
    names = list(space.names)
    knots = [j for j, n in enumerate(names) if n in set(space.knot_names)]
    car = [j for j in range(len(names)) if j not in set(knots)]
    rng = np.random.default_rng(11)
    x0 = np.array([0.5 * (lo + hi) for lo, hi in space.bounds])
    probe = JointProblem(space, sc.geometry, [], [])
    assert probe.log[knots].any() and not probe.log[knots].all()  # both kinds of a knot force's coordinates

    def to_v(X):
        return probe.v(x0) if X is None else np.array([probe.v(x) for x in np.atleast_2d(X)])

    drawn = _Drawn(rng, 40, to_v)
    blocks = [drawn, _AffineInKnots(rng, 60, car, knots), _AffineInKnots(rng, 50, car, knots)]
    prob = JointProblem(space, sc.geometry, blocks, [1.0, 0.5, 2.0], [40, 60, 50])
    v = prob.v(x0)
    split = prob.knot_split()
    assert split is not None and split[2] == [1, 2] and split[3] == [0]
    H = prob.hessian(v)
    vv = np.clip(v, prob.vbounds[0] + 1e-3, prob.vbounds[1] - 1e-3)
    whole = second_differences(prob.costs, vv, 1e-3, range(v.size))
    np.testing.assert_allclose(H, whole, rtol=0, atol=1e-6 * np.abs(whole).max())
    finer = second_differences(prob.costs, vv, 5e-4, range(v.size))  # the whole's truncation, not the split's
    assert np.abs(finer - H)[np.ix_(knots, knots)].max() < 0.3 * np.abs(whole - H)[np.ix_(knots, knots)].max()
    assert np.abs(H[np.ix_(car, knots)]).max() > 1e-3 * np.abs(H).max()  # the car-knot entries are there
    # the population's costs are the rows' own
    V = v + 1e-2 * rng.standard_normal((5, v.size))
    np.testing.assert_allclose(prob.costs(V, parts=[0]), [np.sum(drawn.residuals(prob.x(z), None, None) ** 2)
                                                          for z in V], rtol=1e-12)
