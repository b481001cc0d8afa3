"""One registry of every tuning constant: its value, unit, meaning, measured reason and the test that pins it.

Modelled on python-control's ``control.config.defaults``: each constant of
:mod:`rideid.estimate` (and of :mod:`rideid.conditioning` where it shapes a
verdict) that a study may want to vary is a :class:`Setting` named
``"module.param"`` (``"adequacy.alpha"``). The code reads the value at use
time from :data:`defaults`, so a change applies to the next fit:

>>> import rideid.settings as settings
>>> settings.defaults["adequacy.alpha"]
0.01
>>> with settings.using({"adequacy.alpha": 0.05}):
...     pass                                  # rideid.identify(ds) here uses 0.05
>>> settings.set_defaults("adequacy", alpha=0.05)   # until reset_defaults()
>>> settings.reset_defaults()

A dataset sets them in a ``[settings]`` table of ``dataset.toml``
(``"adequacy.alpha" = 0.05``), applied while :func:`rideid.identify` fits it;
``result.json`` records every value used (``settings``). Unknown names and
values of the wrong kind are errors (:class:`rideid.errors.ArgumentError`).
The table of every setting is docs/settings.md.

The registry is process-wide, as python-control's: a value set in one
thread is seen by the others (the model choice fits candidates on threads,
all with the values in force when the fit began). This module imports
nothing of rideid but its errors, so every layer may read it.
"""

from __future__ import annotations

import contextlib
import difflib
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from .errors import ArgumentError


@dataclass(frozen=True)
class Setting:
    """One tuning constant.

    Attributes
    ----------
    name : str
        ``"module.param"``: the module of :mod:`rideid.estimate` or :mod:`rideid.conditioning` that reads it.
    default : int, float or tuple of them
        The value rideid ships with.
    unit : str
        SI unit, ``"1"`` for a ratio (with what it is a share of in brackets), or a count's noun.
    meaning : str
        What the value does.
    reason : str
        The doc that gives its reason, ``docs/<file>.md#<anchor>``.
    test : str
        The test that pins it, ``tests/<file>.py::<test>``.
    measured : bool
        Whether the value was chosen by a measurement the meaning, the note or the doc states (False: a
        convention or a numerical safeguard, said so in docs/settings.md).
    note : str
        The measurement or the longer story behind the value.
    """

    name: str
    default: object
    unit: str
    meaning: str
    reason: str
    test: str
    measured: bool = False
    note: str = ""


