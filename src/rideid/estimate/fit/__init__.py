"""The fit on a problem: search, polish, error bars.

:mod:`~rideid.estimate.fit.identify` runs the pipeline on a problem with known roads, built up front
(:mod:`rideid.estimate.problem.build`): JADE with adaptive track weights (:mod:`~rideid.estimate.fit.jade`), the
least-squares polish (:mod:`~rideid.estimate.fit.polish`), the error bars
(:mod:`~rideid.estimate.fit.uncertainty`: white, robust HAC, jackknife over runs) and the budget of declared
inputs (:mod:`~rideid.estimate.fit.budget`); :mod:`~rideid.estimate.fit.anyroad` runs it when some runs' roads
are unknown (the roads projected out with the car) or the tracks are taken as built.
"""
