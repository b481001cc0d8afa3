"""The problem and its blocks: what a dataset asks the fit to solve.

:func:`~rideid.estimate.problem.build.build_problem` builds it up front from the dataset and the fit's options
(a frozen :class:`~rideid.estimate.problem.build.Problem`: the model fitted, the model searched, where the
nonlinear groups start, the runs whose start is estimated, the settings; its plan is result.json's ``plan``).

:class:`~rideid.estimate.problem.cost.CostFunction` is the problem: the residual blocks of the runs, the free
parameters' space (:class:`~rideid.estimate.problem.cost.ParameterSpace`) with bounds, and the nuisance unknowns
each block owns — a run's speed and start under their priors, a track's size and unevenness
(:mod:`~rideid.estimate.problem.asbuilt`), an unknown road projected out frequency by frequency
(:mod:`~rideid.estimate.problem.roadfit`, with the time-domain alternative
:mod:`~rideid.estimate.problem.roadstaged`), a sensor chain's relative gains
(:mod:`~rideid.estimate.problem.redundancy`). The fit with unknown roads or tracks as built takes its problem as
blocks of one interface (:mod:`~rideid.estimate.problem.blocks`: the runs as drawn, an unknown road, a track as
built with the run's speed and start, placed and then solved with the car), joined by
:class:`~rideid.estimate.problem.joint.JointProblem` (the stacked residuals, the costs of many cars at once, the
Jacobian, the cost's true Hessian and its rounding). The nonlinear groups' blocks (damper
curves' knots, :mod:`~rideid.estimate.problem.dampers`; bump stops, :mod:`~rideid.estimate.problem.bumps`), the
track weights of the search (:mod:`~rideid.estimate.problem.weighting`), the score series each block's share of
the error bars is made of (:mod:`~rideid.estimate.problem.scores`) and the sensitivity maps
(:mod:`~rideid.estimate.problem.sensitivity`) live here too. Nothing here searches or decides: the fit does.
"""
