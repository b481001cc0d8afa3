"""Is the identified model adequate? Residual checks per run and channel, one verdict.

Three figures per run and channel (residual ``e = measured - simulated``):

level
    RMS of the residual over the run against the *noise floor*: the RMS of
    the residual while the car stands or rolls on flat road before the first
    wheel meets the track's feature (the model predicts zero there, so the
    residual is the sensor noise). ``level`` ~ 1: the fit is as good as the
    sensor allows; ``level`` >> 1: something else is in the residual.
whiteness
    The Ljung-Box portmanteau ``Q = T (T + 2) sum_{k=1}^{25} r_k^2 / (T - k)``
    of the residual's autocorrelations (as MATLAB's ``resid`` shows them,
    25 lags), with its chi-square(25) p-value. Reported, not decisive:
    real sensor noise is coloured, so a correct model need not leave white
    residuals.
input correlation (decisive)
    Sensor noise is independent of the road; a model that misses part of the
    car leaves a residual that is a filtered copy of the road input. The
    residual is prewhitened by its own AR model (order by BIC, at most
    setting ``adequacy.ar_max``), the same filter is applied to the regressors — the four
    wheel inputs and their rates at lags setting ``adequacy.lags`` — and an F-test asks
    whether they explain the whitened residual (with whitened residuals the
    test holds whatever the colour of the noise or of the road). A run and
    channel shows *structure* when the test rejects at setting ``adequacy.alpha``
    divided by the number of run/channel pairs (Bonferroni: a correct model
    is called inadequate in about 1 % of datasets) and the input explains at
    least setting ``adequacy.min_explained`` of the whitened residual's variance and the
    road-explained part (``sqrt(explained) * RMS(e)``) is at least
    setting ``adequacy.min_relative`` of the channel's RMS (so that neither a long run nor
    noise-free data, whose residual is a tiny but perfectly road-driven
    parameter offset, flag a negligible effect).

The model is adequate when no run and channel shows structure.

Power: the prewhitening also whitens away road-driven structure that is
predictable from the residual's own past (a slow sinusoid), so the test
detects broadband mismatch (a missed damper or bar driven by bumps and
ridges) much better than a slow periodic one; the level figure then still
shows it.
"""

from __future__ import annotations

import numpy as np
from scipy import special  # the two tail probabilities; scipy.stats takes 0.5 s to import

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...model.params import SUSPENSION_GROUPS as GROUPS
from ...model.batch import single_threaded_blas, thread_map
from ...model.equations import CHANNELS
from ..problem.cost import min_improvement



_ADVICE_HEAD = ("The residuals carry road-driven structure the model does not explain, so the estimates are "
                "biased by more than their error bars say. ")
_ADVICE_CHECKS = ("check that the track in dataset.toml (kind, start, height, wavelength) is the one driven and "
                  "that each run's start is right; check the run/channel pairs named above for a wrong sign, unit, "
                  "axis or a loose sensor.")
#: SPEC §13: the set-up first, which no model extension mends (a 1 % speed slip left the base model, and every
#: extension after it, not adequate, where its speed estimated with the car fits)
ADVICE_SETUP = ("the set-up first, which no model extension mends: each run's speed and start (declared values are "
                 "priors: result.json tracks.<track>.runs.<run>.motion and the load's warnings say where the data put "
                 "them), the sample rate, each channel's unit (accelerations in m/s^2, gyros in rad/s) and sign, and "
                 "its sensor chain (highpass, lowpass); ")
#: the advice when the model lacks extension groups and --model auto has not weighed them (see :func:`advice`)
ADVICE = (_ADVICE_HEAD + "Try " + ADVICE_SETUP + _ADVICE_CHECKS + " Then `rideid identify --model auto` (or "
          "`--model full`) to let anti-roll bars and tire damping in.")
#: added to the advice when the model has damper curves: where their straight segments miss the real curve
KNOT_ADVICE = ("The damper curves are straight between their knots: a real curve that bends between two knots "
               "leaves road-driven structure, so try knots where it bends (`[model] damper_knots` in dataset.toml, "
               "docs/dampers.md). ")
#: what the model may lack, by the group that adds it
_LACKS = (("damper_curves", "nonlinear dampers"), ("bump_stops", "bump stops"),
          ("powertrain", "a powertrain on mounts"))


