"""Measured runs as loggers write them: channel maps, units, gravity, rates, start.

A run is *measured* (rather than a SPEC §3 CSV taken as it is) when the
dataset gives a channel map, preprocessing options or CSV options, when the
run file is not a CSV, or when the run names its own channels, start, window
or lead-in, or carries a speed or distance channel instead of a constant
``speed``. Its file is then turned into model-ready data in these steps,
each recorded in :attr:`MeasuredRun.record` (and in ``result.json``):

1. **Read** the mapped channels (:mod:`rideid.readers`).
2. **Units, sign, scale** to SI (``g`` -> m/s², ``deg/s`` -> rad/s,
   ``km/h`` -> m/s, ``ms`` -> s ...); unknown units are errors.
3. **Plausibility warnings** (:class:`rideid.DataWarning`): gaps in time,
   flat-lined or clipped channels, an acceleration whose mean is about g
   while ``gravity_included`` is false, a rate labelled rad/s whose values
   look like deg/s, a lead-in that is not stationary.
4. **Gravity and bias**: with ``gravity_included`` the mean of each
   acceleration over the stationary lead-in (gravity plus sensor bias) is
   subtracted; ``remove_bias`` subtracts the lead-in mean of every channel
   (gyro bias too).
5. **Anti-alias filtering and resampling** to one rate ``fs``, by default
   the lowest whole division of the channels' rates at or above 200 Hz
   (:func:`default_rate`): a channel whose rate is a whole multiple of
   ``fs`` is decimated (its samples at the model's times, as the model
   predicts them: see :func:`_filter_resample`), other channels faster than
   ``fs`` are read off by the cubic spline with a warning, or, with
   ``anti_alias = true``, low-passed (analog Butterworth, order 8, at 0.4 fs,
   causal) with the same filter joining their sensor chain, so the model's
   channels pass it too; a channel slower than
   ``fs`` is upsampled to a grid at least five times finer (polyphase,
   Kaiser beta 10: passband gain within 1e-6). The run's ``resampling``
   record (:func:`rate_record`) states the rate, its rule and each filter.
   Each channel is then read off once, by a cubic spline, at the run's
   **samples** ``t_first + k / fs``; a channel logged at ``fs`` on that
   clock keeps its own values exactly. The samples never move afterwards.
6. **Start**: the file time at which the front axle reaches ``x = 0``
   (SPEC §2). When not given (``start = "auto"``, the default for measured
   runs) it is estimated by correlating the samples with the response of a
   nominal car (the built-in car on this geometry; the absolute scale does
   not matter for accelerations) over all lags at the sample rate, to a
   fraction of a sample by a parabola through the correlation peak
   (:mod:`rideid.conditioning.starts`, which runs the model; this module does not).
   :func:`rideid.identify` estimates it again with the parameters. **The
   model moves, the data never do**: a start ``s`` puts the model's time
   axis at ``t = T_k - s`` for the fixed samples ``T_k``; the data are never
   interpolated at a start-dependent time (interpolating noisy samples at a
   fractional offset smooths their noise, so a cost on re-read data prefers
   starts between samples: 1-1.7 ms late at 200 Hz, with unsprung masses and
   tire rates 8-12 % off).
7. **Window**: the model's samples run from ``pre_roll`` (default 0.5 s)
   before the start, or from ``window[0]``, to the end of the recording or
   ``window[1]``; chosen once, at the first start, as a range of samples.
8. **Speed**: a constant ``speed`` or a ``speed`` channel (integrated) or a
   ``distance`` channel; the wheel inputs follow the distance travelled
   since the start.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import DataError, DataWarning
from ..model.equations import CHANNELS
from ..model.params import GRAVITY
from ..model.sensors import AnalogFilter, discretise
from .readers import FORMAT_NAMES, Signal, open_signals
from ..model.posts import MIN_CHAIN_GAIN, POST_CHANNELS, POST_VEL_CHANNELS, unfilter
from .schema.channels import RIG_TARGETS, SI, TARGETS, UNITS, ChannelEntry, gravity_unit_factor, quantity, unit_factor
from .schema.runfiles import PLAUSIBLE_RATE, RunData, check_post_channels, time_units_fitting


#: the default model rate is the lowest whole division of the channels' rates at or above this
#: (:func:`default_rate`)
DEFAULT_FS = 200.0
DEFAULT_LEAD_IN = 1.0
DEFAULT_PRE_ROLL = 0.5
FILTER_ORDER = 8
FILTER_CUTOFF = 0.4  # x fs
UPSAMPLE_TO = 5.0  # x fs
#: time stamps within this share of a sample interval of a uniform clock are that clock, rounded
#: (a logger's time written to 7 digits is off by up to 1.5e-3 of an interval at 300 Hz after 10 s)
ROUNDED_STAMPS = 0.01
#: a rate ratio within this of a whole number is whole (decimation takes the samples as they are)
WHOLE_RATIO = 1e-6
#: Kaiser window of the polyphase upsampling filter: SciPy's default (5) has a passband gain of
#: 1.00065 at the original sample phase, a uniform gain error on every upsampled channel that moved
#: unsprung masses and tire rates by 3 standard errors; 10 keeps it below 1e-6
UPSAMPLE_BETA = 10.0


# ---------------------------------------------------------------------------
# Signal helpers

class Resampled:
    """A channel after filtering, read off by a cubic spline at any file time (0 outside)."""

    def __init__(self, t0: float, h: float, y: np.ndarray):
        from scipy.interpolate import make_interp_spline

        self.t0, self.h, self.n, self.y = t0, h, y.size, y
        self.t1 = t0 + h * (y.size - 1)
        self.spline = make_interp_spline(t0 + h * np.arange(y.size), y, k=3)

    def samples(self, t0: float, fs: float, n: int) -> np.ndarray:
        """The values at ``t0 + k / fs``, k < n: this channel's own values where those times are
        its samples (the same clock), else read off the spline."""
        step = 1.0 / (fs * self.h)
        k0 = (t0 - self.t0) / self.h
        if abs(step - round(step)) < 1e-9 and abs(k0 - round(k0)) < 1e-6 and round(step) >= 1:
            idx = int(round(k0)) + int(round(step)) * np.arange(n)
            if idx[0] >= 0 and idx[-1] < self.n:
                return self.y[idx].astype(float)
        return self(t0 + np.arange(n) / fs)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        tol = 1e-6 * self.h  # a sample time rounded past an end is still that end's sample
        inside = (t >= self.t0 - tol) & (t <= self.t1 + tol)
        out = np.zeros(t.shape)
        out[inside] = self.spline(t[inside])
        return out


class Distance:
    """Distance travelled (m) as a function of file time, linear beyond the ends."""

    def __init__(self, t, d):
        from scipy.interpolate import PchipInterpolator

        self.t, self.d = t, d
        self.f = PchipInterpolator(t, d, extrapolate=False)
        self.v0 = (d[1] - d[0]) / (t[1] - t[0])
        self.v1 = (d[-1] - d[-2]) / (t[-1] - t[-2])

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        tc = np.clip(t, self.t[0], self.t[-1])
        out = self.f(tc)
        out = out + np.where(t < self.t[0], (t - self.t[0]) * self.v0, 0.0)
        out = out + np.where(t > self.t[-1], (t - self.t[-1]) * self.v1, 0.0)
        return out

    def speed_range(self):
        v = np.diff(self.d) / np.diff(self.t)
        return float(v.min()), float(np.mean(v)), float(v.max())


@dataclass
class RelativeDistance:
    """x(t) = d(start + t) - d(start): distance of the front axle past x = 0 at model time t."""

    dist: Distance
    start: float

    def __call__(self, t):
        return self.dist(self.start + np.asarray(t, dtype=float)) - float(self.dist(np.array([self.start]))[0])

    @property
    def max_speed(self):
        return self.dist.speed_range()[2]


def _longest_run(mask: np.ndarray) -> int:
    if not mask.any():
        return 0
    m = np.concatenate([[0], mask.astype(np.int8), [0]])
    d = np.diff(m)
    return int(np.max(np.nonzero(d == -1)[0] - np.nonzero(d == 1)[0]))


# ---------------------------------------------------------------------------
# A measured run

@dataclass
class MeasuredRun:
    """One run file turned into SI channels on a continuous time axis (file clock).

    ``channels`` maps SPEC channel names to :class:`Resampled` signals;
    :meth:`run_data` samples them at ``start + t`` on the model grid.
    """

    run_id: str
    path: Path
    fs: float
    channels: dict
    t_first: float
    t_last: float
    speed: float | None
    distance: Distance | None
    options: dict
    record: dict
    warnings: list = field(default_factory=list)
    start: float | None = None
    #: the run's samples (file time, s): ``t_first + k / fs`` over the recording; the data never move
    times: np.ndarray | None = None
    #: ``(n, 10)`` SI channels at :attr:`times` (CHANNELS order, NaN where missing), read off once
    values: np.ndarray | None = None
    #: the model's samples: index range ``[i0, i1)`` into :attr:`times`, fixed at the first start
    window: tuple | None = None
    #: SPEC channel -> ``(times, interval)``: the file samples (file time, s) where that channel sat at its
    #: range (SPEC §11: declared ``range``, or detected as clipped) and the channel's sample interval (s);
    #: only channels with such samples
    clipped_times: dict = field(default_factory=dict)
    #: SPEC channel -> its sensor chain's analog filters (:class:`rideid.model.sensors.AnalogFilter`)
    filters: dict = field(default_factory=dict)
    #: ``(n, 10)`` bool at :attr:`times`: samples left out of the fit (a channel at its range)
    clipped: np.ndarray | None = None
    #: the distance as the speed channel gave it, when :attr:`distance` carries a correction
    #: (:meth:`with_distance_correction`)
    channel_distance: Distance | None = None
    #: a four-post rig run's post channels (SPEC §13), name -> :class:`Resampled` (m, m/s); empty on a road
    posts: dict = field(default_factory=dict)

    def with_distance_correction(self, knots, values) -> "MeasuredRun":
        """This run driven along its channel's distance plus ``delta`` (piecewise linear through ``values`` m at
        file times ``knots``, constant beyond them): a noisy speed channel's correction
        (:class:`rideid.conditioning.starts.DistanceWarp`). Always from the channel's own distance, so a
        correction replaces an earlier one."""
        base = self.channel_distance if self.channel_distance is not None else self.distance
        if base is None:
            raise ValueError(f"run '{self.run_id}' has no distance profile to correct")
        warped = Distance(base.t, base.d + np.interp(base.t, np.asarray(knots, float), np.asarray(values, float)))
        return replace(self, distance=warped, channel_distance=base)

    def __post_init__(self):
        if self.times is None:
            n = int(math.floor((self.t_last - self.t_first) * self.fs + 1e-9)) + 1
            self.times = self.t_first + np.arange(n) / self.fs
            Y = np.full((n, len(CHANNELS)), np.nan)
            for i, c in enumerate(CHANNELS):
                if c in self.channels:
                    Y[:, i] = self.channels[c].samples(self.t_first, self.fs, n)
            Y.flags.writeable = False
            self.values = Y
        if self.clipped is None:
            M = np.zeros((self.times.size, len(CHANNELS)), dtype=bool)
            for c, (tc, h_file) in self.clipped_times.items():
                M[:, CHANNELS.index(c)] = clipped_samples(self.times, tc, h_file)
            M.flags.writeable = False
            self.clipped = M

    def window_clipped(self) -> np.ndarray:
        """``(n, 10)`` bool: the window's samples left out of the fit (:attr:`clipped`)."""
        i0, i1 = self.window
        return self.clipped[i0:i1]

    def chain_filters(self) -> tuple:
        """Per SPEC channel (CHANNELS order) the tuple of its sensor chain's filters."""
        return tuple(tuple(self.filters.get(c, ())) for c in CHANNELS)

    @property
    def auto_start(self) -> bool:
        return self.options.get("start", "auto") == "auto"

    @property
    def grid(self) -> np.ndarray | None:
        """Model times of the window's samples at the current start (None before a start)."""
        if self.window is None or self.start is None:
            return None
        return self.times[self.window[0]:self.window[1]] - self.start

    def relative_distance(self, start):
        if self.distance is None:
            return None
        return RelativeDistance(self.distance, start)

    def make_grid(self, start: float):
        """Choose the window's samples for a first start estimate; returns their model times."""
        pre = self.options.get("pre_roll", DEFAULT_PRE_ROLL)
        w0, w1 = self.options.get("window", (-math.inf, math.inf))
        lo = max(self.t_first, w0 if "window" in self.options else start - pre)
        hi = min(self.t_last, w1)
        i0 = int(math.ceil((lo - self.t_first) * self.fs - 1e-9))
        i1 = int(math.floor((hi - self.t_first) * self.fs + 1e-9)) + 1
        if i1 - i0 < 3:
            raise DataError(f"{self.path}: fewer than 3 samples between {lo:.3f} s and {hi:.3f} s "
                            "(check window, start and the recording)")
        self.window = (i0, i1)
        return self.times[i0:i1] - start

    def keep_window(self, start: float, model_time) -> bool:
        """Take the samples an earlier reading used: those from ``start + model_time[0]`` to
        ``start + model_time[1]`` (file time; ``model_time`` as ``result.json``'s preprocessing records it), when
        both ends fall on samples of this recording (within a tenth of a sample; else the window stays as it is).

        Returns
        -------
        bool
            Whether the window was set.
        """
        ends = np.asarray(model_time, dtype=float) + start
        if ends.shape != (2,) or not np.all(np.isfinite(ends)):
            return False
        k = np.rint((ends - self.t_first) * self.fs)
        if (np.any(np.abs(k - (ends - self.t_first) * self.fs) > 0.1) or k[0] < 0 or k[1] >= self.times.size
                or k[1] - k[0] < 2):
            return False
        self.window = (int(k[0]), int(k[1]) + 1)
        return True

    def run_data(self, start: float):
        """:class:`RunData` of the window's samples, on the model's time axis for this start."""
        if self.window is None:
            self.make_grid(start)
        i0, i1 = self.window
        Y = self.values
        chans = {c: Y[i0:i1, i].copy() for i, c in enumerate(CHANNELS) if c in self.channels}
        posts = vel = None
        if self.posts:  # SPEC §13: the posts read off at the same samples as the channels
            t0, n = self.times[i0], i1 - i0
            posts = np.column_stack([self.posts[c].samples(t0, self.fs, n) for c in POST_CHANNELS])
            if POST_VEL_CHANNELS[0] in self.posts:
                vel = np.column_stack([self.posts[c].samples(t0, self.fs, n) for c in POST_VEL_CHANNELS])
        return RunData(self.times[i0:i1] - start, chans, distance=self.relative_distance(start), posts=posts,
                       post_vel=vel)


