"""How much a road fit's error bars owe to the cost's rounding: ``python benchmarks/study_rounding.py DATASET``.

A fit with unknown roads or tracks as built (:mod:`rideid.estimate.fit.anyroad`) takes its error bars' bread from
the true Hessian of the cost, by central second differences (``JointProblem.hessian``, step 1e-3 in the problem's
coordinates). The cost carries rounding (eigenvectors, the boundary unknowns' damped solve), and a second
difference divides it by the step squared. ``rideid identify DATASET --seed 1`` (defaults) is run with the Hessian
of the kept fit captured; then, at that point:

* the cost's rounding ``delta``: ``JointProblem.rounding`` (the spread of ``f(v + t e_k) + f(v - t e_k)`` over 16
  moves of 1e-9: the cost itself moves by ~1e-18 there, the gradient's terms cancel, what is left is rounding);
* what it does to each error bar: 200 draws of that rounding on every cost the Hessian's stencils take (one
  ``f0`` shared by the diagonal), each parameter's ``sqrt`` of the bread's diagonal (``pinv(H)`` on the
  directions rideid resolves, the problem's coordinates) against the captured one: the median and the 90th
  percentile of ``|ratio - 1|``;
* the same bread from the Hessian at steps of 5e-4 and 2e-3 (truncation and rounding together);
* the Hessian's three smallest eigenvalues, the parameters that make up each direction, and each one's rounding
  noise (:func:`rideid.estimate.fit.uncertainty.resolve`: ``delta / h^2 sqrt(9/8 + 3/8 sum u^4)``); and the
  parameters rideid reports as not determined (``polish.unresolved``).

The fit then measures each direction not fixed at the Hessian's step again at a larger one
(:func:`rideid.estimate.fit.uncertainty.remeasured`, result.json ``polish.remeasured``); this study is of the Hessian
at its step. Prints one row per parameter. Nothing is changed in rideid; a measurement for docs/uncertainty.md.
"""

from __future__ import annotations

import sys
import tempfile

import numpy as np

from rideid.cli import main
from rideid.estimate.problem.joint import JointProblem
from rideid.estimate.fit.uncertainty import resolve
from rideid.model.batch import single_threaded_blas


def _bread_std(H, res):
    """Each parameter's bread standard error as rideid takes it: the pseudo-inverse on the directions ``res``
    (:func:`rideid.estimate.fit.uncertainty.resolve` of the captured Hessian) keeps."""
    return np.sqrt(np.clip(np.diag(res.pinv(H)), 0, None))


def run(dataset: str) -> None:
    got = []
    orig = JointProblem.hessian

    def capture(self, v, step=1e-3):
        H = orig(self, v, step)
        got.append((self, np.array(v), H))
        return H

    JointProblem.hessian = capture
    with tempfile.TemporaryDirectory() as out:
        assert main(["identify", dataset, "--out", out, "--seed", "1", "--no-report", "--quiet"]) == 0
    JointProblem.hessian = orig
    prob, v, H = got[-1]
    with single_threaded_blas():  # as the fit evaluated its Hessian: the costs' rounding depends on BLAS's threads
        _study(prob, v, H)


def _study(prob, v, H) -> None:
    d = v.size
    h = 1e-3
    delta = prob.rounding(v, h)
    c0 = float(prob.costs(np.clip(v, prob.vbounds[0] + h, prob.vbounds[1] - h)[None])[0])
    rng = np.random.default_rng(1)
    res = resolve(H, delta, h)
    base = _bread_std(H, res)
    ratios = []
    pairs = [(i, j) for i in range(d) for j in range(i)]
    for _ in range(200):  # the stencils of JointProblem.hessian, each cost with its own draw of the rounding
        n0, npl, nmi = rng.standard_normal(), rng.standard_normal(d), rng.standard_normal(d)
        N = np.diag(npl + nmi - 2 * n0) / h ** 2
        for (i, j), q in zip(pairs, rng.standard_normal((len(pairs), 4))):
            N[i, j] = N[j, i] = (q[0] - q[1] - q[2] + q[3]) / (4 * h * h)
        ratios.append(_bread_std(H + 0.5 * delta * N, res))
    steps = {s: _bread_std(prob.hessian(v, s), res) for s in (5e-4, 2e-3)}
    with np.errstate(divide="ignore", invalid="ignore"):  # a direction the pseudo-inverse dropped: nan ratios
        r = np.abs(np.array(ratios) / base - 1)
        steps = {s: b / base for s, b in steps.items()}
    print(f"cost {c0:.6g}, its rounding delta {delta:.3g} ({delta / c0:.2g} of it), d = {d}")
    w, U = np.linalg.eigh(H)
    noise = delta / h ** 2 * np.sqrt(1.125 + 0.375 * np.sum(U ** 4, axis=0))  # resolve's, for every direction
    print("the Hessian's smallest eigenvalues, each against its rounding noise:")
    for k in range(3):
        top = np.argsort(-np.abs(U[:, k]))[:3]
        print(f"  {w[k]:12.4g} (noise {noise[k]:.3g}) along "
              + ", ".join(f"{prob.space.names[i]} {U[i, k]:+.2f}" for i in top))
    nd = res.record(list(prob.space.names))
    print("not determined (polish.unresolved): " + (", ".join(nd["not_determined"]) if nd else "none"))
    print(f"{'parameter':12s} {'bread std':>11s} {'rounding: median':>17s} {'90 %':>7s} {'step 5e-4':>10s} "
          f"{'step 2e-3':>10s}")
    for j, n in enumerate(prob.space.names):
        print(f"{n:12s} {base[j]:11.4g} {100 * np.median(r[:, j]):16.2f}% {100 * np.percentile(r[:, j], 90):6.1f}% "
              f"{100 * (steps[5e-4][j] - 1):+9.1f}% {100 * (steps[2e-3][j] - 1):+9.1f}%")


if __name__ == "__main__":
    run(sys.argv[1])