#: every setting, grouped by the module that reads it (docs/settings.md is this list as a table)
_SETTINGS: tuple[Setting, ...] = (
    Setting('adequacy.lags', (0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32), 'samples',
            'lags (samples) of the road inputs and rates regressed on the residual',
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_input_correlation_finds_a_filtered_road',
            measured=False),
    Setting('adequacy.alpha', 0.01, '1 (probability)',
            'family-wise false-alarm rate of the input-correlation tests over all runs and channels',
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_input_correlation_is_calibrated_under_coloured_noise',
            measured=False),
    Setting('adequacy.min_explained', 0.05, '1 (share of variance)',
            'share of the whitened residual variance the road must explain to count as structure',
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_verdict_counts_structure_only_when_material',
            measured=False),
    Setting('adequacy.loud_share', 0.25, '1 (share of run/channel pairs)',
            ('the least share of run/channel pairs (those with a quiet lead-in) whose residual is above 3x the '
             "lead-in's noise floor for an adequate verdict to carry adequacy.level_caveat. Measured on the MuJoCo "
             "cars of docs/verification.md: every right model 2 of 100 (the washboard runs' roll rates, whose lead-in"
             ' floor is about zero); the base model forced on the car with anti-roll bars, 6 % off and called '
             'adequate when its washboard runs were taken as drawn and the rest as built (an intermediate version of '
             'the as-built rules), 52 of 100'),
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_the_level_caveat_needs_an_adequate_verdict_and_many_loud_pairs',
            measured=True),
    Setting('adequacy.min_relative', 0.005, "1 (share of the channel's RMS)",
            ("road-explained residual RMS, as a share of the channel's RMS, below which structure is immaterial "
             '(below the accuracy of any accelerometer or gyro)'),
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_verdict_counts_structure_only_when_material',
            measured=False),
    Setting('adequacy.ar_max', 10, '1 (AR order)',
            'highest AR order of the prewhitening filter',
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_ljung_box_and_ar_fit',
            measured=False),
    Setting('adequacy.whiteness_lags', 25, 'samples',
            "lags of the whiteness test (MATLAB resid's default)",
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_ljung_box_and_ar_fit',
            measured=False),
    Setting('adequacy.min_quiet', 20, 'samples',
            'fewest quiet lead-in samples for a noise floor',
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_adequacy.py::test_the_level_caveat_needs_an_adequate_verdict_and_many_loud_pairs',
            measured=False),
    Setting('anyroad.speed_tolerance', 0.02, '1 (share of the mean speed)',
            "an unknown-road run's speed may vary by this fraction of its mean (the delay is taken as constant)",
            'docs/any-road.md#what-a-road-run-needs',
            'tests/test_anyroad.py::test_an_unknown_road_needs_a_steady_speed',
            measured=False),
    Setting('anyroad.held_speed', 0.005, '1 (share of the mean speed)',
            ('a run on a declared track with a speed or distance channel is fitted as built when the driver held the '
             "speed: the channel's wander about its mean over the run's window (its spread less the channel's white "
             "noise, anyroad.speed_wander) at most this share of the mean (the rear wheels' delay is taken as "
             'constant; a +-3 % driver wanders 1.5 % RMS)'),
            'docs/tracks-as-built.md#along-a-speed-channel-a-clipped-channel',
            'tests/test_asbuilt_speed.py::test_a_held_speed_is_fitted_as_built_and_a_wandering_one_is_not',
            measured=True),
    Setting('anyroad.plausible_factor', 0.1, '1 (relative)',
            ("what a track as built may depart from its drawing before the verdict says the road explains the model's"
             " misses: the amplitude factor's distance from 1, and the unevenness RMS (m, one wheel path; SPEC §11: a"
             " few per cent and 1-2 mm, plus what the disc's envelope adds on sharp features: 2.6 mm measured on a "
             'washboard laid with 1.5 mm)'),
            'docs/tracks-as-built.md#resultjson',
            'tests/test_tracks_asbuilt.py::test_rideid_identify_on_tracks_as_built_and_exact',
            measured=True,
            note=("The factor's limit widens by twice its standard error (``amplitude_factor_std``): a track of one "
                  'spectral line (a washboard) whose bins the prior opened leaves its factor ill-determined (1.139 +-'
                  ' 0.038 on the all-realities case, where the envelope of the 4 % taller washboard is 4.0 % taller)')),
    Setting('anyroad.plausible_rms', 0.0035, 'm',
            ('the largest unevenness RMS (one wheel path) of a track as built before the verdict says the road '
             "explains the model's misses (with anyroad.plausible_factor)"),
            'docs/tracks-as-built.md#resultjson',
            'tests/test_tracks_asbuilt.py::test_rideid_identify_on_tracks_as_built_and_exact',
            measured=True),
    Setting('anyroad.plausible_wavelength', 10.0, 'm',
            ("the unevenness judged over the waves up to this long (m): a track's surface (SPEC §11's 1-2 mm; the "
             "tests' 0.5-10 m), not its grade and cross-fall; there the slowest bins of the fit band (0.2-1 Hz at 10 "
             'm/s, 10-50 m waves), which the accelerations barely see, are where the prior opens on noise: on the '
             "all-realities case the herringbone's 3.0-3.7 mm was 1.7 mm without its opened bins at 0.3 and 0.6 Hz"),
            'docs/tracks-as-built.md#resultjson',
            'tests/test_tracks_asbuilt.py::test_rideid_identify_on_tracks_as_built_and_exact',
            measured=True),
    Setting('anyroad.spread_tol', 0.2, '1 (coefficient of variation)',
            "the search's population-spread stop (as the track search with a polish)",
            'docs/any-road.md#how-it-works',
            'tests/test_anyroad.py::test_the_car_from_two_unknown_roads',
            measured=False),
    Setting('adequacy.gross_error', 0.3, '1 (share of a run\'s signal)',
            ('a first fit leaving more than this share of any run\'s signal unexplained misses grossly: the model '
             'choice is not run and the set-up is named first'),
            'docs/model-choice.md#a-gross-first-fit-the-set-up-first',
            'tests/test_priors.py::test_a_gross_first_fit_stops_before_the_model_choice_with_the_set_up_first',
            measured=True,
            note=('linear dampers on 2:1 digressive ones leave 0.096, the largest misfit an extension mends in the '
                  'project\'s cases; a 1 % speed slip on the SUV\'s herringbone 0.23 of the dataset\'s')),
    Setting('adequacy.gross_bounds', 3, 'parameters',
            ('a first fit ending with this many free parameters at their search bounds misses grossly (the bounds, '
             'not the data, decided them)'),
            'docs/model-choice.md#a-gross-first-fit-the-set-up-first',
            'tests/test_priors.py::test_a_gross_first_fit_stops_before_the_model_choice_with_the_set_up_first',
            measured=False),
    Setting('anyroad.motion_named', 3.0, 'prior std',
            ('a run\'s speed, start or track size estimated this many of its prior\'s std from the declared value '
             'is named with the run and the value the data show (SPEC §13)'),
            'docs/tracks-as-built.md#every-runs-speed-and-start-with-their-priors-spec-13',
            'tests/test_priors.py::test_a_motion_record_names_a_value_beyond_three_prior_std',
            measured=False),
    Setting('anyroad.joint_motion_bound', 30.0, 'asbuilt.motion_scale units',
            ("the joint solve's speed and start unknowns (asbuilt.motion_scale units): their bounds either side of "
             'the placement they start from, and their finite-difference steps (asbuilt.motion_jacobian_steps)'),
            'docs/tracks-as-built.md#along-a-speed-channel-a-clipped-channel',
            'tests/test_asbuilt_speed.py::test_the_speed_and_the_start_are_fitted_to_the_track',
            measured=False),
    Setting('asbuilt.smooth_bins', 5, 'DFT bins',
            'the unevenness power is averaged over this many bins either side (and both wheel paths)',
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_tracks_asbuilt.py::test_the_unevenness_found',
            measured=False),
    Setting('asbuilt.open_factor', 4.0, '1 (times the unevenness background)',
            ('a bin whose deviation from the drawing exceeds this many times the unevenness background gets its own '
             'variance'),
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_tracks_asbuilt.py::test_the_unevenness_found',
            measured=False),
    Setting('asbuilt.prior_floor', 0.001, '1 (share of the noise power)',
            ('the unevenness variance is at least this share of what the sensor noise puts into the free road '
             'estimate'),
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_tracks_asbuilt.py::test_the_unevenness_found',
            measured=False),
    Setting('asbuilt.normal_ridge', 1e-12, '1 (on a unit diagonal)',
            "the diagonal load of the boundary unknowns' normal equations (unit diagonal; asbuilt._normal_solve)",
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_tracks_asbuilt.py::test_the_car_on_tracks_as_built_from_a_start',
            measured=False),
    Setting('asbuilt.cluster_bins', 1, 'DFT bins',
            "neighbouring DFT bins per cluster of the error bars' sandwich (asbuilt.meat)",
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_tracks_asbuilt.py::test_rideid_identify_on_tracks_as_built_and_exact',
            measured=False),
    Setting('asbuilt.noise_bins', 10, 'DFT bins',
            'the sensor-noise power per bin is averaged over this many bins either side',
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_tracks_asbuilt.py::test_the_unevenness_found',
            measured=False),
    Setting('roads.max_share', 0.03, "1 (share of the channel's RMS)",
            ("a road run's channel whose residual at its own road estimate is above this share of the channel's RMS "
             "is off: a right car leaves the noise's fit-band share (0.45 % at 1 % noise, 0.8-1.0 % at 2 %)"),
            'docs/any-road.md#is-the-car-adequate-on-an-unknown-road',
            'tests/test_road_verdict.py::test_the_road_runs_verdict_on_a_right_and_a_wrong_car',
            note=("measured: the van with real dampers fitted with linear ones (../shared/cases/van-roads-dampers, "
                  "c_sf -16 %) 2.5-12 % on its three roads (every acceleration 9-12 %); the built-in car on a B road "
                  "with a twist run, 1 % noise, the right model, 0.42-0.47 %; a run fails at adequacy.loud_share of "
                  "its channels off")),
    Setting('asbuilt.boundary_share', 1e9, "1 (times the drawing's road power)",
            ("a run whose free-road fit puts more than this many times the drawn road's power into the road estimate "
             "through its boundary unknowns (the start's state, the rear lead-in) cannot tell unevenness from them: "
             "its unevenness is held at the prior's floor, said in result.json, and not judged. Off by default (1e9): "
             "a car missing its anti-roll bars put 4.1e4-7.4e5 there on the washboard, as much as the right car's "
             "short washboard run, and holding those runs hid the only evidence that rejected the tracks as built "
             "(the base model then adequate, k_sf 2.6 % off instead of the verdict 'not adequate'); 10 holds a short "
             "washboard run of a right car whose fake unevenness rejects the tracks"),
            'docs/tracks-as-built.md#limits-said-plainly',
            'tests/test_tracks_asbuilt.py::test_a_short_washboard_run_holds_its_unevenness_at_the_prior',
            note=("measured at the true SUV, exact drawings, 1 % noise, seeds 1-3 (tests/asbuilt_tracks.py): the "
                  "washboard's 3.1 s at 10 m/s 1.2e3-5.4e5 (the fake 19-399 mm RMS); the twist, the herringbone, a "
                  "6 s washboard and the washboard with 1.5 mm unevenness 2e-4 to 0.83; the SUV without its bars "
                  "fitted with the base model (tests/cars.py, seed 50): the washboard runs 4.1e4 and 7.4e5")),
    Setting('asbuilt.motion_scale', (0.001, 0.001), '1 (relative speed), s (start)',
            ("blocks.TrackBlock.aligned's unknowns: the speed's relative change and the start's shift (s), in these "
             "units"),
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_asbuilt_speed.py::test_the_speed_and_the_start_are_fitted_to_the_track',
            measured=False),
    Setting('asbuilt.motion_steps', (0.5, 2.0), 'asbuilt.motion_scale units',
            "the first steps of blocks.TrackBlock.aligned's Nelder-Mead simplex (asbuilt.motion_scale units)",
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_asbuilt_speed.py::test_the_speed_and_the_start_are_fitted_to_the_track',
            measured=False),
    Setting('asbuilt.motion_xtol', 0.01, 'asbuilt.motion_scale units',
            "the tolerance of TrackBlock.aligned's Nelder-Mead simplex",
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_asbuilt_speed.py::test_the_speed_and_the_start_are_fitted_to_the_track',
            measured=False),
    Setting('asbuilt.motion_maxfev', 120, 'evaluations',
            "TrackBlock.aligned's Nelder-Mead evaluations at most",
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_asbuilt_speed.py::test_the_speed_and_the_start_are_fitted_to_the_track',
            measured=False),
    Setting('asbuilt.motion_jacobian_steps', (0.1, 0.2), 'asbuilt.motion_scale units',
            ("blocks.TrackBlock.motion_jacobian's central-difference steps (asbuilt.motion_scale units: 1e-4 of the "
             "speed, 0.2 ms): about the speed's and the start's standard errors on the all-realities case "
             '(docs/tracks-as-built.md)'),
            'docs/tracks-as-built.md#the-model-rideidestimateproblemasbuiltpy',
            'tests/test_asbuilt_speed.py::test_the_speed_and_the_start_are_fitted_to_the_track',
            measured=True),
    Setting('budget.at_bound', 1e-09, '1 (share of the bound range)',
            'a variable this close (bound-normalised) to a search bound is held there by the polish, and here',
            'docs/uncertainty.md#how-it-is-propagated-rideidestimatefitbudgetpy',
            'tests/test_budget.py::test_sensitivities_agree_with_refits_with_the_input_moved',
            measured=False),
    Setting('budget.jacobian_step', 1e-07, '1 (share of the bound range)',
            "forward-difference step of the residual Jacobian (bound-normalised, as the polish's)",
            'docs/uncertainty.md#how-it-is-propagated-rideidestimatefitbudgetpy',
            'tests/test_budget.py::test_sensitivities_agree_with_refits_with_the_input_moved',
            measured=False),
    Setting('budget.input_step', 0.1, '1 (share of the declared std)',
            'central-difference step of a known or geometric input, as a fraction of its declared std',
            'docs/uncertainty.md#how-it-is-propagated-rideidestimatefitbudgetpy',
            'tests/test_budget.py::test_sensitivities_agree_with_refits_with_the_input_moved',
            measured=False),
    Setting('bumps.min_samples', 20, 'samples',
            'samples (both corners of the axle, all runs) beyond the clearance that make a stop reached',
            'docs/dampers.md#identifying-bump-stops---model-bump_stops',
            'tests/test_bump_stops.py::test_stops_never_reached',
            measured=False),
    Setting('bumps.scan_counts', (20, 40, 80, 160, 320, 640, 1280), 'samples',
            'scan: candidate clearances are the compressions exceeded by these many samples',
            'docs/dampers.md#identifying-bump-stops---model-bump_stops',
            'tests/test_bump_stops.py::test_bump_stops_are_recovered',
            measured=False),
    Setting('bumps.scan_rates', (10000.0, 30000.0, 100000.0, 300000.0), 'N/m',
            'scan: candidate rates (N/m)',
            'docs/dampers.md#identifying-bump-stops---model-bump_stops',
            'tests/test_bump_stops.py::test_bump_stops_are_recovered',
            measured=False),
    Setting('bumps.min_gain', 0.01, '1 (share of the cost)',
            ("an axle's best scan candidate must lower the equal-weight cost by this share to start a stop, or by "
             "adequacy.min_relative squared absolutely (the adequacy verdict's materiality floor), for a car whose "
             "cost other misfits dominate (a stop then gains less than 1 % of it)"),
            'docs/dampers.md#identifying-bump-stops---model-bump_stops',
            'tests/test_bump_stops.py::test_bump_stops_are_recovered',
            measured=False),
    Setting('bumps.unreached_factor', 1.25, '1 (times the largest compression)',
            'an unreached stop is held at this multiple of the largest compression reached',
            'docs/dampers.md#identifying-bump-stops---model-bump_stops',
            'tests/test_bump_stops.py::test_stops_never_reached',
            measured=False),
    Setting('bumps.state_rho', 0.2, '1 (sub-step bound)',
            "the sub-step bound of the compression simulations (as the report's velocity histograms)",
            'docs/dampers.md#identifying-bump-stops---model-bump_stops',
            'tests/test_bump_stops.py::test_bump_stops_are_recovered',
            measured=False),
    Setting('cost.energy_floor', 0.01, '1 (share of the mean channel energy)',
            ("a channel's energy normaliser is at least this share of the largest energy among the present channels "
             'of its kind (a nearly silent channel does not dominate the cost)'),
            'docs/method.md#4-cost-rideidestimateproblemcostpy',
            'tests/test_identify.py::test_channel_normalisation',
            measured=False),
    Setting('cost.knot_bound_factor', (3.0, 2.0), '1 (factors on the c_s bounds)',
            ("default bounds of a knot force ``F(v)``: the axle's ``c_s`` bounds times ``|v|``, the lower one divided"
             " by the first factor (a digressive damper's high-speed force lies far below ``c_min v``), the upper one"
             ' times the second (a progressive or bleed-stiff low-speed force above ``c_max v``); ``F`` has the sign '
             'of ``v``. Wider upper bounds buy nothing but stiffer search candidates (more RK4 sub-steps).'),
            'docs/dampers.md#what-a-damper-curve-costs-issue-37',
            'tests/test_damper_curves.py::test_digressive_asymmetric_curves_are_recovered',
            measured=False),
    Setting('cost.mean_slope_velocity', 0.1, 'm/s',
            "the velocity (m/s) of the derived ``c_sf``, ``c_sr``: the curve's mean slope over ``[-V, V]``",
            'docs/dampers.md#datasets-model',
            'tests/test_damper_curves.py::test_digressive_asymmetric_curves_are_recovered',
            measured=False),
    Setting('dampers.min_samples', 20, 'samples',
            'samples (both corners of the axle, all runs) beyond the previous knot that make a knot excited',
            'docs/dampers.md#where-the-curves-bend-knees-found-by-the-data',
            'tests/test_knees.py::test_knees_leave_out_knots_not_excited',
            measured=False),
    Setting('dampers.knee_grid', (0.025, 0.05, 0.075, 0.1, 0.125, 0.15, 0.175, 0.2, 0.3, 0.4), 'm/s',
            ('the positive knots (m/s) of the curves fitted without ``[model] damper_knots``, mirrored into rebound: '
             "0.025 m/s apart to 0.2 m/s, then 0.3 and the default knots' 0.4; every default knot is one of them"),
            'docs/dampers.md#where-the-curves-bend-knees-found-by-the-data',
            'tests/test_knees.py::test_the_grid_replaces_the_default_knots_unless_the_user_sets_knots',
            measured=False),
    Setting('dampers.knee_draws', 400, 'draws',
            "draws of the knot forces (robust covariance) behind a knee's standard error",
            'docs/dampers.md#where-the-curves-bend-knees-found-by-the-data',
            'tests/test_knees.py::test_knee_std_robust_agrees_with_the_delta_method',
            measured=False),
    Setting('dampers.knee_seed', 20260, '1 (seed)',
            "seed of the knot-force draws behind a knee's standard error (deterministic)",
            'docs/dampers.md#where-the-curves-bend-knees-found-by-the-data',
            'tests/test_knees.py::test_knee_std_robust_agrees_with_the_delta_method',
            measured=False),
    Setting('dampers.knee_significance', 3.0, 'std_robust',
            'a side bends when its slope ratio above/below the knee differs from 1 by more than this many std_robust',
            'docs/dampers.md#where-the-curves-bend-knees-found-by-the-data',
            'tests/test_knees.py::test_a_curve_that_bends_in_stages_lists_each_bend',
            measured=False),
    Setting('dampers.bend_share', 0.1, '1 (share of the steepest slope)',
            ("a knot is a bend when its slope change exceeds this share of the side's steepest slope (and "
             "dampers.knee_significance std_robust) and no neighbour's is larger"),
            'docs/dampers.md#where-the-curves-bend-knees-found-by-the-data',
            'tests/test_knees.py::test_a_curve_that_bends_in_stages_lists_each_bend',
            measured=False),
    Setting('identify.spread_tol', 0.2, '1 (coefficient of variation)',
            "JADE's early stop before the polish: every free parameter's spread below this share",
            'docs/method.md#8-jade-rideidestimatefitjadepy',
            'tests/test_identify.py::test_noise_free_identification_within_0p1_percent',
            measured=True,
            note=("The polish only needs the optimum's basin: on five problems (the built-in car noise-free and at 2 "
                  '%, an SUV with AR(1) noise, the SUV with bars and tire damping fitted with the full model, a van),'
                  ' two seeds each, every setting from (64, 0.02) to (24, 0.3) ends within 1e-5 standard errors of '
                  'the same estimate; (32, 0.2) takes 0.3 of the evaluations of the former (64, 0.1) and 0.16 of (64,'
                  ' 0.02) (benchmarks/bench_search.py)')),
    Setting('identify.spread_tol_no_polish', 1e-05, '1 (coefficient of variation)',
            "JADE's early stop without a polish: JADE itself must converge, so a much tighter stop",
            'docs/method.md#8-jade-rideidestimatefitjadepy',
            'tests/test_identify.py::test_callback_stops_identify',
            measured=False),
    Setting('identify.zero_scale', 1.0, '1 (share of the range)',
            ('a parameter whose search range starts at 0 (an extension) may truly be 0, where its coefficient of '
             'variation never settles: its spread is judged against this share of its range instead (the polish '
             'finishes it: the cost is smooth and nearly quadratic in the extensions; measured on the built-in car, '
             "0.05 doubled the full model's generations)"),
            'docs/method.md#8-jade-rideidestimatefitjadepy',
            'tests/test_identify.py::test_noise_free_identification_within_0p1_percent',
            measured=True),
    Setting('identify.restart_at_bound', 1e-06, '1 (share of the range)',
            ('a free parameter this close to a search bound (as a share of its range) is at it, for '
             'identify.mode_restart'),
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_realities.py::test_an_engine_mode_left_at_its_bounds_is_started_again',
            measured=False),
    Setting('identify.repair_restarts', 2, 'polishes',
            ('a polish ending on a damper-curve row the monotone repair changes is solved again from the repaired row'
             ' at most this often (fit.polish._polish: logger files of the SUV at 100 Hz ended with a front knot force '
             "57 % off, hidden below its neighbour, at a cost 1e6 times the true car's; solved again, within 0.01 %)"),
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_paths.py::test_polish_leaves_a_knot_hidden_by_the_monotone_repair',
            measured=True),
    Setting('identify.polish_max_nfev', 100, 'evaluations',
            ("the polish's least-squares evaluations in all (on the built-in car, SUVs, vans and damper curves it "
             'converges in 6-20, a base model on a car with bars in 30; fit.polish._Polish.solve)'),
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_identify.py::test_the_polish_does_not_stop_beside_a_bound',
            measured=True),
    Setting('identify.dogbox_max_nfev', 30, 'evaluations',
            "dogbox's share of the polish's evaluations (see identify.polish_max_nfev)",
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_identify.py::test_the_polish_does_not_stop_beside_a_bound',
            measured=True),
    Setting('identify.bound_snap', 1e-09, '1 (share of the range)',
            ('a variable this share of its range from a bound (bound-normalised) is on it (see '
             'identify.polish_max_nfev)'),
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_identify.py::test_the_polish_does_not_stop_beside_a_bound',
            measured=False),
    Setting('identify.warp_bound', 0.5, 'm',
            ("a distance correction's knots stay within this many metres of the speed channel's integral in one "
             'polish'),
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_identify.py::test_a_distance_warp_is_a_random_walk_anchored_at_the_start',
            measured=False),
    Setting('identify.stall_optimality', 1e-08, '1 (normalised gradient)',
            ("dogbox's first-order optimality (the largest gradient component of the free variables, "
             'bound-normalised; the cost is a normalised mean square) above which an end beside a bound is a stall, '
             'not convergence: converged polishes end at 1e-13 (noise-free) to 1e-11, the stall on damper-van-logger '
             'at 7e-3'),
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_identify.py::test_the_polish_does_not_stop_beside_a_bound',
            measured=True),
    Setting('identify.realign_tol', 0.001, '1 (share of a sample interval)',
            're-estimate the starts until none moves by more than this fraction of a sample interval',
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_checks.py::test_recorded_cost_is_at_the_final_parameters_and_starts',
            measured=False),
    Setting('identify.realign_max', 8, 'rounds',
            'at most this many rounds of re-estimating the starts (identify.realign_tol)',
            'docs/method.md#9-polish-and-standard-errors-rideidestimatefitidentifypy',
            'tests/test_checks.py::test_recorded_cost_is_at_the_final_parameters_and_starts',
            measured=False),
    Setting('materiality.material_shift', 1.0, 'std_total',
            "the largest shift (in std_total) the flagged pairs' structure may cause for the model to stay adequate",
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_materiality.py::test_weigh_measures_the_shift_in_std_total_and_decides',
            measured=False),
    Setting('materiality.max_share', 0.5, '1 (share of run/channel pairs)',
            'structure in more than this share of the pairs is not weighed: the model misses something everywhere',
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_materiality.py::test_weigh_measures_the_shift_in_std_total_and_decides',
            measured=False),
    Setting('model_choice.penalty_level', 0.001, '1 (probability)',
            ('the false-alarm probability at which a group of two extension parameters enters the model: the '
             "criterion's price per free parameter is half the (1 - level) point of chi-square(2)"),
            'docs/model-choice.md#the-criterion-a-robust-wald-information-criterion',
            'tests/test_model_choice.py::test_wald_and_criterion_closed_form',
            measured=False),
    Setting('model_choice.drawing_runs', 2, 'runs',
            ('the flagged pairs must span at least this many runs for the tracks-as-drawn caveat '
             '(model_choice._drawing_caveat)'),
            'docs/model-choice.md#adequacy-resultjson-adequacy',
            'tests/test_model_choice.py::test_the_tracks_as_drawn_caveat_says_when_the_weighing_cannot_clear_a_drawing',
            measured=True),
    Setting('redundancy.flag_sigma', 3.0, 'standard errors',
            ('a body sensor whose relative gain departs from 1 by more than this many of its standard errors and by '
             "more than twice its declared sensitivity_std (1 % when none is declared) is named in the result's notes"),
            'docs/uncertainty.md#what-the-data-tell-of-the-sensors-themselves-rigid-body-redundancy',
            'tests/test_budget.py::test_rigid_body_redundancy_finds_relative_gains_but_not_the_common_one',
            measured=False),
    Setting('redundancy.flag_undeclared', 0.01, '1 (relative gain)',
            ('twice the declared sensitivity_std a body sensor without one is taken to have, in the rule of '
             'redundancy.flag_sigma'),
            'docs/uncertainty.md#what-the-data-tell-of-the-sensors-themselves-rigid-body-redundancy',
            'tests/test_budget.py::test_rigid_body_redundancy_finds_relative_gains_but_not_the_common_one',
            measured=False),
    Setting('roadfit.band', (0.2, 25.0), 'Hz',
            ('the fit band (Hz): below, the accelerations carry little of the road; above, the road between samples '
             "(module docstring) and the logger's anti-alias filter take over"),
            'docs/any-road.md#how-it-works',
            'tests/test_roadfit.py::test_noise_free_recovery_and_the_road',
            measured=False),
    Setting('roadfit.delay_order', 8, '1 (filter order)',
            "order of the Lagrange filter of the rear wheels' fractional delay",
            'docs/any-road.md#how-it-works',
            'tests/test_roadfit.py::test_delay_filter_is_exact_on_polynomials',
            measured=False),
    Setting('roadfit.road_wavelengths', (0.5, 20.0), 'm',
            "the reconstructed road's wavelength band (m), SPEC §9 and issue 26's acceptance band",
            'docs/any-road.md#how-it-works',
            'tests/test_anyroad.py::test_the_roads_and_their_classes',
            measured=False),
    Setting('roadfit.search_bins', 400, 'DFT bins',
            "the search's cost uses about this many bins of the fit band (every n-th bin of a Hann-windowed DFT)",
            'docs/any-road.md#how-it-works',
            'tests/test_roadfit.py::test_search_costs_on_thread_slices_equal_one_batch',
            measured=False),
    Setting('roadfit.clip_share', 0.5, '1 (share of in-band values)',
            ('a clipped channel whose samples at the range exceed this share of its in-band real values (2 per fit '
             "bin) is left out of the run's road fit whole; below it each clipped sample is one free unknown (module "
             'docstring)'),
            'docs/any-road.md#clipped-samples-spec-11',
            'tests/test_roadfit.py::test_clipped_samples_are_freed_in_the_road_fit',
            measured=False),
    Setting('roadfit.clip_max', 200, 'samples',
            ("every clipped channel of a run with more than this many clipped samples is left out of the run's road "
             "fit (the solve's cost grows with their square)"),
            'docs/any-road.md#clipped-samples-spec-11',
            'tests/test_roadfit.py::test_clipped_samples_are_freed_in_the_road_fit',
            measured=False),
    Setting('roadfit.signal_floor', 1e-06, '1 (share of the largest RMS)',
            ("a channel whose RMS (about its mean) is below this share of the largest RMS among the run's channels of"
             ' the same kind (body, axle, rate) carries rounding or a dead sensor, not the car: the fit, which '
             'weights each channel by 1 / its RMS, leaves it out (a roll rate on a washboard: 1e-19 against 1e-2 '
             'rad/s)'),
            'docs/any-road.md#how-it-works',
            'tests/test_anyroad.py::test_a_channel_the_road_run_does_not_excite_is_left_out_with_a_note',
            measured=True),
    Setting('roadfit.modal_cond', 100000000.0, '1 (condition number)',
            'eigenvector matrices worse conditioned than this use the direct solves instead of the modal form',
            'docs/any-road.md#how-it-works',
            'tests/test_sensors.py::test_modal_form_matches_the_state_space_response',
            measured=False),
    Setting('score.coverage_k', 2.0, 'std_total',
            ('an estimate covers the truth when it lies within this many standard errors (about 95 %, SPEC §6): '
             '``std_total`` (SPEC §12: std_robust with every declared uncertainty), ``std_robust`` in results written'
             ' before it'),
            'docs/uncertainty.md#checks-teststest_uncertaintypy',
            'tests/test_budget.py::test_score_judges_by_std_total',
            measured=False),
    Setting('sensitivity.step', 0.25, '1 (relative)',
            'relative step of each parameter for the sensitivity maps (paper §4.3)',
            'docs/method.md#6-sensitivity-maps-rideidestimateproblemsensitivitypy-paper-43',
            'tests/test_identify.py::test_sensitivity_maps_physics',
            measured=False),
    Setting('sensor_check.hint_corners', (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0), 'Hz',
            "first-order high-pass corners (Hz) tried on the identified car's channels",
            'docs/any-road.md#sensors-as-wired-spec-11',
            'tests/test_sensors.py::test_undeclared_ac_coupling_is_named',
            measured=False),
    Setting('sensor_check.hint_reduction', 0.5, '1 (share of the residual sum of squares)',
            "the least share by which a corner must cut the channel's residual sum of squares to be named",
            'docs/any-road.md#sensors-as-wired-spec-11',
            'tests/test_sensors.py::test_undeclared_ac_coupling_is_named',
            measured=False),
    Setting('sensor_check.road_hint_single', (0.2, 0.5, 1.0), 'Hz',
            ("the corners a single channel is tried at by the road fit's hint (the groups: every "
             'sensor_check.hint_corners)'),
            'docs/any-road.md#sensors-as-wired-spec-11',
            'tests/test_sensors_roads.py::test_the_road_fit_names_an_undeclared_coupling',
            measured=False),
    Setting('sensor_check.free_road_hint_reduction', 0.2, '1 (share of the residual sum of squares)',
            ('the least share a trial high-pass must cut the residual of runs on unknown roads by to be named: there '
             "the road is free at every frequency and takes up part of a coupling's signature"),
            'docs/any-road.md#sensors-as-wired-spec-11',
            'tests/test_sensors_roads.py::test_the_road_fit_names_an_undeclared_coupling_on_unknown_roads',
            measured=True,
            note=('Measured at the car identified without the declaration (SPEC CSVs, 200 Hz, '
                  '``benchmarks/road_hints.py``): hubs coupled at 0.5 Hz, 2 % noise, two ISO 8608 roads: 35 %; hubs '
                  'at 0.3 Hz, 1 % noise, the four roads of examples/roads/class_b.toml: 56 %; the same data not '
                  'coupled, or coupled and declared: every trial made the residual 27-105 % larger.')),
    Setting('small_angle.threshold_deg', 1.0, 'deg',
            ('the largest angle (degrees) below which nothing is said: the bias there (< 0.05 %) is below the error '
             'bars of a proving-ground test at 1 % noise'),
            'docs/verification.md#why-t_hl-is-flagged-what-the-small-angle-model-drops',
            'tests/test_small_angle.py::test_small_angles_say_nothing',
            measured=False),
    Setting('small_angle.bias_per_degree', 0.0005217391304347826, '1/deg',
            ('relative bias per degree of the largest body angle, measured on the MuJoCo car of docs/verification.md '
             '(0.12 % of k_sf at 2.3 degrees of roll; linear in the amplitude)'),
            'docs/verification.md#why-t_hl-is-flagged-what-the-small-angle-model-drops',
            'tests/test_small_angle.py::test_a_body_that_rolls_degrees_names_the_error_bars_narrower_than_the_bias',
            measured=True),
    Setting('uncertainty.rho_max', 0.97, '1 (autocorrelation)',
            ('first-order autocorrelations are clipped to this in the plug-in rule (a unit root has no finite '
             'bandwidth)'),
            'docs/uncertainty.md#the-estimator-a-hac-sandwich-runs-as-independent-blocks',
            'tests/test_uncertainty.py::test_andrews_bandwidth_of_an_ar1_series',
            measured=False),
    Setting('uncertainty.rank_rtol', 1e-12, '1 (share of the largest singular value)',
            ('singular values of a Jacobian below this fraction of its largest are taken as zero (no information): a '
             'little above the rounding floor of an SVD of a Jacobian with 1e5 rows (~1e-13 of the largest)'),
            'docs/uncertainty.md#the-estimator-a-hac-sandwich-runs-as-independent-blocks',
            'tests/test_uncertainty.py::test_a_rank_deficient_jacobian_reports_the_unidentified_parameter_as_infinite',
            measured=True),
    Setting('uncertainty.null_share', 1e-08, '1 (squared share)',
            ('a parameter whose unit vector has more than this squared share in the dropped directions is not '
             'identified'),
            'docs/uncertainty.md#the-estimator-a-hac-sandwich-runs-as-independent-blocks',
            'tests/test_uncertainty.py::test_a_rank_deficient_jacobian_reports_the_unidentified_parameter_as_infinite',
            measured=False),
    Setting('uncertainty.birge_p', 0.99, '1 (probability)',
            ("the Birge ratio's quantile: the runs disagree beyond their noise when the jackknife variance exceeds "
             'the robust one by more than the chi-square(k - 1) quantile at this probability over k - 1'),
            'docs/uncertainty.md#between-runs-when-the-runs-disagree-beyond-their-noise',
            'tests/test_uncertainty.py::test_jackknife_runs_is_the_exact_delete_one_refit_for_a_linear_model',
            measured=False),
    # -- rideid.conditioning: the checks of load_dataset whose thresholds decide a refusal or a finding
    Setting('checks.match_min', 0.5, '1 (correlation)',
            'correlation with the nominal car below which a run does not match its track and speed',
            'docs/common-mistakes.md#the-checks',
            'tests/test_checks.py::test_mistake_ends_in_one_line_naming_the_cause',
            measured=False),
    Setting('checks.start_margin', 0.025, '1 (correlation)',
            ('a given start is a bump or a cycle off when the data correlate with the nominal car by this much '
             'better at another start more than checks.start_samples samples away than at their best near it'),
            'docs/common-mistakes.md#the-checks',
            'tests/test_checks.py::test_start_finding_needs_a_clear_margin',
            measured=True,
            note=('Measured on the hatchback of tests/test_checks.py (1 kHz logger files): a start one cycle off '
                  'peaks 0.050-0.054 below the best start (herringbone, 16 cycles), 0.11 (washboard), 0.33 (twist, '
                  'one bump), half a cycle off 0.96-1.7 below; the true start given, 0.000 below on the hatchback '
                  'and on the built-in car with an engine on as-built tracks (tests/realities_case.py, twenty runs), '
                  'whose best start lies within 1.7 samples of it')),
    Setting('checks.start_samples', 3.0, 'samples',
            'the neighbourhood of a given start within which its best correlation is taken (checks.start_margin)',
            'docs/common-mistakes.md#the-checks',
            'tests/test_checks.py::test_start_finding_needs_a_clear_margin',
            measured=True),
    Setting('speed.wander_max', 0.01, '1 (share of the declared speed)',
            ('largest relative deviation of the speed from the declared one a run may show beyond its uncertainty '
             '(a run without a speed channel)'),
            'docs/real-data.md#a-speed-that-wanders-without-a-speed-channel-teststest_speed_wanderpy-benchmarksspeed_wanderpy',
            'tests/test_speed_wander.py::test_a_wandering_speed_is_refused_in_one_line_naming_the_run_and_the_wander',
            measured=True,
            note=('Measured (benchmarks/speed_wander.py): no run held at its speed shows one beyond its uncertainty, '
                  'each dataset of a +-3 % driver 1.7-2.3 %')),
    Setting('speed.z_min', 1.0, 'standard errors',
            "a deviation of the speed is seen only when it exceeds this many times its uncertainty",
            'docs/real-data.md#a-speed-that-wanders-without-a-speed-channel-teststest_speed_wanderpy-benchmarksspeed_wanderpy',
            'tests/test_speed_wander.py::test_runs_held_at_their_speed_pass_with_margin',
            measured=True,
            note=('Measured: at most 0.5 on every run held at its speed (exact and as-built tracks, the SUV, the van, '
                  'the built-in car, damper curves, bump stops, a rough profile road), up to 1.7-2.3 on each dataset '
                  'of a +-3 % driver')),
    Setting('speed.steady', 0.5, '1 (share of speed.wander_max)',
            ('a run off its declared speed whose speed departs from its own mean by at most this fraction of the '
             'limit is called steady, and the speed the data show is named'),
            'docs/real-data.md#a-speed-that-wanders-without-a-speed-channel-teststest_speed_wanderpy-benchmarksspeed_wanderpy',
            'tests/test_speed_wander.py::test_a_steady_speed_other_than_the_declared_one_names_the_speed_the_data_show',
            measured=False),
    Setting('wiring.rigid_ok', 0.05, '1 (relative residual)',
            'rigid-body residual of the body accelerometers against the gyros that counts as consistent',
            'docs/real-data.md#sensors-as-wired-spec-11',
            'tests/test_checks.py::test_rigid_body_identities_hold_for_the_van',
            measured=False),
    Setting('wiring.rigid_bad', 0.15, '1 (relative residual)',
            'rigid-body residual of the body accelerometers against the gyros that counts as inconsistent',
            'docs/real-data.md#sensors-as-wired-spec-11',
            'tests/test_checks.py::test_rigid_body_identities_hold_for_the_van',
            measured=False),
    Setting('wiring.assign_margin', 0.6, '1 (summed correlation)',
            'a re-wiring must beat the channel map by this much summed correlation to be reported',
            'docs/real-data.md#sensors-as-wired-spec-11',
            'tests/test_checks.py::test_best_assignment_on_a_known_matrix',
            measured=False),
    Setting('wiring.amplitude_band', 2.5, '1 (factor)',
            ("an axle channel's amplitude against the road's (nominal car) may differ from its siblings' by this "
             'factor either way before a unit is blamed'),
            'docs/common-mistakes.md#the-checks',
            'tests/test_checks.py::test_no_amplitude_unit_mistake_where_the_lead_in_read_g',
            measured=False),
)


