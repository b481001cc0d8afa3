"""Estimation: a dataset's problem, the fit that solves it, the model choice over its extensions, and the
assessments of the result.

* :mod:`rideid.estimate.problem` — the problem and its blocks: the cost over the runs (the car's parameters, each
  run's speed and start, a track's size and unevenness, an unknown road, a sensor chain's gains), the track
  weights, the sensitivity maps, the damper-curve and bump-stop groups.
* :mod:`rideid.estimate.fit` — the fit on a problem: the search (JADE), the least-squares polish, the error
  bars (white, robust, jackknife) and the uncertainty budget of declared inputs; the single-model fit and the
  fit with unknown roads.
* :mod:`rideid.estimate.choice` — ``--model auto``: the loop over extensions of one problem.
* :mod:`rideid.estimate.assess` — the assessments of a fit, each a typed record: adequacy, materiality, small
  angles, sensor hints; the responses, frequency responses and scores computed from a result.
* :mod:`rideid.estimate.result` and :mod:`rideid.estimate.records` — the result and its typed records
  (result.json, SPEC §13).
"""