def _warn(mr_warnings: list, msg: str, stacklevel: int = 3):
    mr_warnings.append(msg)
    warnings.warn(msg, DataWarning, stacklevel=stacklevel)


#: stack depth from :func:`warnings.warn` in :func:`_warn` to the caller of
#: :func:`load_measured_run`, for the warnings its stages give
_STAGE = 4


def load_measured_run(run, man) -> MeasuredRun:
    """Read and preprocess one measured run (steps 1-5 and 8 of the module docstring).

    The stages: read the mapped channels in SI units (:func:`_map_channels`,
    :func:`_read_si`), find the common time span and rate
    (:func:`_span_and_rate`), subtract gravity and bias over the lead-in
    (:func:`_remove_gravity_bias`), filter and resample
    (:func:`_filter_resample`), and take the speed or distance
    (:func:`_motion`). Each stage adds to the run's record.
    """
    path = Path(run.file)
    if not path.is_absolute():
        path = man.base_dir / path
    opts = {**man.preprocess, **run.options}
    cmap = {**man.channel_map, **run.channels}
    where_map = f"{man.path}: run '{run.id}'"
    sf = open_signals(path, man.csv_options)
    warns: list[str] = []

    targets, time_name, time_scale = _map_channels(run, cmap, sf, path, where_map)
    measured = [c for c in targets if c in CHANNELS]
    raw, rec_ch = _read_si(targets, sf, time_name, time_scale, opts, path, where_map, warns)
    _check_time_base(rec_ch, measured, time_name, time_scale, path)
    t_first, t_last, fs, rule = _span_and_rate(raw, rec_ch, measured, opts.get("fs", None), path, warns)
    lead = opts.get("lead_in", (t_first, t_first + DEFAULT_LEAD_IN))
    grav = opts.get("gravity_included", False)
    bias = opts.get("remove_bias", False)
    _remove_gravity_bias(raw, rec_ch, measured, lead, grav, bias, path, where_map, warns)
    channels, added = _filter_resample(raw, rec_ch, measured, fs, opts.get("anti_alias"), path, warns)
    _unfilter_posts(raw, rec_ch, targets)
    # the posts are the car's input: read off at fs, never low-passed (the model's channels would pass it twice)
    posts, _ = _filter_resample(raw, rec_ch, [c for c in RIG_TARGETS if c in raw], fs, False, path, warns)
    distance, motion_rec = _motion(raw, targets, run.speed, path)
    if run.posts:
        motion_rec = {"source": "none: a four-post rig run (SPEC §13), its wheel inputs the posts"}

    record = {"file": str(path), "format": FORMAT_NAMES[sf.format], "channels": rec_ch, "fs": fs,
              "speed": motion_rec, "recording": [t_first, t_last],
              "resampling": rate_record(rec_ch, measured, fs, rule)}
    if grav or bias:
        record["lead_in"] = list(lead)
    if sf.format == "csv":
        record["csv"] = {"delimiter": sf.delimiter, "decimal": sf.decimal}
    clipped = {c: (rec_ch[c].pop("_clipped_times"), 1.0 / rec_ch[c]["rate_hz"]) for c in measured
               if "_clipped_times" in rec_ch[c]}
    declared = {c: tuple(targets[c].filters) for c in measured if targets[c].filters}
    for c, fs_c in declared.items():
        rec_ch[c]["sensor_filters"] = [f.describe() for f in fs_c]
    # the model's chain: the declared sensor filters, then the ones rideid applied to the data
    filters = {c: declared.get(c, ()) + added.get(c, ()) for c in measured if c in declared or c in added}
    return MeasuredRun(run.id, path, fs, channels, t_first, t_last, run.speed, distance, opts, record, warns,
                       clipped_times=clipped, filters=filters, posts=posts)


