"""Conditioning: what loading a dataset does once its files are read, with the model.

Between the data layer (:mod:`rideid.data`: schemas, readers, the Dataset; no
simulation) and the estimation: :mod:`.starts` (the start of every measured
run, by correlation with a car's response), :mod:`.checks` (coverage, wiring,
units and track checks against a nominal car), :mod:`.wiring` (the wiring and
unit checks' pure math: rigid-body identities, assignment to the road),
:mod:`.nominal` (the one place that simulates: the nominal car's responses the
starts and the checks ask for, a round at a time in one batch), :mod:`.load`
(:func:`load_dataset`, the orchestrator: read, then align and check).
"""