#: module-level numbers of :mod:`rideid.estimate` that are not tuning constants, each with what it is instead
#: (tests/test_settings.py: every other module-level number there is in the registry)
NOT_SETTINGS: dict[str, str] = {
    "identify.DEFAULT_POPULATION": "an argument's default (rideid.identify population=, --population; SPEC §5)",
    "identify.DEFAULT_GENERATIONS": "an argument's default (rideid.identify generations=, --generations; SPEC §5)",
    "cost.BUMP_BOUNDS": "the bump stops' default search bounds: a model default, [bounds] overrides it",
    "scores.ANDREWS_BARTLETT": "a mathematical constant: Andrews (1991), the Bartlett kernel's optimal bandwidth",
    "sensitivity.P2R_STARS": "display: the report's star ratings of the sensitivity maps (docs/report.md)",
    "sensitivity.R2T_STARS": "display: the report's star ratings of the sensitivity maps (docs/report.md)",
    "sensitivity.P2T_STARS": "display: the report's star ratings of the sensitivity maps (docs/report.md)",
    "asbuilt.SIZE_PRIOR_WEIGHT": "a mathematical constant: sqrt(1/2), a complex residual's real and imaginary "
                                 "parts' share of its variance (its comment)",
    "frequency.STEP": "a numerical stencil: the relative step of the central differences of |H|",
    "roadstaged.HOLD_FIX": "a numerical stencil: the first-order-hold correction filter (module docstring)",
    "roadstaged.LOWPASS_HZ": "the compared time-domain road method (docs/road-methods.md#tuning), run by "
                             "benchmarks/road_methods.py only, not by rideid identify",
    "roadstaged.EDGE_SECONDS": "the compared time-domain road method (docs/road-methods.md#tuning), run by "
                               "benchmarks/road_methods.py only, not by rideid identify",
}