def _unfilter_posts(raw: dict, rec_ch: dict, targets: dict) -> None:
    """A post channel's sensor chain (SPEC §13: ``highpass``, ``lowpass`` like any channel's) divided out of its
    values (:func:`rideid.model.posts.unfilter`): the posts are the model's input, so the model needs them as
    the rig moved them, not as the chain recorded them."""
    for c in RIG_TARGETS:
        if c in raw and targets[c].filters:
            s = raw[c]
            t = s.time[0] + float(np.median(np.diff(s.time))) * np.arange(s.time.size)
            raw[c] = Signal(s.time, unfilter(t, s.values, targets[c].filters), s.unit)
            rec_ch[c]["sensor_filters"] = [f.describe() for f in targets[c].filters]
            rec_ch[c]["unfiltered"] = (f"the chain's response divided out where its gain is at least "
                                       f"{MIN_CHAIN_GAIN:g} (frequency domain), the rest left out")


def clipped_samples(times, clipped_times, h_channel: float) -> np.ndarray:
    """Which of ``times`` (file time, s) a clipped file sample reaches: a time on a clipped sample, or
    strictly between a clipped sample and its neighbour (the read-off interpolates it), within a
    millionth of the channel's interval ``h_channel``."""
    tc = np.asarray(clipped_times, dtype=float)
    if tc.size == 0:
        return np.zeros(np.shape(times), dtype=bool)
    t = np.asarray(times, dtype=float)
    k = np.searchsorted(tc, t)
    left = np.abs(t - tc[np.clip(k - 1, 0, tc.size - 1)])
    right = np.abs(tc[np.clip(k, 0, tc.size - 1)] - t)
    return np.minimum(left, right) < h_channel * (1 - 1e-6)


