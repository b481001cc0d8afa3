"""The wiring checks: which channel the map really took, in which sign and unit, from the numbers alone.

Pure functions over a run's ``(n, 10)`` channel matrix (SPEC channel order,
SI units), its sample rate, the geometry and, where there is a road, a
nominal car's response on it (simulated by the caller,
:func:`rideid.conditioning.checks.check_dataset`). They return plain
results or :class:`rideid.data.checks.Finding` objects that name the
mistake and the ``[channels]`` entries that fix it.

* **Rigid body** (:func:`rigid_body_scores`): the four body accelerometers
  and the gyro measure one rigid body. With corners at ``x = a, -b`` and
  ``y = ±track/2``, the body accelerations are ``z'' - x θ'' + y φ''``, so

  - roll: ``(a_fl - a_fr) / track_front = (a_rl - a_rr) / track_rear = d/dt roll_rate``
  - pitch: ``((a_rl + a_rr) - (a_fl + a_fr)) / (2 wheelbase) = d/dt pitch_rate``

  independent of the CG and of every mass and stiffness. A swapped pair, a
  flipped sign or a unit factor (57.3 deg/rad, 9.81 m/s² per g) breaks these
  identities; the hypothesis that restores them names the mistake, with no
  model at all.
* **Assignment to the road** (:func:`assignment`): each axle channel follows
  its own wheel path's road input (front before rear by wheelbase/speed; left
  and right as the track's asymmetry dictates). Correlating every measured
  channel with every channel of a nominal car's response on the run's track
  tells which permutation and signs of the channels the road supports; it
  also breaks the rigid-body check's ties (front/rear body swap versus a
  flipped pitch gyro). :func:`wiring_fix` combines the two.
* **Units** (:func:`unit_findings`,
  :func:`rideid.data.schema.channels.gravity_unit_factor`): with
  ``gravity_included`` an acceleration reads about g at rest. A lead-in mean of about 1 m/s² is g
  mapped as m/s², of about 96 m/s² m/s² mapped as g: for every
  acceleration channel, axle ones too, which the rigid-body identities do
  not cover. Without gravity (:func:`axle_amplitude_findings`), an axle
  channel whose amplitude against the nominal car's on the same road is
  about g times its siblings' (or the body channels') is in the wrong unit.
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np

from ..settings import defaults, legacy_names
from ..data.checks import ERROR, WARNING, Finding, MapFix
from ..data.schema.channels import UNITS, quantity
from ..model.equations import CHANNELS

G0 = 9.80665
DEG = 180.0 / math.pi


# ---------------------------------------------------------------------------
# Rigid body: body accelerometers against the gyro

#: low-pass corner of the rigid-body check, Hz (ride content lies below it; sensor noise above)
RIGID_BODY_FC = 10.0


def lowpass_gram(X: np.ndarray, fs: float, fc: float = RIGID_BODY_FC) -> np.ndarray:
    """Gram matrix ``Xf @ Xf.T`` of the signals after a zero-phase low-pass.

    The low-pass is a fourth-order Butterworth applied forwards and
    backwards (power response ``|H|^2 = 1 / (1 + (f/fc)^8)``), the filter
    ``scipy.signal.sosfiltfilt`` applies; by Parseval the Gram matrix of the
    filtered signals is the cross-spectrum weighted by ``|H|^4``, computed
    here from one zero-padded FFT (no circular wrap-around). The ends differ
    from ``sosfiltfilt``'s (it pads by reflection), by far less than the
    rigid-body check can resolve; it spares the check the 1 s import of
    ``scipy.signal``.

    Parameters
    ----------
    X : (k, n) array
        Signals, one per row.
    fs, fc : float
        Sample rate and corner frequency, Hz (``fc`` at most ``0.3 fs``).

    Returns
    -------
    G : (k, k) array
    """
    n = X.shape[-1]
    if n < 30:  # too short to filter: the plain Gram matrix
        return X @ X.T
    fc = min(fc, 0.3 * fs)
    nfft = 1 << int(2 * n - 1).bit_length()
    F = np.fft.rfft(X, n=nfft, axis=-1)
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    w = 1.0 / (1.0 + (f / fc) ** 8) ** 2
    w[1:(nfft + 1) // 2] *= 2.0  # the negative frequencies; DC and Nyquist once
    return ((F * w) @ F.conj().T).real / nfft


#: relative factors a mapped gyro can be off by (values too small by 57.3: rad/s mapped as deg/s, ...)
GYRO_FACTORS = (1.0, DEG, 1 / DEG, G0, 1 / G0)


def _hypotheses(has_gyro: bool):
    """Every (body permutation, body factors, gyro factor, pitch sign, roll sign, gyro swap).

    Body factors are signs, or one channel off by g (a single accelerometer in
    the wrong unit; all four off by g is the gyro factor's inverse).
    """
    perms = list(itertools.permutations(range(4)))
    signs = list(itertools.product((1.0, -1.0), repeat=4))
    units = []
    for c in range(4):
        for f in (G0, 1 / G0):
            for s in signs:
                units.append(tuple(s[k] * (f if k == c else 1.0) for k in range(4)))
    body = [(p, s) for p in perms for s in signs] + [(tuple(range(4)), u) for u in units]
    if not has_gyro:
        return [(p, s, 1.0, 1.0, 1.0, False, False) for p, s in body]
    hyps = [(p, s, f, sp, sr, sw, False) for p, s in body for f in GYRO_FACTORS
            for sp in (1.0, -1.0) for sr in (1.0, -1.0) for sw in (False, True)]
    # one gyro channel in another unit than the other (body channels only signed)
    for s in signs:
        for fp in GYRO_FACTORS:
            for fr in GYRO_FACTORS:
                if fp != fr:
                    hyps += [(tuple(range(4)), s, 1.0, fp * sp, fr * sr, False, False)
                             for sp in (1.0, -1.0) for sr in (1.0, -1.0)]
    return hyps


def _rename_hypotheses(F, has_gyro: bool):
    """Names permuted in the map while each entry's unit, sign and scale stay put.

    ``F``: (10,) the factor (unit x sign x scale) each SPEC channel was read
    with. If the file channel of entry ``p(c)`` really is channel ``c``,
    then ``true_c = F_c / F_p(c) * loaded_p(c)``.
    """
    out = []
    for p in itertools.permutations(range(4)):
        sg = tuple(F[c] / F[p[c]] for c in range(4))
        for sw in ((False, True) if has_gyro else (False,)):
            sp = F[8] / F[9 if sw else 8] if has_gyro else 1.0
            sr = F[9] / F[8 if sw else 9] if has_gyro else 1.0
            out.append((p, sg, 1.0, sp, sr, sw, True))
    return out


def _transforms(hyps) -> np.ndarray:
    """(H, 6, 6): corrected signals = T @ raw signals, for each hypothesis."""
    T = np.zeros((len(hyps), 6, 6))
    for h, (perm, sg, f, sp, sr, sw, _) in enumerate(hyps):
        T[h, np.arange(4), perm] = sg
        T[h, 4, 5 if sw else 4] = f * sp
        T[h, 5, 4 if sw else 5] = f * sr
    return T


@functools.lru_cache(maxsize=2)
def _base_transforms(has_gyro: bool):
    hyps = tuple(_hypotheses(has_gyro))
    return hyps, _transforms(hyps)


def _constraints(has_gyro: bool, tf: float, tr: float, L: float) -> np.ndarray:
    """Rigid-body constraints on the corrected signals ``[b_fl, b_fr, b_rl, b_rr, pitch'', roll'']``."""
    if has_gyro:
        return np.array([[1 / tf, -1 / tf, 0, 0, 0, -1],
                         [0, 0, 1 / tr, -1 / tr, 0, -1],
                         [-1 / (2 * L), -1 / (2 * L), 1 / (2 * L), 1 / (2 * L), -1, 0]])
    return np.array([[1 / tf, -1 / tf, -1 / tr, 1 / tr, 0, 0]])


@functools.lru_cache(maxsize=4)
def _base_coefficients(has_gyro: bool, tf: float, tr: float, L: float):
    """Every base hypothesis's constraint coefficients on the raw signals, (H, k, 6): one per geometry."""
    hyps, T0 = _base_transforms(has_gyro)
    C = np.matmul(_constraints(has_gyro, tf, tr, L)[None], T0)
    C.flags.writeable = False
    return hyps, C


def _relative_residuals(C, G):
    """Mean over the constraints of ``c^T G c / sum_i c_i^2 G_ii`` for each hypothesis's rows ``C`` (H, k, 6)."""
    num = np.sum((C.reshape(-1, 6) @ G).reshape(C.shape) * C, axis=-1)
    den = (C * C) @ np.diag(G)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    return e.mean(axis=1)


def rigid_body_scores(Y: np.ndarray, fs: float, geom, F=None):
    """Rigid-body residual of every wiring hypothesis.

    Parameters
    ----------
    Y : (n, 10) array
        The run's channels in SPEC order (SI units), NaN where missing.
    fs : float
        Sample rate, Hz.
    geom : Geometry

    Returns
    -------
    F : (10,) array, optional
        The factor (unit x sign x scale) each channel was read with: adds
        the hypotheses "names swapped in the map" (:func:`_rename_hypotheses`).
    hyps : list of tuples, or None when the body channels are incomplete
        ``(perm, signs, gyro_factor, pitch_sign, roll_sign, gyro_swapped, renamed)``;
        the corrected ``body[c] = signs[c] * Y[:, perm[c]]``, the corrected
        pitch rate ``gyro_factor * pitch_sign * (roll_rate if swapped else
        pitch_rate)``, likewise roll.
    scores : (H,) array
        Mean relative residual of the rigid-body identities (roll front, roll
        rear, pitch; without a gyro the warp ``roll front = roll rear``):
        0 is a perfect rigid body, about 1 unrelated signals.
    """
    present = ~np.all(np.isnan(Y), axis=0)
    if not present[:4].all():
        return None, None
    has_gyro = bool(present[8] and present[9])
    X = np.nan_to_num(Y[:, [0, 1, 2, 3, 8, 9]].T, nan=0.0)
    X = X - X.mean(axis=1, keepdims=True)
    if has_gyro:
        X[4:] = np.gradient(X[4:], 1.0 / fs, axis=1)
    G = lowpass_gram(X, fs)
    geo = (has_gyro, float(geom.track_front), float(geom.track_rear), float(geom.wheelbase))
    base, C0 = _base_coefficients(*geo)  # (H, k, 6) coefficients on the raw signals
    hyps = list(base)
    scores = _relative_residuals(C0, G)
    if F is not None:
        extra = _rename_hypotheses(np.asarray(F, float), has_gyro)
        hyps += extra
        scores = np.concatenate([scores, _relative_residuals(np.matmul(_constraints(*geo)[None], _transforms(extra)),
                                                             G)])
    return hyps, scores


# ---------------------------------------------------------------------------
# Assignment: measured channels against a nominal car's response on the track

def _corr_matrix(Y, Yhat, idx):
    """corr(Y[:, i], Yhat[:, j]) for i, j in idx (NaN where a channel is missing or zero)."""
    C = np.full((len(idx), len(idx)), np.nan)
    for a, i in enumerate(idx):
        y = Y[:, i]
        if np.all(np.isnan(y)):
            continue
        ny = np.linalg.norm(y)
        for b, j in enumerate(idx):
            m = Yhat[:, j]
            nm = np.linalg.norm(m)
            if ny > 0 and nm > 0:
                C[a, b] = float(y @ m) / (ny * nm)
    return C


def best_assignment(C: np.ndarray):
    """The permutation and signs maximising the summed correlation ``sum_c s_c C[perm[c], c]``.

    ``C[i, j]``: measured channel ``i`` against model channel ``j``. Returns
    ``(perm, signs, score, identity_score)``; ``perm[c]`` is the measured
    channel that best serves as channel ``c``.
    """
    n = C.shape[0]
    Cz = np.nan_to_num(C, nan=0.0)
    ident = float(np.trace(Cz))
    best = (tuple(range(n)), (1.0,) * n, ident)
    for perm in itertools.permutations(range(n)):
        vals = np.array([Cz[perm[c], c] for c in range(n)])
        s = np.where(vals < 0, -1.0, 1.0)
        score = float(np.sum(np.abs(vals)))
        if score > best[2] + 1e-9:
            best = (perm, tuple(s), score)
    return best[0], best[1], best[2], ident


def assignment(Y: np.ndarray, Yhat: np.ndarray):
    """Best re-wiring per channel group (body 0-3, axles 4-7, gyro 8-9) by correlation with ``Yhat``.

    Returns a dict group -> (channel indices, perm, signs, score, identity score, C).
    """
    out = {}
    for name, idx in (("body", [0, 1, 2, 3]), ("axle", [4, 5, 6, 7]), ("gyro", [8, 9])):
        C = _corr_matrix(Y, Yhat, idx)
        perm, signs, score, ident = best_assignment(C)
        out[name] = (idx, perm, signs, score, ident, C)
    return out


def _track_score(hyp, A):
    """Summed correlation with the nominal response of a rigid-body hypothesis's body and gyro channels."""
    perm, sg, f, sp, sr, sw, _ = hyp
    Cb = np.nan_to_num(A["body"][5], nan=0.0)
    Cg = np.nan_to_num(A["gyro"][5], nan=0.0)
    s = sum(sg[c] * Cb[perm[c], c] for c in range(4))
    s += sp * Cg[1 if sw else 0, 0] + sr * Cg[0 if sw else 1, 1]
    return float(s)


def _n_changes(hyp):
    perm, sg, f, sp, sr, sw, renamed = hyp
    if renamed:
        return sum(perm[c] != c for c in range(4)) + 2 * sw
    return (sum(perm[c] != c for c in range(4)) + sum(s < 0 for s in sg) + sum(abs(s) != 1 for s in sg)
            + (f != 1.0) + (sp < 0) + (sr < 0) + 2 * sw)


def _rigid_fix(hyp) -> dict:
    """The channel fix of one rigid-body hypothesis (only the channels it changes)."""
    perm, sg, f, sp, sr, sw, renamed = hyp
    fix = {}
    for c in range(4):
        if perm[c] != c or (sg[c] != 1.0 and not renamed):
            fix[CHANNELS[c]] = {"source": CHANNELS[perm[c]], "factor": sg[c], "renamed": renamed}
    for c, src, s in ((8, 9 if sw else 8, sp), (9, 8 if sw else 9, sr)):
        if src != c or (f * s != 1.0 and not renamed):
            fix[CHANNELS[c]] = {"source": CHANNELS[src], "factor": f * s, "renamed": renamed}
    return fix


def wiring_fix(Y: np.ndarray, Yhat: np.ndarray | None, fs: float, geom, F=None, unit_known=()):
    """The re-wiring the data support, or None when the map is right.

    The rigid-body identities pick the consistent hypotheses (and the unit
    factors, which correlation cannot see); the correlation with the nominal
    car's response on the track picks among them (front/rear swap versus a
    flipped pitch gyro) and assigns the axle channels.

    ``Yhat`` None (a run on an unknown road, SPEC §9): the rigid-body
    identities alone. Among the hypotheses that restore them equally the one
    with the fewest changes is taken, and the others are listed under
    ``"alternatives"`` (a front/rear swap of the body channels and a flipped
    pitch gyro look alike without a road); the axle channels are not checked.

    ``unit_known``: channels whose unit the lead-in has confirmed
    (:func:`lead_in_units`); no hypothesis puts one of them in another
    unit, so the wiring check never says "wrong unit" where the lead-in says
    "unit right".

    Returns
    -------
    dict or None
        ``{"fix": {channel: {"source": channel, "factor": f}}, "rigid": (before, after),
        "track": (before, after)}`` listing only the channels that change.
    """
    fix = {}
    info = {}
    A = assignment(Y, Yhat) if Yhat is not None else None
    hyps, scores = rigid_body_scores(Y, fs, geom, F)
    known = [c for c in range(4) if CHANNELS[c] in unit_known]
    if hyps is not None and known:  # as arrays: a loop over the ~10^5 hypotheses took 0.1-0.2 s a run
        signs = np.array([h[1] for h in hyps], dtype=float)[:, known]
        renamed = np.array([bool(h[6]) for h in hyps])
        scores = np.where(~renamed & np.any(np.abs(np.abs(signs) - 1.0) > 1e-9, axis=1), np.inf, scores)
    if hyps is not None:
        ident = 0
        e_id = float(scores[ident])
        e_best = float(scores.min())
        if e_id > defaults["wiring.rigid_ok"] and e_best < e_id / 10:
            tie = np.nonzero(scores <= max(2.0 * e_best, e_best + 0.01))[0]
            h = max(tie, key=lambda k: (round(_track_score(hyps[k], A), 1) if A is not None else 0.0,
                                        -_n_changes(hyps[k])))
            fix = _rigid_fix(hyps[h])
            info["rigid"] = (e_id, float(scores[h]))
            if A is None:
                alts = []
                for k in sorted(tie, key=lambda k: _n_changes(hyps[k])):
                    alt = _rigid_fix(hyps[k])
                    if alt and alt != fix and alt not in alts:
                        alts.append(alt)
                if alts:
                    info["alternatives"] = alts
        elif e_id > defaults["wiring.rigid_bad"]:
            info["rigid_inconsistent"] = (e_id, e_best)
    elif A is not None:
        # no complete body set: signs and order of the body and gyro channels from the track alone
        for g in ("body", "gyro"):
            idx, perm, signs, score, ident, C = A[g]
            if score - ident > defaults["wiring.assign_margin"] and score / len(idx) > 0.5:
                for c in range(len(idx)):
                    if perm[c] != c or signs[c] != 1.0:
                        fix[CHANNELS[idx[c]]] = {"source": CHANNELS[idx[perm[c]]], "factor": signs[c]}
    if A is not None:
        idx, perm, signs, score, ident, C = A["axle"]
        if score - ident > defaults["wiring.assign_margin"] and score / 4 > 0.5:
            # names swapped in the map (each entry's unit and sign stay) when that explains the signs too
            renamed = F is not None and all(np.sign(F[idx[c]] / F[idx[perm[c]]]) == signs[c] for c in range(4))
            for c in range(4):
                if perm[c] != c or (signs[c] != 1.0 and not renamed):
                    f = F[idx[c]] / F[idx[perm[c]]] if renamed else signs[c]
                    fix[CHANNELS[idx[c]]] = {"source": CHANNELS[idx[perm[c]]], "factor": f, "renamed": renamed}
            info["axle"] = (ident, score)
    if not fix:
        return {"fix": {}, **info} if info else None
    return {"fix": fix, **info}


def corrected(Y: np.ndarray, fix: dict) -> np.ndarray:
    """``Y`` with a wiring fix applied."""
    Z = Y.copy()
    for c, e in fix.items():
        Z[:, CHANNELS.index(c)] = e["factor"] * Y[:, CHANNELS.index(e["source"])]
    return Z


def describe_fix(fix: dict) -> str:
    """Plain words for a wiring fix: 'axle_az_fl and axle_az_rl swapped', 'pitch_rate sign flipped', ..."""
    parts, done = [], set()
    for c, e in fix.items():
        if c in done:
            continue
        src, f = e["source"], e["factor"]
        other = fix.get(src)
        if e.get("renamed"):
            if other and other["source"] == c:
                parts.append(f"the file channels of {c} and {src} are swapped in the map")
                done |= {c, src}
            else:
                parts.append(f"{c} takes the file channel mapped to {src}")
                done.add(c)
            continue
        if (src != c and other and other["source"] == c and abs(abs(f) - 1) < 1e-9
                and abs(abs(other["factor"]) - 1) < 1e-9):
            s = "" if f > 0 and other["factor"] > 0 else " (and a sign)"
            parts.append(f"{c} and {src} swapped{s}")
            done |= {c, src}
            continue
        words = []
        if src != c:
            words.append(f"{c} is the file's {src} channel")
        a = abs(f)
        if abs(a - DEG) < 1e-6 * DEG:
            words.append(f"{c} reads 57.3x too small (rad/s mapped as deg/s?)")
        elif abs(a - 1 / DEG) < 1e-9:
            words.append(f"{c} reads 57.3x too large (deg/s mapped as rad/s?)")
        elif abs(a - G0) < 1e-6:
            words.append(f"{c} reads 9.81x too small (g mapped as m/s^2?)")
        elif abs(a - 1 / G0) < 1e-9:
            words.append(f"{c} reads 9.81x too large (m/s^2 mapped as g?)")
        if f < 0:
            words.append(f"{c} has its sign flipped")
        parts.append(", ".join(words) if words else c)
        done.add(c)
    return "; ".join(parts)


# ---------------------------------------------------------------------------
# Units: an acceleration whose lead-in reads g in another unit

def unit_findings(run_id: str, entries: dict, record: dict, level: str = "error") -> list[Finding]:
    """Acceleration channels mapped in the wrong unit, seen in the gravity their lead-in reads.

    Parameters
    ----------
    run_id : str
    entries : dict
        SPEC channel -> map entry the run was read with (:func:`rideid.conditioning.checks._map_entries`).
    record : dict
        SPEC channel -> its preprocessing record (``removed``: the lead-in
        mean subtracted, ``removed_as``: ``"gravity and bias"`` when gravity
        was included, ``gravity_unit_factor``: the factor that makes that
        mean gravity when a unit mistake explains it,
        :func:`rideid.data.schema.channels.gravity_unit_factor`, recorded
        when the run was read; a ``flat_lined`` channel is dead, not in a
        wrong unit).
    level : {"error", "warn"}
        The run's ``[checks] wiring`` level: errors, or warnings at ``"warn"``.

    Returns
    -------
    list of Finding (check "wiring"), one per channel, with the fix
    """
    out, severity = [], ERROR if level == "error" else WARNING
    for c, rec in record.items():
        if c not in CHANNELS or rec.get("removed_as") != "gravity and bias" or rec.get("flat_lined"):
            continue
        f = rec.get("gravity_unit_factor")
        if f is None:
            continue
        fix = {c: {"source": c, "factor": f}}
        out.append(Finding(severity, "wiring", f"run '{run_id}': {describe_fix(fix)}: its lead-in reads "
                           f"{rec['removed']:.3g} m/s^2 with gravity included, g is {G0:.2f}", run_id, c, fix,
                           MapFix(tuple(fix_entries(fix, entries)), level=level)))
    return out


def lead_in_units(record: dict) -> set:
    """The acceleration channels whose unit the lead-in confirms: with gravity included it read about ±g.

    ``record``: SPEC channel -> its preprocessing record (as :func:`unit_findings`). A channel whose lead-in
    mean lies within ±20 % of g (upside down or not) is in the unit it was mapped with; the checks then name
    no unit mistake on it (a swapped cable or a start off explains what else looks wrong).
    """
    return {c for c, rec in record.items()
            if c in CHANNELS and rec.get("removed_as") == "gravity and bias" and not rec.get("flat_lined")
            and 0.8 * G0 < abs(float(rec.get("removed", 0.0))) < 1.2 * G0}


def axle_amplitude_findings(run_id: str, entries: dict, Y: np.ndarray, Yhat: np.ndarray | None,
                            skip=(), level: str = "error") -> list[Finding]:
    """Axle accelerometers in the wrong unit, seen in their amplitude (gravity removed or not logged).

    Without a lead-in reading g, a hub channel in g mapped as m/s^2 is only
    9.81x too small. Each axle channel's RMS over the nominal car's response
    on the same road is compared with that of the other axle channels (or,
    when every hub channel is off by the same factor, with the body
    channels', which the rigid-body identities have checked): a ratio of
    about g (within setting ``wiring.amplitude_band``) is a unit mistake, since cars
    differ from the nominal car by far less.

    On a road nobody measured (SPEC §9: ``Yhat`` None, no nominal response) the hub channels' own RMS are
    compared: the four wheels ride one road of one class, left and right its two tracks, the rear the front's
    wheel paths, so their amplitudes differ by the unsprung masses' and the tracks' differences (0.89-1.12 of
    the others' median on the tests' ISO roads and the shared van's), not by g. Every hub off alike cannot be
    seen there (the body channels' amplitude is the car's, not the hubs').

    Returns one finding (check "wiring") per channel, with the fix, as
    :func:`unit_findings` (a warning at ``level`` ``"warn"``).
    """
    r = np.array([_rms_ratio(Y, Yhat, i) for i in range(len(CHANNELS))])
    axles = [i for i in range(4, 8) if np.isfinite(r[i]) and r[i] > 0 and CHANNELS[i] not in skip]
    body = np.nanmedian(r[:4]) if Yhat is not None and np.any(np.isfinite(r[:4])) else np.nan

    def factor(q, band=defaults["wiring.amplitude_band"]):
        for f in (G0, 1 / G0):  # the factor that restores the channel: q is about 1/f
            if 1 / band < q * f < band:
                return f
        return None

    flagged = {}
    for i in axles:
        others = [r[j] for j in axles if j != i]
        ref = float(np.median(others)) if len(others) >= 2 else body
        if not np.isfinite(ref) or ref <= 0:
            continue
        f = factor(r[i] / ref)
        if f is None and len(others) >= 2 and np.isfinite(body) and body > 0:
            # every hub off alike: against the body channels, whose ratio to the nominal car differs more
            f = factor(r[i] / body, 2.0) if factor(ref / body, 2.0) is not None else None
        if f is not None:
            flagged[CHANNELS[i]] = f
    out, severity = [], ERROR if level == "error" else WARNING
    for c, f in flagged.items():
        fix = {c: {"source": c, "factor": f}}
        i = CHANNELS.index(c)
        seen = (f"its amplitude is {r[i]:.3g}x the nominal car's on this road, the other channels' about "
                f"{r[i] * f:.3g}x" if Yhat is not None else
                f"its RMS is {r[i]:.3g} m/s^2 as mapped, the other hub channels' about {r[i] * f:.3g} on the same "
                "road (a road nobody measured: the hubs compared with each other)")
        out.append(Finding(severity, "wiring", f"run '{run_id}': {describe_fix(fix)}: {seen}", run_id, c, fix,
                           MapFix(tuple(fix_entries(fix, entries)), level=level)))
    return out


def _rms_ratio(Y: np.ndarray, Yhat: np.ndarray | None, i: int) -> float:
    """RMS of measured channel ``i`` over the nominal car's on the same road (``Yhat`` None: its own RMS; NaN:
    missing or no response)."""
    y = Y[:, i]
    if np.all(np.isnan(y)):
        return float("nan")
    den = 1.0 if Yhat is None else float(np.sqrt(np.mean(Yhat[:, i] ** 2)))
    return float(np.sqrt(np.nanmean(y * y))) / den if den > 0 else float("nan")


def gyro_or_accelerations(Y: np.ndarray, Yhat: np.ndarray, fix: dict) -> dict | None:
    """Which of the gyros or the accelerometers is off in scale, when the rigid-body identities say the two
    disagree by g (:func:`wiring_fix` proposes both gyro channels scaled by 1/g or g: all four body accelerations
    off by g look exactly like that), decided from absolute amplitudes against the nominal car on the same road.

    The rigid-body identities fix only the ratio of the two; the nominal car fixes the scale: a real car's
    response differs from the nominal one's by far less than g (:data:`AMPLITUDE_BAND`). The gyros' ratio to the
    nominal car and the accelerometers' (the median over the body and axle channels, and each axle channel
    judged on its own: hub sensors may be in the other unit) are compared under both hypotheses; the one that
    brings them within the band of the nominal car is taken. Returns None when ``fix`` is not that gyro scale;
    else ``{"side": "accelerations" | "gyros" | None (neither checks out), "channels": [...] (the accelerometers
    off), "factor": f (what restores them), "ratios": {channel: ratio}}``.
    """
    gy = [c for c in ("pitch_rate", "roll_rate") if c in fix]
    if not gy or any(c not in ("pitch_rate", "roll_rate") for c in fix) or any(
            fix[c]["source"] != c for c in gy):
        return None
    f = abs(float(fix[gy[0]]["factor"]))
    if not any(abs(f * k - 1.0) < 1e-6 for k in (G0, 1 / G0)) or any(abs(abs(fix[c]["factor"]) - f) > 1e-9 * f
                                                                         for c in gy):
        return None
    r = {c: _rms_ratio(Y, Yhat, i) for i, c in enumerate(CHANNELS)}
    gyro = float(np.nanmedian([r[c] for c in ("pitch_rate", "roll_rate")]))
    body = [c for c in CHANNELS[:4] if np.isfinite(r[c]) and r[c] > 0]
    if not body or not np.isfinite(gyro) or gyro <= 0:
        return None
    b = float(np.median([r[c] for c in body]))
    # the accelerometers off by 1/f (the gyro fix's inverse): the body ones for sure, an axle one when it reads
    # like the body ones rather than like the gyros
    axles = [c for c in CHANNELS[4:8] if np.isfinite(r[c]) and r[c] > 0
             and abs(np.log(r[c] / b)) < abs(np.log(r[c] / (b / f)))]
    acc = body + axles

    def fits(q):
        return 1 / defaults["wiring.amplitude_band"] < q < defaults["wiring.amplitude_band"]

    if fits(b / f) and fits(gyro) and all(fits(r[c] / f) for c in axles):
        side = "accelerations"
    elif fits(b) and fits(gyro * f):
        side = "gyros"
    else:
        side = None
    return {"side": side, "channels": acc, "factor": 1.0 / f, "ratios": r, "gyro_ratio": gyro, "body_ratio": b}


def fix_entries(fix: dict, entries: dict) -> list[str]:
    """``[channels]`` lines (TOML) that apply a wiring fix to the map the run was read with."""
    lines = []
    for c, e in fix.items():
        base = entries.get(e["source"])
        if base is None:
            continue
        if e.get("renamed"):  # only the file channel's name moves
            own = dict(entries[c], name=base["name"])
            parts = [f'name = "{own["name"]}"', f'unit = "{own["unit"]}"']
            if own["sign"] != 1:
                parts.append("sign = -1")
            if own["scale"] != 1:
                parts.append(f"scale = {own['scale']:g}")
            lines.append(f"{c} = {{ {', '.join(parts)} }}")
            continue
        f = e["factor"]
        sign = int(base["sign"] * (1 if f > 0 else -1))
        q = UNITS[quantity(c)]
        unit, scale = base["unit"], float(base["scale"])
        fu = base.get("file_unit")
        if fu and fu.strip().replace(" ", "").lower() in q and abs(abs(f) - 1) <= 1e-9:
            unit = fu  # a unit belongs to the file's channel: a swapped name takes its own unit along
        if abs(abs(f) - 1) > 1e-9:
            want = q.get(unit.strip().replace(" ", "").lower(), 1.0) * abs(f)
            named = [u for u, v in q.items() if abs(v - want) <= 1e-6 * want]
            if named:
                unit = named[0]
            else:
                scale *= abs(f)
        parts = [f'name = "{base["name"]}"', f'unit = "{unit}"']
        if sign != 1:
            parts.append("sign = -1")
        if scale != 1:
            parts.append(f"scale = {scale:g}")
        lines.append(f"{c} = {{ {', '.join(parts)} }}")
    return lines


__all__ = ["gyro_or_accelerations", "assignment",
           "axle_amplitude_findings", "best_assignment", "corrected", "describe_fix", "fix_entries",
           "lead_in_units", "lowpass_gram", "rigid_body_scores", "unit_findings", "wiring_fix"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "RIGID_OK": "wiring.rigid_ok", "RIGID_BAD": "wiring.rigid_bad", "ASSIGN_MARGIN": "wiring.assign_margin",
    "AMPLITUDE_BAND": "wiring.amplitude_band"})