def ljung_box(e, lags: int | None = None) -> tuple[float, float]:
    """Ljung-Box ``Q`` of ``e`` over ``lags`` autocorrelations and its chi-square p-value."""
    lags = defaults["adequacy.whiteness_lags"] if lags is None else lags
    e = np.asarray(e, dtype=float) - np.mean(e)
    T = e.size
    den = float(e @ e)
    if den == 0 or T <= lags + 1:
        return float("nan"), float("nan")
    r = np.array([e[k:] @ e[:-k] for k in range(1, lags + 1)]) / den
    Q = T * (T + 2) * float(np.sum(r * r / (T - np.arange(1, lags + 1))))
    return Q, float(special.chdtrc(lags, Q))


def fit_ar(e, max_order: int | None = None) -> np.ndarray:
    """AR coefficients ``a`` (``e_t = sum_k a_k e_{t-k} + w_t``) by least squares, order by BIC.

    Returns
    -------
    ndarray, shape (p,)
        ``p = 0`` (empty) when no order beats white noise.
    """
    max_order = defaults["adequacy.ar_max"] if max_order is None else max_order
    e = np.asarray(e, dtype=float) - np.mean(e)
    T = e.size
    best, best_bic = np.zeros(0), T * np.log(max(float(e @ e) / T, 1e-300))
    P = min(max_order, T // 10)
    if P < 1:
        return best
    # every order's regressors are leading columns of one lag matrix (rows from P on; the rows
    # p..P-1 an order p could also use are added to its normal equations below)
    L = np.column_stack([e[P - k:T - k] for k in range(0, P + 1)])  # column k: e lagged by k
    G = L.T @ L
    for p in range(1, P + 1):
        # normal equations of y = e[p:] on its p lags, rows p..T-1: rows P..T-1 from G, the rest added
        extra = np.column_stack([e[p - k:P - k] for k in range(0, p + 1)]) if p < P else np.zeros((0, p + 1))
        Gp = G[:p + 1, :p + 1] + extra.T @ extra
        try:
            a = np.linalg.solve(Gp[1:, 1:], Gp[1:, 0])
        except np.linalg.LinAlgError:
            a, *_ = np.linalg.lstsq(Gp[1:, 1:], Gp[1:, 0], rcond=None)
        y = e[p:]
        # the true residual, not a normal-equation estimate: rows p..P-1, then P..T-1 of the lag matrix, times
        # (1, -a)
        c = np.concatenate([[1.0], -a])
        rss = float(np.sum((extra @ c) ** 2) + np.sum((L[:, :p + 1] @ c) ** 2))
        bic = y.size * np.log(max(rss / y.size, 1e-300)) + p * np.log(y.size)
        if bic < best_bic:
            best, best_bic = a, bic
    return best


def whiten(x, a) -> np.ndarray:
    """Apply the AR prewhitening filter ``x_t - sum_k a_k x_{t-k}`` (drops the first ``len(a)`` samples)."""
    x = np.asarray(x, dtype=float)
    p = len(a)
    out = x[p:].copy()
    for k in range(1, p + 1):
        out -= a[k - 1] * x[p - k:x.shape[0] - k]
    return out


def lagged(U, lags=None) -> np.ndarray:
    """Regressors ``U[t - k]`` for every column and lag (zeros before the start), shape (T, n_col * n_lag)."""
    lags = defaults["adequacy.lags"] if lags is None else lags
    U = np.asarray(U, dtype=float)
    T = U.shape[0]
    cols = []
    for k in lags:
        Z = np.zeros_like(U)
        Z[k:] = U[:T - k]
        cols.append(Z)
    return np.concatenate(cols, axis=1)


def input_basis(U, lags=None) -> np.ndarray:
    """Orthonormal basis of the lagged road regressors of one run, shape (T, r).

    The columns of :func:`lagged` are centred (an intercept is in both
    models of the F-test) and scaled to unit deviation, so that the rank
    decision is unit-free; the rank ``r`` counts singular values above 1e-8
    of the largest (lagged smooth inputs are nearly collinear; a symmetric
    track gives identical left and right columns). Decided once per run:
    the regressors' span is the run's, whatever the residual's colour.
    """
    lags = defaults["adequacy.lags"] if lags is None else lags
    Z = lagged(U, lags)
    sd = Z.std(axis=0)
    keep = sd > 1e-12 * max(sd.max(), 1e-300)
    if not keep.any():
        return np.zeros((Z.shape[0], 0))
    Zs = (Z[:, keep] - Z[:, keep].mean(axis=0)) / sd[keep]
    Q, s, _ = np.linalg.svd(Zs, full_matrices=False)
    return Q[:, :int(np.sum(s > 1e-8 * s[0]))]


def input_correlation(e, U, lags=None, max_order: int | None = None, basis=None) -> dict:
    """F-test of the road inputs (lagged) on the prewhitened residual.

    Parameters
    ----------
    e : ndarray, shape (T,)
        Residual of one channel.
    U : ndarray, shape (T, k)
        Known inputs (wheel inputs in m, their rates in m/s).
    basis : ndarray, shape (T, r), optional
        :func:`input_basis` of ``U`` (shared by a run's channels).

    Returns
    -------
    dict
        ``F``, ``p`` (p-value), ``explained`` (adjusted share of the whitened
        residual variance the inputs explain, 0..1), ``df`` (regressors used),
        ``ar_order`` (of the prewhitening filter).
    """
    lags = defaults["adequacy.lags"] if lags is None else lags
    max_order = defaults["adequacy.ar_max"] if max_order is None else max_order
    e = np.asarray(e, dtype=float)
    Q = input_basis(U, lags) if basis is None else basis
    # the noise model is fitted to the residual itself: fitted to what the inputs leave unexplained
    # (feasible GLS) it loses the low-frequency noise that many smooth regressors soak up, under-whitens,
    # and the test rejects far too often (measured: 25 % at 5 % under AR(1) 0.9 noise)
    a = fit_ar(e, max_order)
    ew = whiten(e, a)
    # the whitening filter is linear: the whitened regressors span what the whitened basis spans
    Qw = whiten(Q, a)
    Qw -= Qw.mean(axis=0)
    n = ew.size
    y = ew - ew.mean()
    rss0 = float(y @ y)
    if Q.shape[1] == 0 or rss0 == 0:
        return {"F": 0.0, "p": 1.0, "explained": 0.0, "df": 0, "ar_order": len(a)}
    r, rss1 = _projection_rss(Qw, y, rss0)
    dfd = n - r - 1
    if dfd <= 0 or rss1 <= 0:
        return {"F": float("inf"), "p": 0.0, "explained": 1.0, "df": r, "ar_order": len(a)}
    F = ((rss0 - rss1) / r) / (rss1 / dfd)
    r2 = 1.0 - rss1 / rss0
    adj = 1.0 - (1.0 - r2) * (n - 1) / dfd
    return {"F": float(F), "p": float(special.fdtrc(r, dfd, F)), "explained": float(max(adj, 0.0)), "df": r,
            "ar_order": len(a)}


def _projection_rss(Z, y, yy):
    """Rank of ``Z`` and the residual sum of squares of ``y`` on its columns.

    ``Z`` is a whitened orthonormal basis, well conditioned unless the
    whitening filter nearly annihilates a direction: the eigen-decomposition
    of the Gram matrix ``Z^T Z`` (a r x r problem, ~20x cheaper than the SVD
    of the T x r ``Z``) is then exact to about ``eps * cond(Z)^2`` of ``yy``,
    directions below 1e-12 of the largest eigenvalue dropped. Where the
    regressors explain nearly all of ``y`` that bound is no longer small
    against the residual, and the SVD decides.
    """
    lam, V = np.linalg.eigh(Z.T @ Z)
    lam, V = lam[::-1], V[:, ::-1]
    keep = lam > 1e-12 * lam[0]
    c = V[:, keep].T @ (Z.T @ y)
    rss = yy - float(np.sum(c * c / lam[keep]))
    if rss > 1e-6 * yy:
        return int(keep.sum()), rss
    U_, s, _ = np.linalg.svd(Z, full_matrices=False)
    r = int(np.sum(s > 1e-6 * s[0]))
    fitted = U_[:, :r] @ (U_[:, :r].T @ y)
    return r, float(np.sum((y - fitted) ** 2))


def quiet_samples(U, tol: float = 1e-9) -> int:
    """Number of leading samples in which every input is (numerically) zero."""
    U = np.asarray(U, dtype=float)
    moving = np.any(np.abs(U) > tol * max(np.abs(U).max(), 1e-300), axis=1)
    return int(np.argmax(moving)) if moving.any() else U.shape[0]


def assess(runs: dict, channels, *, alpha: float | None = None, min_explained: float | None = None) -> dict:
    """Adequacy figures and verdict (module docstring).

    Parameters
    ----------
    runs : dict
        run id -> ``(E, Y, U)``: ``E`` residuals ``(T, 10)`` in
        :data:`rideid.CHANNELS` order (NaN for channels not measured), ``Y``
        the measured channels (same shape), ``U`` the known inputs ``(T, k)``
        (wheel inputs and their rates).
    channels : sequence of str
        The channel names of ``E``'s columns.
    alpha, min_explained : float
        Family-wise rate and effect size of the input-correlation test.

    Returns
    -------
    dict
        ``{"adequate", "reasons", "advice", "method", "alpha", "min_explained", "runs":
        {run: {channel: figures}}}``; JSON-ready.
    """
    alpha = defaults["adequacy.alpha"] if alpha is None else alpha
    min_explained = defaults["adequacy.min_explained"] if min_explained is None else min_explained

    with single_threaded_blas():  # many small SVDs: BLAS threads only contend
        return _assess(runs, channels, alpha, min_explained)


def _assess(runs, channels, alpha, min_explained):

    pairs = [(rid, c) for rid, (E, _, _) in runs.items() for c in range(E.shape[1]) if not np.all(np.isnan(E[:, c]))]
    alpha_each = alpha / max(len(pairs), 1)
    out_runs, flagged, loud = {}, [], []

    def one_run(item):
        rid, (E, Y, U) = item
        q = quiet_samples(U)
        basis = input_basis(U)
        rec, hits, noisy = {}, [], []
        for c, name in enumerate(channels):
            e = E[:, c]
            if np.all(np.isnan(e)):
                continue
            e = np.nan_to_num(e)
            rms = float(np.sqrt(np.mean(e * e)))
            floor = float(np.sqrt(np.mean(e[:q] ** 2))) if q >= defaults["adequacy.min_quiet"] else None
            Q, pq = ljung_box(e)
            ic = input_correlation(e, U, basis=basis)
            signal = float(np.sqrt(np.mean(np.nan_to_num(Y[:, c]) ** 2)))
            road_rel = np.sqrt(ic["explained"]) * rms / signal if signal > 0 else 0.0
            structure = bool(ic["p"] < alpha_each and ic["explained"] >= min_explained
                             and road_rel >= defaults["adequacy.min_relative"])
            rec[name] = {"rms": rms, "signal_rms": signal, "road_explained_rel": float(road_rel), "noise_floor": floor,
                         "level": (rms / floor) if floor else None,
                         "whiteness_q": Q, "whiteness_p": pq, "white": bool(pq >= 0.01),
                         "input_f": ic["F"], "input_p": ic["p"], "input_explained": ic["explained"],
                         "input_df": ic["df"], "ar_order": ic["ar_order"], "structure": structure}
            if structure:
                hits.append((ic["explained"], rid, name))
            if floor and rms / floor > 3:
                noisy.append((rms / floor, rid, name))
        return rid, rec, hits, noisy

    # runs on parallel threads (the SVDs and filters release the GIL), in order
    for rid, rec, f, lo in thread_map(one_run, runs.items(), "rideid-adequacy"):
        out_runs[rid] = rec
        flagged += f
        loud += lo
    adequate = not flagged
    reasons = []
    if flagged:
        flagged.sort(reverse=True)
        worst = ", ".join(f"{rid}/{name} ({100 * ex:.0f} %)" for ex, rid, name in flagged[:6])
        reasons.append(f"the road input explains part of the residual in {len(flagged)} of {len(pairs)} "
                       f"run/channel pairs (largest share of the whitened residual: {worst}): the model misses "
                       "road-driven dynamics")
    else:
        reasons.append(f"the residuals are not explained by the road input in any of {len(pairs)} run/channel pairs "
                       f"(F-test on prewhitened residuals, family-wise {alpha:.0%})")
    if loud:
        loud.sort(reverse=True)
        reasons.append("residual above 3x the quiet lead-in noise floor in "
                       + ", ".join(f"{rid}/{name} ({lv:.1f}x)" for lv, rid, name in loud[:6])
                       + (f" and {len(loud) - 6} more" if len(loud) > 6 else ""))
    n_white = sum(1 for rec in out_runs.values() for f in rec.values() if f["white"])
    reasons.append(f"{n_white} of {len(pairs)} residuals pass the whiteness test "
                   f"({defaults['adequacy.whiteness_lags']} lags, 1 %); coloured sensor "
                   "noise fails it without the model being wrong, so it does not decide")
    out = {"adequate": adequate, "reasons": reasons, "advice": None if adequate else ADVICE,
           "method": "F-test of the road inputs and rates (lags " + ",".join(map(str, defaults["adequacy.lags"]))
                     + " samples) on "
                     "the AR-prewhitened residual of every run and channel; Bonferroni over the pairs",
           "alpha": alpha, "min_explained": min_explained, "runs": out_runs}
    caveat = level_caveat(out)
    return out if caveat is None else dict(out, level_caveat=caveat)


@stage("adequacy")
def assess_fit(cf, P, sims=None) -> dict:
    """Adequacy of a full parameter row ``P`` on the data of a :class:`rideid.CostFunction`.

    The residuals are the unweighted ``measured - simulated`` channels; the
    inputs are the four wheel inputs and their rates of each run. ``sims``:
    ``cf.simulate(P)`` when the caller has it already.
    """

    sims = cf.simulate(P) if sims is None else sims
    runs = {}
    for ri, rid in enumerate(cf.run_ids):
        s, e = cf.sim.run_start[ri], cf.sim.run_start[ri + 1]
        Y = cf.Y[s:e].copy()
        Y[:, cf.W[ri] <= 0] = np.nan
        run = cf.sim.runs[ri]
        U = np.concatenate([run.u, run.rate], axis=1)
        E = Y - sims[rid]
        keep = getattr(cf, "keep", None)
        if keep is not None:  # samples at a channel's range are left out of the fit (SPEC §11): residual 0
            E = np.where(keep[s:e] > 0, E, 0.0)
        runs[rid] = (E, Y, U)
    return assess(runs, CHANNELS)


def level_caveat(adequacy: dict) -> str | None:
    """What an adequate verdict must add when the residual is well above the sensor noise in many run/channel
    pairs (setting ``adequacy.loud_share`` of those with a quiet lead-in) though the road-driven test finds nothing: the
    prewhitening takes away what the residual's own past predicts, so a slow miss (a roll stiffness the model
    lacks, at the roll mode) passes the F-test and shows only in the level figure, which does not decide
    (sensor noise may grow while driving). None when not adequate, or when few pairs are loud."""
    if not adequacy.get("adequate"):
        return None
    levels = [f["level"] for rec in adequacy.get("runs", {}).values() for f in rec.values()
              if f.get("level") is not None]
    loud = sum(1 for lv in levels if lv > 3)
    if not levels or loud < defaults["adequacy.loud_share"] * len(levels):
        return None
    return (f"the road-driven test finds nothing, but the residual is above 3x the lead-in's noise floor in {loud} "
            f"of {len(levels)} run/channel pairs: a model that misses slow dynamics (a roll or pitch stiffness, "
            "which the test on prewhitened residuals cannot see) leaves this, as does sensor noise that grows while "
            "driving; unless the latter, the estimates may be off by more than their error bars (check the set-up "
            "first: speeds, starts, sample rate, units, sensor chains; then fit the groups the model lacks, "
            "`--model` with damper_curves, anti_roll_bars, tire_damping or powertrain, and compare)")


def caveats(adequacy: dict | None) -> list[str]:
    """What keeps an adequate verdict from being a clean one (SPEC §12, §13): runs the verdict does not cover
    (``not_assessed``: runs on unknown roads), a residual level well above the sensor noise (``level_caveat``),
    tracks taken as drawn while the residuals hold road-driven structure (``tracks_caveat``), a declared set-up value
    the data contradicted at load (``setup_caveat``, :func:`setup_caveat`), error bars narrower than the cost's
    shape allows (``shape_caveat``, :mod:`rideid.estimate.assess.shape`). Empty when not
    adequate (the verdict already says not to trust the numbers) or when there are none. The terminal, the report
    and the adequacy record all read this list, so they say the same."""
    if not adequacy or not adequacy.get("adequate"):
        return []
    out = []
    runs = list(adequacy.get("not_assessed") or [])
    if runs:
        out.append(f"{len(runs)} run(s) not assessed ({', '.join(map(str, runs))}: on unknown roads, where rideid has "
                   "no residual test yet): the verdict covers the other runs only, and a misfit on these would not "
                   "show")
    for key in ("level_caveat", "tracks_caveat", "setup_caveat", "shape_caveat"):
        if adequacy.get(key):
            out.append(str(adequacy[key]))
    return out


def setup_slips(findings) -> list[dict]:
    """The declared speeds the data contradicted: a warning of the ``speed`` check at load (a declared speed more
    than 3 of its prior's std from the speed the lags show) or of the ``motion`` check on a speed (the speed
    estimated with the car beyond 3 prior std: a track as built, an unknown road; rideid.estimate.fit.anyroad), one
    ``{"run", "declared", "speed"}`` per run (m/s; None where the finding has no fix), the fit's speed where it
    estimated one (a ``motion`` finding), else the load's. ``findings``: :class:`rideid.data.checks.Finding`
    objects or their dicts (result.json ``checks``)."""
    out = []
    found = [f.to_dict() if hasattr(f, "to_dict") else f for f in findings or ()]
    for f in sorted(found, key=lambda f: f.get("check") != "motion"):  # the fit's estimate before the load's
        speed = f.get("check") == "speed" or (f.get("check") == "motion" and f.get("channel") == "speed")
        if speed and f.get("severity") == "warning" and f.get("run") and f["run"] not in {o["run"] for o in out}:
            fix = f.get("fix") or {}
            out.append({"run": f["run"], "declared": fix.get("declared"),
                        "speed": fix.get("speed") if "declared" in fix else None})
    return out


def setup_caveat(findings) -> str | None:
    """``adequacy.setup_caveat``: the set-up values the data contradicted at load (:func:`setup_slips`), one
    sentence naming each run; None when there are none. The fit took the data's value, so the numbers may be right;
    but a set-up slip the data had to mend means the verdict is not a clean one (the terminal warned first; the
    report must say so too). The assessment ``setup`` (:class:`rideid.estimate.records.SetupAssessment`) says it."""
    slips = setup_slips(findings)
    if not slips:
        return None
    runs = ", ".join(f"{s['run']} (declared {s['declared']:g}, the data {s['speed']:.3f} m/s)"
                     if s["declared"] is not None else str(s["run"]) for s in slips)
    return (f"a declared speed the data contradict: {runs}; the fit took the data's speed; check the test log "
            "(a speed typed wrong may not be the only slip of that run)")


def advice(model: dict | None) -> str:
    """What to try when the model is not adequate, for the model option the identification used.

    Parameters
    ----------
    model : dict or None
        The result's ``model`` block: ``extensions`` (the groups fitted) and,
        after ``--model auto``, ``selection = "auto"``.

    Returns
    -------
    str
        :data:`ADVICE` (let the extension groups in) unless they have been
        tried: after ``--model auto`` or with every group fitted it points to
        the data and to what the model still lacks instead. With damper
        curves in the model, :data:`KNOT_ADVICE` too (their knots).
    """
    model = model or {}
    ext = model.get("extensions") or []
    knots = KNOT_ADVICE if "damper_curves" in ext else ""
    if model.get("selection") == "auto":
        tried = (f"`--model auto` has already weighed anti-roll bars and tire damping (it kept "
                 f"{' + '.join(ext) or 'base'}), so the structure comes from elsewhere. ")
    elif set(GROUPS) <= set(ext):
        tried = ("The model already has anti-roll bars and tire damping (`--model full`), so the structure comes "
                 "from elsewhere. ")
    else:
        return ADVICE + (" " + knots.rstrip() if knots else "")
    lacks = [what for group, what in _LACKS if group not in ext] + ["a flexible body"]
    return (_ADVICE_HEAD + tried + knots + "Try " + ADVICE_SETUP + _ADVICE_CHECKS + " Or the car has what the "
            "model lacks ("
            + ", ".join(lacks) + ").")


def gross_misfit(run_errors: dict, at_bound: list, findings=()) -> dict | None:
    """The verdict of a first fit far beyond what any model extension could explain (SPEC §13): a run whose
    error exceeds setting ``adequacy.gross_error``, or setting ``adequacy.gross_bounds`` parameters at their search
    bounds; None otherwise.

    ``run_errors``: run id -> relative squared error of the first fit; ``at_bound``: the parameters at a bound;
    ``findings``: the load's findings (:class:`rideid.data.checks.Finding`), whose speed notes name what the data
    said of each run's set-up. The verdict (``adequate`` False, ``gross_misfit``, ``reasons``, ``advice``) names
    the runs, then the set-up to check (speed, start, rate, units, sensor chain), before any extension."""
    gross_error, gross_bounds = defaults["adequacy.gross_error"], defaults["adequacy.gross_bounds"]
    bad = {rid: float(e) for rid, e in run_errors.items() if np.isfinite(e) and e > gross_error}
    if not bad and len(at_bound) < gross_bounds:
        return None
    reasons = []
    if bad:
        worst = sorted(bad, key=lambda r: -bad[r])
        reasons.append("the first fit leaves " + ", ".join(f"{100 * bad[r]:.0f} % of run {r}'s signal" for r in worst)
                       + f" unexplained (an extension mends at most about {100 * gross_error / 3:.0f} %)")
    if len(at_bound) >= gross_bounds:
        reasons.append(f"{len(at_bound)} parameters ended at their search bounds ({', '.join(at_bound)})")
    seen = [f.message for f in findings if getattr(f, "check", None) == "speed"]
    advice = ("This is far beyond what a model extension explains, so the model choice was not run: check "
              + ADVICE_SETUP + _ADVICE_CHECKS
              + (" What loading found of the speeds: " + " ".join(seen) if seen else ""))
    return {"adequate": False, "gross_misfit": {"run_errors": {r: float(e) for r, e in run_errors.items()},
                                                "at_bound": list(at_bound), "threshold": gross_error,
                                                "bounds_threshold": gross_bounds},
            "reasons": reasons, "advice": advice}


def run_errors(ds, response: dict) -> dict:
    """Run id -> the relative squared error of the fitted ``response`` (run id -> (n, 10), NaN where not fitted):
    the squared residual over the squared data, over the samples and channels both have."""
    out = {}
    for rid, yhat in (response or {}).items():
        if rid not in ds.data:
            continue
        y = ds.data[rid].matrix()
        yhat = np.asarray(yhat, dtype=float)
        if yhat.shape != y.shape:
            continue
        ok = np.isfinite(y) & np.isfinite(yhat)
        den = float(np.sum(np.where(ok, y, 0.0) ** 2))
        out[rid] = float(np.sum(np.where(ok, y - yhat, 0.0) ** 2)) / den if den > 0 else float("nan")
    return out


def advise(adequacy: dict | None, model: dict | None) -> dict | None:
    """``adequacy`` with its ``advice`` for ``model`` (:func:`advice`); unchanged when adequate or not assessed."""
    if not adequacy or adequacy.get("adequate", True):
        return adequacy
    return {**adequacy, "advice": advice(model)}


def verdict_paragraph(adequacy: dict | None) -> str | None:
    """The plain paragraph the terminal prints when the model is not adequate (``None`` when it is)."""
    if not adequacy or adequacy.get("adequate", True):
        return None
    return "MODEL NOT ADEQUATE: " + adequacy["reasons"][0] + ". " + adequacy["advice"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "MIN_IMPROVEMENT": min_improvement,
    "LAGS": "adequacy.lags", "ALPHA": "adequacy.alpha", "MIN_EXPLAINED": "adequacy.min_explained", "LOUD_SHARE":
    "adequacy.loud_share", "MIN_RELATIVE": "adequacy.min_relative", "AR_MAX": "adequacy.ar_max",
    "WHITENESS_LAGS": "adequacy.whiteness_lags", "MIN_QUIET": "adequacy.min_quiet",
    "GROSS_ERROR": "adequacy.gross_error", "GROSS_BOUNDS": "adequacy.gross_bounds"})
