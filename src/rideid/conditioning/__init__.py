"""Conditioning: what loading a dataset does once its files are read, with the model.

Between the data layer (:mod:`rideid.data`: schemas, readers, the Dataset; no
simulation) and the estimation: :mod:`.starts` (the start of every measured
run, by correlation with a car's response), :mod:`.checks` (wiring, units and
track checks against a nominal car), :mod:`.load` (:func:`load_dataset`, the
orchestrator).
"""