REGISTRY: dict[str, Setting] = {s.name: s for s in _SETTINGS}
_values: dict[str, object] = {s.name: s.default for s in _SETTINGS}


def _check(name: str, value) -> object:
    """``value`` as the setting ``name`` holds it; :class:`ArgumentError` naming the setting otherwise."""
    if name not in REGISTRY:
        close = difflib.get_close_matches(str(name), REGISTRY, n=2) or [
            n for n in REGISTRY if n.split(".")[-1] == str(name).split(".")[-1]]
        hint = f" (did you mean {' or '.join(close)}?)" if close else ""
        raise ArgumentError(f"settings: unknown setting '{name}'{hint}; the settings are listed in docs/settings.md")
    default = REGISTRY[name].default

    def number(v, integer):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
        if integer:
            return int(v) if float(v).is_integer() else None
        return float(v)

    if isinstance(default, tuple):
        integer = all(isinstance(d, int) for d in default)
        vals = [number(v, integer) for v in value] if isinstance(value, (list, tuple)) else [None]
        if not vals or None in vals or (len(default) == 2 and len(vals) != 2):
            n = "two" if len(default) == 2 else "one or more"
            kind = "integers" if integer else "numbers"
            raise ArgumentError(f"settings: '{name}' must be a list of {n} finite {kind} (default {list(default)}), "
                                f"got {value!r}")
        return tuple(vals)
    v = number(value, isinstance(default, int))
    if v is None:
        kind = "an integer" if isinstance(default, int) else "a finite number"
        raise ArgumentError(f"settings: '{name}' must be {kind} (default {default!r}), got {value!r}")
    return v