def _map_channels(run, cmap: dict, sf, path: Path, where_map: str):
    """Which file channel feeds which SPEC target, and how the file's time is read.

    Returns ``(targets, time_name, time_scale)``: ``targets`` maps SPEC names
    (channels, ``speed``, ``distance``) to :class:`ChannelEntry`; the mapped
    ones plus SPEC-named columns the map does not mention.
    """
    # time column (CSV, Parquet) or time channel (TDMS)
    time_name, time_scale = None, 1.0
    if "time" in cmap:
        te = cmap["time"]
        time_name = te.name
        time_scale = unit_factor(te.unit, "time", f"{where_map} time unit") if te.unit else 1.0
        time_scale *= te.scale

    targets = {}
    for c in TARGETS:
        if c == "time":
            continue
        if c in cmap:
            targets[c] = cmap[c]
        elif (c in CHANNELS or (run.posts and c in RIG_TARGETS)) and sf.has(c):
            targets[c] = ChannelEntry(c)
    if not run.posts:  # post channels mapped for every run of a mixed dataset: only a rig run's are read
        targets = {c: e for c, e in targets.items() if c not in RIG_TARGETS}
    if not any(c in CHANNELS for c in targets):
        raise DataError(f"{path}: none of the SPEC channels found; map the file's channels in [channels] "
                        f"(the file has: {', '.join(sf.names()[:12])})")
    if "speed" in targets and "distance" in targets:
        raise DataError(f"{where_map}: map either a speed or a distance channel, not both")
    has_motion = "speed" in targets or "distance" in targets
    if run.posts:  # SPEC §13: a rig run's road is its four posts; it does not drive
        check_post_channels(targets, where_map, f"is neither mapped in [channels] nor a column of {path}")
        if has_motion:
            raise DataError(f"{where_map}: a four-post rig run has no speed or distance channel (a rig does not "
                            "drive); leave it out of the run's channels")
        return targets, time_name, time_scale
    if has_motion and run.speed is not None:
        raise DataError(f"{where_map}: give either a constant 'speed' or a speed/distance channel, not both")
    if not has_motion and run.speed is None:
        raise DataError(f"{where_map}: missing key 'speed' (m/s), or map a speed or distance channel")
    return targets, time_name, time_scale


def _read_si(targets: dict, sf, time_name, time_scale: float, opts: dict, path: Path, where_map: str,
             warns: list):
    """Read each target, check its time axis, convert it to SI (unit, scale, sign) and warn on the implausible.

    Returns ``(raw, rec_ch)``: SPEC name -> :class:`Signal` in SI units, and
    SPEC name -> its record (source, unit, sign, rate, ...).
    """
    raw: dict[str, Signal] = {}
    rec_ch = {}
    for c, e in targets.items():
        w = f"channel '{e.name}' mapped to {c}"
        sig = sf.get(e.name, w, time_name, time_scale)
        if sig.values.size < 3:
            raise DataError(f"{path}: {w}: only {sig.values.size} samples")
        if not np.all(np.isfinite(sig.values)):
            k = int(np.argmax(~np.isfinite(sig.values)))
            raise DataError(f"{path}: {w}: NaN or infinite value at t = {sig.time[k]:.6g} s")
        if not np.all(np.isfinite(sig.time)):
            raise DataError(f"{path}: {w}: time has a NaN or infinite value")
        dt = np.diff(sig.time)
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            raise DataError(f"{path}: {w}: time is not strictly increasing at t = {sig.time[k]:.6g} s")
        unit, unit_src = _channel_unit(c, e, sig, path, w, warns)
        factor = unit_factor(unit, c, f"{where_map} {c}") * e.scale * e.sign
        v = sig.values * factor
        raw[c] = Signal(sig.time, v, unit)
        med = float(np.median(dt))
        h_clock = uniform_clock(sig.time)
        rec_ch[c] = {"source": e.name, "unit": unit, "unit_from": unit_src, "file_unit": sig.unit, "sign": int(e.sign),
                     "scale": e.scale, "rate_hz": round(1.0 / (h_clock or med), 6), "samples": int(v.size)}
        # plausibility
        gap = dt > 1.5 * med
        if gap.any():
            k = int(np.argmax(dt))
            _warn(warns, f"{path}: {w}: {int(gap.sum())} gap(s) in time, the longest {dt[k]:.4g} s at "
                         f"t = {sig.time[k]:.6g} s (sample interval {med:.4g} s); bridged by interpolation", _STAGE)
        if c in CHANNELS:
            if not _plausibility(c, v, unit, opts, f"{path}: {w}", warns):
                # a dead channel: no unit to check (rideid.conditioning.wiring.unit_findings)
                rec_ch[c]["flat_lined"] = True
            else:
                at = at_range(sig.values, e.range)
                if at.any():
                    rec_ch[c]["_clipped_times"] = sig.time[at] * 1.0
                    rec_ch[c]["clipped"] = {"samples": int(at.sum()), "share": float(at.mean()),
                                            "how": (f"at the declared range +-{e.range:g} {unit}"
                                                    if e.range is not None else
                                                    "detected: 3 or more consecutive samples at the extreme")}
        if gap.any():
            rec_ch[c]["gaps"] = {"count": int(gap.sum()), "longest_s": float(dt.max())}
    return raw, rec_ch


