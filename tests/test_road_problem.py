"""The road problem's numbers (rideid.estimate.problem.joint.JointProblem): its Hessian by second differences, every
evaluation on both cores, against a closed form."""

import numpy as np

import rideid
from rideid.estimate.problem.joint import JointProblem


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
