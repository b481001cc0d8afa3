"""``--model auto``: the model choice as a loop over extensions of one problem.

:mod:`~rideid.estimate.choice.model_choice` fits the base problem, extends it by one group at a time (anti-roll
bars, tire damping, a powertrain, damper curves, bump stops), weighs each extension against the choice so far on
its criterion and Wald statistic, weighs the linear groups again when a nonlinear one comes in, and hands the
kept model to the assessments. :mod:`~rideid.estimate.choice.first_fit` owns what follows a first fit that misses
grossly: the extension the data call for most, fitted before the choice stops (on the tracks as built when the
drawing is off as well).
"""