class _Defaults(Mapping):
    """The values in force, by name (read-only: change them with :func:`set_defaults` or :func:`using`)."""

    def __getitem__(self, name):
        try:
            return _values[name]
        except KeyError:
            try:
                _check(name, None)
            except ArgumentError as e:  # a KeyError (a Mapping's `in` and `get` rely on it) naming the setting
                raise KeyError(str(e)) from None
            raise

    def __iter__(self) -> Iterator[str]:
        return iter(_values)

    def __len__(self):
        return len(_values)

    def __repr__(self):
        changed = {n: v for n, v in _values.items() if v != REGISTRY[n].default}
        return f"<rideid.settings.defaults: {len(self)} settings, changed: {changed or 'none'}>"


#: the values in force: ``defaults["adequacy.alpha"]``
defaults = _Defaults()


def _flatten(module_or_values, kw) -> dict:
    """``("adequacy", alpha=0.05)`` or ``({"adequacy.alpha": 0.05})`` -> ``{"adequacy.alpha": 0.05}``."""
    if isinstance(module_or_values, str):
        return {f"{module_or_values}.{k}": v for k, v in kw.items()}
    if module_or_values is None and kw:
        raise ArgumentError(f"settings: {', '.join(kw)}: a keyword needs the module it belongs to, "
                            f"as set_defaults('adequacy', alpha=0.05)")
    values = dict(module_or_values or {})
    if kw:
        raise ArgumentError("settings: give a module name with keywords (set_defaults('adequacy', alpha=0.05)) "
                            "or one mapping of full names ({'adequacy.alpha': 0.05}), not a mapping and keywords")
    return values