def at_range(values, full_scale: float | None = None) -> np.ndarray:
    """The samples of a channel at its range: ``|value| >= full_scale`` (in the file's unit, less a
    part in 1e9) when the range is declared; else, as detected, every sample equal to an extreme that
    the channel holds for 3 or more consecutive samples (a sensor or logger at its rail)."""
    v = np.asarray(values, dtype=float)
    if full_scale is not None:
        return np.abs(v) >= full_scale * (1 - 1e-9)
    out = np.zeros(v.shape, dtype=bool)
    if v.size and np.ptp(v) > 0:
        for val in (v.max(), v.min()):
            if _longest_run(v == val) >= 3:
                out |= v == val
    return out


def _channel_unit(c: str, e: ChannelEntry, sig: Signal, path: Path, w: str, warns: list):
    """The unit of target ``c``: the map's, else the file's (if known), else SI; and where it came from."""
    unit, unit_src = e.unit, "map"
    if unit is None:
        if sig.unit:
            try:
                unit_factor(sig.unit, c, "")
            except DataError:
                raise DataError(f"{path}: {w}: the file's unit '{sig.unit}' is not one rideid knows; "
                                f"give unit in [channels] ({', '.join(UNITS[quantity(c)])})") from None
            unit, unit_src = sig.unit, "file"
        else:
            unit, unit_src = SI[quantity(c)], "SI (none given)"
    elif sig.unit:
        try:
            fu = unit_factor(sig.unit, c, "")
        except DataError:
            fu = None
        if fu is not None and fu != unit_factor(unit, c, ""):
            _warn(warns, f"{path}: {w}: the file says unit '{sig.unit}' but the map says '{unit}'; "
                         "using the map's", _STAGE + 1)
    return unit, unit_src


def _check_time_base(rec_ch: dict, measured: list, time_name, time_scale: float, path: Path) -> None:
    """One clear error when the measured channels' sample rate is not a ride recording's: the time base is in
    another unit than read (a time column in ms read as s), naming the time column and the unit that fits."""
    rates = [rec_ch[c]["rate_hz"] for c in measured if rec_ch.get(c, {}).get("rate_hz")]
    if not rates:
        return
    rate = max(rates)
    lo, hi = PLAUSIBLE_RATE
    if lo <= rate <= hi:
        return
    fits = time_units_fitting(rate, time_scale)
    where = (f"the time column '{time_name}'" if time_name else "the file's time base")
    hint = (f"; is it in {fits[0]}? set [channels] time = {{ name = \"{time_name or 'time'}\", unit = \"{fits[0]}\" }}"
            if fits else "; check the time column's unit and the logger's rate")
    raise DataError(f"{path}: {where} gives the channels a sample rate of {rate:.3g} Hz, not a ride recording's "
                    f"({lo:g} Hz - {hi / 1000:g} kHz){hint}")


