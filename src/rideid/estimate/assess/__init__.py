"""The assessments of a fit, and what is computed from a result.

Each assessment returns a typed record (:mod:`rideid.estimate.records`): the adequacy test of the residuals
(:mod:`~rideid.estimate.assess.adequacy`), whether their structure matters
(:mod:`~rideid.estimate.assess.materiality`), the small-angle check (:mod:`~rideid.estimate.assess.small_angle`),
what the sensor chain may have done (:mod:`~rideid.estimate.assess.sensor_check`), the runs on unknown roads by
their residual at their own road estimate (:mod:`~rideid.estimate.assess.roads`), each estimate's entry with
what the data did not measure and the bound check (:mod:`~rideid.estimate.assess.details`). From a result: the car's
responses on the runs (:mod:`~rideid.estimate.assess.responses`), its frequency responses with their uncertainty
(:mod:`~rideid.estimate.assess.frequency`) and the score against a known truth
(:mod:`~rideid.estimate.assess.score`). What the data say of each run's set-up values against their priors (its
speed, start, track size; SPEC §13): :mod:`~rideid.estimate.assess.motion`.
"""