def checked(values: Mapping) -> dict:
    """``values`` (name -> value) checked against the registry, as the settings hold them (tuples for lists);
    :class:`ArgumentError` naming the first unknown or malformed one."""
    return {n: _check(n, v) for n, v in values.items()}


def set_defaults(module_or_values=None, /, **kw) -> None:
    """Change settings until :func:`reset_defaults`.

    ``set_defaults("adequacy", alpha=0.05, min_relative=0.01)`` (python-control's form) or
    ``set_defaults({"adequacy.alpha": 0.05})``. All are checked before any is changed.
    """
    _values.update(checked(_flatten(module_or_values, kw)))


def reset_defaults() -> None:
    """Every setting back to the value rideid ships with."""
    _values.update({n: s.default for n, s in REGISTRY.items()})


@contextlib.contextmanager
def using(module_or_values=None, /, **kw):
    """The settings given, inside a ``with`` block; the previous values after it (also on an error).

    Same arguments as :func:`set_defaults`: ``with using("adequacy", alpha=0.05):`` or
    ``with using({"adequacy.alpha": 0.05}):``.
    """
    new = checked(_flatten(module_or_values, kw))
    before = {n: _values[n] for n in new}
    _values.update(new)
    try:
        yield defaults
    finally:
        _values.update(before)