def uniform_clock(t) -> float | None:
    """The sample interval (s) of time stamps that lie on a uniform clock to within
    :data:`ROUNDED_STAMPS` of an interval (a logger that writes its time rounded to a few digits:
    ``10.00333`` for ``10.003333...`` at 300 Hz); None when they do not
    (a jittered or gapped time base, put on a uniform grid by :func:`_filter_resample`). The interval is the
    least-squares slope of the stamps over their index (the rounding averages out: 1e-10 relative at 300 Hz
    over 10 s), the clock's origin the first stamp."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return None
    k = np.arange(t.size) - (t.size - 1) / 2.0
    h = float(k @ (t - t.mean()) / (k @ k))
    if not h > 0:
        return None
    dev = t - (t[0] + h * np.arange(t.size))
    return float(h) if float(np.max(np.abs(dev))) <= ROUNDED_STAMPS * h else None


def default_rate(rates) -> tuple:
    """``(fs, rule)``: rideid's default model rate for channels logged at ``rates`` (Hz), and the rule that chose it.

    The lowest rate of at least :data:`DEFAULT_FS` that every rate is a whole multiple of (so every channel is
    decimated, its samples taken as they are: 300 Hz -> 300, 500 -> 250, 1000 -> 200, 200 -> 200, mixed
    1000 and 500 -> 250). When the rates have no such common divisor (300 and 500 Hz), the slowest rate's
    (300 -> 300), and the channels it does not divide are read off by a cubic spline, with a warning
    (:func:`_filter_resample`). Below :data:`DEFAULT_FS`: the slowest rate.
    """
    rates = [float(r) for r in rates]
    slow = min(rates)

    def divides(fs, r):
        q = r / fs
        return abs(q - round(q)) < WHOLE_RATIO

    if slow <= DEFAULT_FS * (1 + WHOLE_RATIO):
        return slow, f"the slowest channel's rate, {DEFAULT_FS:g} Hz or less"
    n_max = int(math.floor(slow / DEFAULT_FS + WHOLE_RATIO))
    for n in range(n_max, 0, -1):
        fs = slow / n
        if all(divides(fs, r) for r in rates):
            which = "of every channel's rate" if len(set(rates)) > 1 else "of the file's rate"
            return fs, (f"{slow:g} Hz / {n}: the lowest whole division {which} at or above {DEFAULT_FS:g} Hz")
    fs = slow / n_max
    return fs, (f"{slow:g} Hz / {n_max}: the lowest whole division of the slowest channel's rate at or above "
                f"{DEFAULT_FS:g} Hz ({', '.join(f'{r:g}' for r in sorted(set(rates)) if not divides(fs, r))} Hz "
                "no whole multiple of it: read off by a cubic spline)")


def _span_and_rate(raw: dict, rec_ch: dict, measured: list, fs, path: Path, warns: list):
    """``(t_first, t_last, fs, rule)``: the time all measured channels cover, the model rate (default:
    :func:`default_rate`) and how it was chosen."""
    t_first = max(s.time[0] for c, s in raw.items() if c in CHANNELS)
    t_last = min(s.time[-1] for c, s in raw.items() if c in CHANNELS)
    if t_last - t_first <= 0:
        raise DataError(f"{path}: the channels do not overlap in time")
    rates = [rec_ch[c]["rate_hz"] for c in measured]
    rate_min = min(rates)
    if fs is None:
        fs, rule = default_rate(rates)
    else:
        rule = "[preprocess] fs"
    if fs > rate_min * 1.0001:
        _warn(warns, f"{path}: resampling to {fs:g} Hz, above the slowest channel's rate ({rate_min:g} Hz): "
                     "that channel carries nothing above its own Nyquist frequency", _STAGE)
    return t_first, t_last, fs, rule


#: the lead-in is not stationary when its RMS exceeds this share of the run's ...
LEAD_IN_RUN_SHARE = 0.25
#: ... and this multiple of the quietest stretch of the run as long as the lead-in (the noise floor)
LEAD_IN_FLOOR_FACTOR = 2.0


def quietest_rms(values: np.ndarray, n: int) -> float:
    """The least RMS about the mean of any ``n`` consecutive samples (windows every ``n // 2``): the noise floor.

    Where the car stands still at some time of the recording this is the
    sensor's noise over a lead-in's length; on a channel the run does not
    excite (a roll rate on a washboard) it is about the whole run's RMS.
    """
    v = np.asarray(values, dtype=float)
    n = max(int(n), 3)
    if v.size <= n:
        return float(np.std(v))
    v = v - np.mean(v)  # sums of squares about zero: no cancellation for a bias of g
    c1 = np.concatenate([[0.0], np.cumsum(v)])
    c2 = np.concatenate([[0.0], np.cumsum(v * v)])
    a = np.arange(0, v.size - n + 1, max(n // 2, 1))
    mean = (c1[a + n] - c1[a]) / n
    var = (c2[a + n] - c2[a]) / n - mean ** 2
    return float(np.sqrt(max(float(np.min(var)), 0.0)))


def lead_in_moving(rms_lead: float, rms_run: float, floor: float) -> bool:
    """Is the lead-in clearly not at rest?

    Its RMS (about its mean) must exceed both :data:`LEAD_IN_RUN_SHARE` of
    the run's RMS (a share of the signal that matters) and
    :data:`LEAD_IN_FLOOR_FACTOR` times the noise floor, the RMS of the
    quietest stretch of the run as long as the lead-in
    (:func:`quietest_rms`). A lead-in at rest is the noise floor (the
    floor's own scatter between stretches is well below a factor 2 for
    hundreds of samples, white or coloured noise), whatever the run's
    level: so a channel the run hardly excites, whose lead-in and run are
    both noise, is not flagged, while a lead-in set over moving data, with
    a standstill elsewhere in the recording, is.
    """
    return rms_lead > LEAD_IN_RUN_SHARE * rms_run and rms_lead > LEAD_IN_FLOOR_FACTOR * floor


def _remove_gravity_bias(raw: dict, rec_ch: dict, measured: list, lead, grav: bool, bias: bool, path: Path,
                         where_map: str, warns: list) -> None:
    """Subtract the lead-in mean (gravity and bias) from ``raw`` in place and note it in ``rec_ch``.

    Warns when the lead-in is not stationary (:func:`lead_in_moving`), except on a channel flat-lined.
    """
    for c in measured:
        s = raw[c]
        in_lead = (s.time >= lead[0]) & (s.time <= lead[1])
        is_acc = quantity(c) == "acceleration"
        if not ((grav and is_acc) or bias):
            continue
        if in_lead.sum() < 3:
            raise DataError(f"{where_map}: lead_in [{lead[0]:g}, {lead[1]:g}] s holds fewer than 3 samples of "
                            f"{c} (its time runs {s.time[0]:.6g} .. {s.time[-1]:.6g} s)")
        seg = s.values[in_lead]
        m = float(np.mean(seg))
        # a mean that is g in another unit is an error of the data checks (rideid.conditioning.wiring.unit_findings
        # reads the factor recorded here)
        unit_seen = gravity_unit_factor(m) if grav and is_acc else None
        if grav and is_acc and not (0.8 * GRAVITY < m < 1.2 * GRAVITY) and unit_seen is None:
            if -1.2 * GRAVITY < m < -0.8 * GRAVITY:
                _warn(warns, f"{path}: {c}: reads {m:.3g} m/s^2 at rest (gravity included): mounted upside down? "
                             "set sign = -1 in its channel map", _STAGE)
            else:
                _warn(warns, f"{path}: {c}: lead-in mean {m:.3g} m/s^2 with gravity_included = true "
                             f"(expected about {GRAVITY:.2f}); check its unit and the lead_in window", _STAGE)
        whole = s.values - np.mean(s.values)
        rms_all = float(np.sqrt(np.mean(whole ** 2)))
        rms_lead = float(np.std(seg))
        # a flat-lined channel (warned of already) has no motion to find: its lead-in's "RMS" is rounding
        if not rec_ch[c].get("flat_lined") and lead_in_moving(rms_lead, rms_all, quietest_rms(s.values, seg.size)):
            _warn(warns, f"{path}: {c}: the lead-in [{lead[0]:g}, {lead[1]:g}] s is not stationary (RMS "
                         f"{rms_lead:.3g} vs {rms_all:.3g} over the run); set lead_in to a part at rest", _STAGE)
        raw[c] = Signal(s.time, s.values - m, s.unit)
        rec_ch[c]["removed"] = m
        rec_ch[c]["removed_as"] = "gravity and bias" if (grav and is_acc) else "bias"
        if unit_seen is not None:
            rec_ch[c]["gravity_unit_factor"] = unit_seen


def _filter_resample(raw: dict, rec_ch: dict, measured: list, fs: float, anti_alias: bool | None = None,
                     path: Path | None = None, warns: list | None = None):
    """Anti-alias filter each measured channel where asked and represent it for reading off at ``fs``.

    Returns ``(channels, added)``: name -> :class:`Resampled`, and name -> the tuple of
    :class:`rideid.model.sensors.AnalogFilter` this applied to the data, which the channel's sensor chain
    must apply to the model's channel too (every filter rideid applies, its model sees).

    ``anti_alias``: None (default) or False filters nothing: a channel whose rate is a whole multiple of
    ``fs`` is decimated, its samples at the model's times taken as they are. The model predicts
    instantaneous values at its samples, with all their high frequencies (the rigid-disc road input's
    harmonics reach the axles far above 0.4 fs on short wavelengths): data low-passed at 0.4 fs lack what
    the model keeps, and the residual then carries road-driven structure (every 400 -> 200 Hz logger run
    of an exactly modelled SUV was "not adequate"). Decimating folds the noise above the new Nyquist
    frequency into the band instead, which only adds to the noise. A rate that is no whole multiple is
    read off between its samples by the cubic spline, which the model does not see, and warned of (``warns``,
    naming ``path``, with the rate that would take its samples as they are). ``True`` low-passes every
    faster channel (for loggers with strong vibration the model does not describe): the analog Butterworth
    of order :data:`FILTER_ORDER` at :data:`FILTER_CUTOFF` ``fs``, run causally on the file's samples
    (first-order hold at the file's rate, :func:`rideid.model.sensors.discretise`), and the same analog
    filter joins the channel's sensor chain, where the model's channel passes it at ``fs`` (SPEC §11,
    ``lowpass``).

    Why a rate that is no whole multiple is not low-passed by default, the model through the same filter:
    at ``fs`` the model's version is approximate (its samples carry what lies above ``fs / 2`` folded into
    the band, and the hold between them errs near the corner). Measured on a van's 500 Hz runs read at
    200 Hz (``benchmarks/resample_mismatch.py``, docs/real-data.md): the data and the model's channel
    differ by up to 4.5 times 1 % sensor noise with the filter in both (5.9 with it in the data alone,
    the default before), 1.1 with the spline alone, 0 decimated to 250 Hz; the damper-curve fits cost
    0.000228, 0.000397, 0.000109 and 0.000108, with the twelve within 1.14 %, 0.22 %, 0.07 % and 0.017 %.
    """
    from scipy.signal import resample_poly

    channels, added, odd = {}, {}, []
    for c in measured:
        t, v, med = _uniform(raw[c].time, raw[c].values, rec_ch[c])
        src_fs = 1.0 / med
        ratio = src_fs / fs
        whole = abs(ratio - round(ratio)) < WHOLE_RATIO
        if src_fs > fs * 1.0001 and anti_alias:
            filt = AnalogFilter("lowpass", FILTER_CUTOFF * fs, FILTER_ORDER)
            v = discretise(filt, med).apply(v)
            added[c] = (filt,)
            rec_ch[c]["filter"] = (f"{filt.describe()} (anti-alias, {src_fs:g} -> {fs:g} Hz; Butterworth, causal); "
                                   "the model's channel passes the same filter")
        elif src_fs > fs * 1.0001 and whole:
            rec_ch[c]["decimated"] = f"1 sample in {int(round(ratio))} taken, not filtered"
        elif src_fs > fs * 1.0001:
            rec_ch[c]["interpolated"] = (f"{src_fs:g} -> {fs:g} Hz by a cubic spline (no whole multiple), not "
                                         "filtered")
        up = int(math.ceil(UPSAMPLE_TO * fs / src_fs - 1e-9)) if src_fs < fs * 0.9999 else 1
        if up > 1:  # a channel slower than fs: band-limited interpolation onto a fine grid
            v = resample_poly(v, up, 1, padtype="line", window=("kaiser", UPSAMPLE_BETA))
            rec_ch[c]["upsampled"] = f"x{up} (polyphase, Kaiser beta {UPSAMPLE_BETA:g})"
        channels[c] = Resampled(t[0], med / up, v)
        if src_fs > fs * 1.0001 and (not whole or anti_alias):
            odd.append(c)  # read off by the spline, or low-passed: neither is what the model gives at fs
    if odd and warns is not None:
        _warn(warns, _rate_warning(rec_ch, measured, odd, fs, anti_alias, path), _STAGE)
    return channels, added


def _uniform(t, v, rec: dict):
    """``(t, v, h)``: a channel's samples on a uniform clock of step ``h``: time stamps off a uniform clock by
    rounding taken as that clock, other non-uniform times put on a uniform grid by a cubic spline (each said in
    the channel's record ``rec``)."""
    med = float(np.median(np.diff(t)))
    h_clock = uniform_clock(t)
    if h_clock is not None and np.max(np.abs(np.diff(t) - med)) > 1e-6 * med:
        dev = float(np.max(np.abs(t - (t[0] + h_clock * np.arange(t.size)))))
        rec["clock"] = (f"time stamps off a uniform clock by up to {dev / h_clock:.2g} of a sample "
                        "(rounded): taken as that clock, not interpolated")
        med = h_clock
    elif h_clock is None and np.max(np.abs(np.diff(t) - med)) > 1e-6 * med:
        from scipy.interpolate import make_interp_spline
        n = int(math.floor((t[-1] - t[0]) / med)) + 1
        tu = t[0] + med * np.arange(n)
        v = make_interp_spline(t, v, k=3)(tu)
        rec["regridded"] = "non-uniform time put on a uniform grid (cubic spline)"
    return t, v, med


def _rate_warning(rec_ch: dict, measured: list, odd: list, fs: float, anti_alias, path) -> str:
    """The warning of :func:`_filter_resample` for the channels ``odd`` (read off by the spline, or low-passed):
    what was done at which rates, and the rate or logging that would take every sample as it is."""
    rates = sorted({rec_ch[c]["rate_hz"] for c in measured})
    fs_ok, _ = default_rate(rates)
    odd_rates = sorted({rec_ch[c]["rate_hz"] for c in odd})
    fix = (f"set [preprocess] fs = {fs_ok:g} ({'/'.join(f'{r:g}' for r in rates)} Hz taken 1 sample in "
           f"{'/'.join(str(int(round(r / fs_ok))) for r in rates)}: nothing filtered)"
           if all(abs(r / fs_ok - round(r / fs_ok)) < WHOLE_RATIO for r in rates) else
           "log every channel at one rate (or at rates with a common whole division of at least "
           f"{DEFAULT_FS:g} Hz) and leave fs to rideid")
    which = "all 10 channels" if len(odd) == len(CHANNELS) else ", ".join(odd)
    at = f"{path}: {which} at {'/'.join(f'{r:g}' for r in odd_rates)} Hz"
    if anti_alias:
        return (f"{at}: low-passed at {FILTER_CUTOFF * fs:g} Hz for the model's {fs:g} Hz (anti_alias = true), the "
                "model's channels through the same filter, which at this rate it reproduces only roughly (up to "
                "several times the sensor noise on short wavelengths, and tire rates 1 % off on a van, "
                f"docs/real-data.md); {fix.replace('set [preprocess] fs', 'leave anti_alias out and set fs')}")
    return (f"{at}: no whole multiple of the model's {fs:g} Hz, so read off between its samples by a cubic "
            "spline the model does not see (about the sensor noise on short wavelengths, docs/real-data.md); "
            f"{fix}")


def rate_record(rec_ch: dict, measured: list, fs: float, rule: str) -> dict:
    """The run's ``resampling`` record: the model rate, the rule that chose it, and each filter rideid applied to
    the data, by kind, corner, order and channels, with whether the model's channels pass it too."""
    filters, groups = [], {}
    for c in measured:
        r = rec_ch[c]
        if "filter" in r:
            groups.setdefault(("lowpass", FILTER_CUTOFF * fs, FILTER_ORDER, r["rate_hz"]), []).append(c)
    for (kind, hz, order, src), chans in groups.items():
        filters.append({"kind": kind, "hz": hz, "order": order, "design": "analog Butterworth, causal",
                        "why": f"anti-alias, {src:g} -> {fs:g} Hz", "channels": chans, "model": True})
    for key, kind in (("upsampled", "interpolation"), ("interpolated", "cubic spline"), ("regridded", "cubic spline")):
        chans = [c for c in measured if key in rec_ch[c]]
        if chans:
            filters.append({"kind": kind, "what": rec_ch[chans[0]][key], "channels": chans, "model": False})
    rates = sorted({rec_ch[c]["rate_hz"] for c in measured})
    return {"fs": fs, "rule": rule, "file_rates_hz": rates,
            "decimated": {c: int(round(rec_ch[c]["rate_hz"] / fs)) for c in measured if "decimated" in rec_ch[c]},
            "filters": filters}


def _motion(raw: dict, targets: dict, speed: float | None, path: Path):
    """``(distance, record)``: distance from a distance or (integrated) speed channel; None at a constant speed."""
    distance, motion_rec = None, {}
    if "distance" in raw:
        s = raw["distance"]
        if np.any(np.diff(s.values) < -1e-6 * max(1.0, np.ptp(s.values))):
            raise DataError(f"{path}: distance channel '{targets['distance'].name}' decreases "
                            "(the car must not reverse)")
        distance = Distance(s.time, s.values)
        motion_rec = {"source": f"distance channel '{targets['distance'].name}' ({s.unit})"}
    elif "speed" in raw:
        s = raw["speed"]
        if np.min(s.values) < -0.1:
            raise DataError(f"{path}: speed channel '{targets['speed'].name}' goes negative "
                            f"({np.min(s.values):.3g} m/s); the car must not reverse")
        from scipy.integrate import cumulative_trapezoid
        d = cumulative_trapezoid(np.clip(s.values, 0, None), s.time, initial=0.0)
        distance = Distance(s.time, d)
        # white-noise level of the speed channel: second differences cancel a smooth speed (a driver's wander
        # of a few per cent over seconds leaves 1e-3 of the first differences' share), var = 6 sigma^2
        noise = float(np.std(np.diff(s.values, 2)) / math.sqrt(6.0)) if s.values.size > 3 else 0.0
        motion_rec = {"source": f"speed channel '{targets['speed'].name}' ({s.unit}), integrated",
                      "noise_std": noise, "noise_interval": float(np.median(np.diff(s.time)))}
    else:
        motion_rec = {"source": "constant", "value": speed}
    if distance is not None:
        vmin, vmean, vmax = distance.speed_range()
        motion_rec.update({"min": vmin, "mean": vmean, "max": vmax})
    return distance, motion_rec


def _plausibility(c, v, unit, opts, w, warns) -> bool:
    """Warn of what looks wrong in channel ``c``'s values ``v`` (SI); False when it is flat-lined."""
    ptp = float(np.ptp(v))
    if ptp == 0.0:
        _warn(warns, f"{w}: flat-lined (every sample is {v[0]:.6g}); check the sensor and its cable")
        return False
    for end, val in (("maximum", v.max()), ("minimum", v.min())):
        run = _longest_run(v == val)
        if run >= 3:
            _warn(warns, f"{w}: clipped: {run} consecutive samples at its {end} {val:.6g} "
                         f"(sensor or logger range exceeded?)")
    if quantity(c) == "acceleration" and not opts.get("gravity_included", False):
        m = float(np.mean(v))
        if 0.8 * GRAVITY < abs(m) < 1.2 * GRAVITY:
            _warn(warns, f"{w}: mean {m:.3g} m/s^2 is about g: the channel seems to include gravity; "
                         "set gravity_included = true in [preprocess]")
    if quantity(c) == "rate" and UNITS["rate"].get(unit.strip().replace(" ", "").lower()) == 1.0:
        peak = float(np.max(np.abs(v - np.median(v))))
        if peak > 3.0:
            _warn(warns, f"{w}: peaks at {peak:.3g} rad/s ({math.degrees(peak):.0f} deg/s), implausible for a "
                         "car body on a ride track: are the values in deg/s? set unit = \"deg/s\"")
    return True


__all__ = ["MeasuredRun", "RunData", "default_rate", "load_measured_run", "rate_record", "uniform_clock"]
