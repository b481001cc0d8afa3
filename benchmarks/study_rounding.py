"""How much a road fit's error bars owe to the cost's rounding: ``python benchmarks/study_rounding.py DATASET``.

A fit with unknown roads or tracks as built (:mod:`rideid.estimate.fit.anyroad`) takes its error bars' bread from
the true Hessian of the cost, by central second differences (``_Problem.hessian``, step 1e-3 in the problem's
coordinates). The cost carries rounding (eigenvectors, the boundary unknowns' damped solve), and a second
difference divides it by the step squared. ``rideid identify DATASET --seed 1`` (defaults) is run with the Hessian
of the kept fit captured; then, at that point:

* the cost's rounding ``delta``: the spread of the cost over eight moves of 1e-9 along fixed directions (the cost
  itself moves by ~1e-18 there: what is left is rounding);
* what it does to each error bar: 200 draws of the noise the Hessian's stencils give that rounding (a diagonal
  entry ``(f+ - 2 f0 + f-) / h^2``: ``sqrt(6) delta / h^2``; a cross term, four costs over ``4 h^2``:
  ``delta / (2 h^2)``; both halved as the Hessian is), each
  parameter's ``sqrt`` of the bread's diagonal (``pinv(H)``, the problem's coordinates) against the captured one:
  the median and the 90th percentile of ``|ratio - 1|``;
* the same bread from the Hessian at steps of 5e-4 and 2e-3 (truncation and rounding together);
* the Hessian's three smallest eigenvalues, the parameters that make up each direction, and the rounding noise
  of an eigenvalue (about a diagonal entry's, ``1.22 delta / h^2``): a direction whose curvature is not above
  it is not fixed by the data.

Prints one row per parameter. Nothing is changed in rideid; a measurement for docs/uncertainty.md.
"""

from __future__ import annotations

import sys
import tempfile

import numpy as np

from rideid.cli import main
from rideid.estimate.fit import anyroad


def _bread_std(H):
    return np.sqrt(np.clip(np.diag(anyroad._pinv(H)), 0, None))


def run(dataset: str) -> None:
    got = []
    orig = anyroad._Problem.hessian

    def capture(self, v, step=1e-3):
        H = orig(self, v, step)
        got.append((self, np.array(v), H))
        return H

    anyroad._Problem.hessian = capture
    with tempfile.TemporaryDirectory() as out:
        assert main(["identify", dataset, "--out", out, "--seed", "1", "--no-report", "--quiet"]) == 0
    anyroad._Problem.hessian = orig
    prob, v, H = got[-1]
    d = v.size
    v = np.clip(v, prob.vbounds[0] + 1e-3, prob.vbounds[1] - 1e-3)
    dirs = np.eye(d)[np.arange(8) % d] * np.where(np.arange(8) % 2, 1.0, -1.0)[:, None]
    c = prob.costs(v + 1e-9 * dirs)
    delta = float(np.std(c))
    h = 1e-3
    rng = np.random.default_rng(1)
    base = _bread_std(H)
    ratios = []
    for _ in range(200):
        N = np.triu(rng.standard_normal((d, d)) * (delta / (2 * h * h)), 1)
        N = N + N.T + np.diag(rng.standard_normal(d) * np.sqrt(6) * delta / (h * h))
        ratios.append(_bread_std(H + 0.5 * N))
    steps = {s: _bread_std(prob.hessian(v, s)) for s in (5e-4, 2e-3)}
    with np.errstate(divide="ignore", invalid="ignore"):  # a direction the pseudo-inverse dropped: nan ratios
        r = np.abs(np.array(ratios) / base - 1)
        steps = {s: b / base for s, b in steps.items()}
    print(f"cost {float(c.mean()):.6g}, its rounding delta {delta:.3g} ({delta / c.mean():.2g} of it), d = {d}")
    w, U = np.linalg.eigh(H)
    print(f"the Hessian's smallest eigenvalues (rounding noise of one: about {1.22 * delta / h ** 2:.3g}):")
    for k in range(3):
        top = np.argsort(-np.abs(U[:, k]))[:3]
        print(f"  {w[k]:12.4g} along " + ", ".join(f"{prob.space.names[i]} {U[i, k]:+.2f}" for i in top))
    print(f"{'parameter':12s} {'bread std':>11s} {'rounding: median':>17s} {'90 %':>7s} {'step 5e-4':>10s} "
          f"{'step 2e-3':>10s}")
    for j, n in enumerate(prob.space.names):
        print(f"{n:12s} {base[j]:11.4g} {100 * np.median(r[:, j]):16.2f}% {100 * np.percentile(r[:, j], 90):6.1f}% "
              f"{100 * (steps[5e-4][j] - 1):+9.1f}% {100 * (steps[2e-3][j] - 1):+9.1f}%")


if __name__ == "__main__":
    run(sys.argv[1])