def current() -> dict:
    """Every value in force, name -> value (tuples as lists): what ``result.json`` records as ``settings``."""
    return {n: list(v) if isinstance(v, tuple) else v for n, v in _values.items()}


def changed() -> dict:
    """The settings whose value differs from the shipped default, name -> value."""
    return {n: v for n, v in current().items() if _values[n] != REGISTRY[n].default}


def legacy_names(module: str, names: dict[str, object]):
    """A module ``__getattr__`` (PEP 562) that reads the old constant names of ``module`` (its ``__name__``)
    from the registry: ``rideid.estimate.assess.adequacy.ALPHA`` -> ``defaults["adequacy.alpha"]`` (the names code
    outside rideid may still import; read when imported, so they do not follow a later change). A value that is
    not a setting's name is a function of none, called (``PENALTY`` -> ``penalty()``)."""

    def __getattr__(attr):
        if attr in names:
            return _values[names[attr]] if isinstance(names[attr], str) else names[attr]()
        raise AttributeError(f"module {module!r} has no attribute {attr!r}")

    return __getattr__


def markdown_table() -> str:
    """Every setting as a Markdown table (docs/settings.md holds it; tests/test_settings.py checks they agree)."""
    rows = ["| setting | default | unit | meaning | measured | reason | test |", "|---|---|---|---|---|---|---|"]
    for s in _SETTINGS:
        default = list(s.default) if isinstance(s.default, tuple) else s.default
        test = s.test.split("::")
        rows.append(f"| `{s.name}` | `{default}` | {s.unit} | {s.meaning.replace('|', '/')} | "
                    f"{'yes' if s.measured else 'no'} | [{s.reason.split('/')[-1]}]({s.reason.replace('docs/', '')}) | "
                    f"`{test[0].replace('tests/', '')}::{test[1]}` |")
    return "\n".join(rows) + "\n"


__all__ = ["Setting", "REGISTRY", "NOT_SETTINGS", "defaults", "set_defaults", "reset_defaults", "using", "checked",
           "current", "changed", "markdown_table"]


if __name__ == "__main__":  # python -m rideid.settings: the table of docs/settings.md
    print(markdown_table(), end="")
