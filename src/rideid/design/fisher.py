"""Fisher information of candidate runs, and what it says about precision.

For run ``r`` with sample count ``N_r``, channel ``c`` of the ten SPEC
channels and Gaussian sensor noise of standard deviation ``sigma_rc`` and
correlation ``R_rc`` in time (identity for white noise; AR(1) or a spectrum,
:mod:`rideid.design.colour`), the Fisher information about the free
parameters ``x`` (the names of a :class:`rideid.ParameterSpace`: scale
anchor, fixed and derived values applied exactly as identify applies them) is

    F_r = sum_c  J_rc^T R_rc^-1 J_rc / sigma_rc^2,     J_rc = d y_rc / d x   (N_r, d)

(the information of the whitened problem).

Runs have independent noise, so a subset ``S`` of runs carries
``F_S = sum_{r in S} F_r`` and the Cramér-Rao lower bound is
``cov >= F_S^-1``.

Identify does not minimise that noise-weighted sum, it minimises the
equal-run-weight, energy-normalised cost of :mod:`rideid.cost`: channel
weight ``W_rc = 1 / (|C_r| D_rc)``. A weighted least-squares estimator with
weights ``W`` has the (linearised) sandwich covariance

    cov_identify = A^-1 B A^-1,   A = sum w_r W_rc J_rc^T J_rc,
                                  B = sum w_r^2 W_rc^2 sigma_rc^2 J_rc^T R_rc J_rc

(equal run weights ``w_r`` cancel). Identify does not whiten coloured noise,
so ``B`` holds the noise covariance itself. By Gauss-Markov (generalised
least squares is the efficient linear estimator) it is never below the
CRLB; both are reported. ``W_rc`` is computed by identify's own
:func:`rideid.cost.channel_weights` on the expected measured energy
(signal energy plus ``N_r sigma_rc^2``).

Sensitivities are batched central finite differences through the compiled
kernel, relative step ``STEP`` (see ``docs/planning.md`` for the step study:
central differences at 1e-5 agree with a Richardson extrapolation from
1e-3 to 5e-9 of the largest sensitivity; 1e-4 to 3e-8, 1e-6 to 4e-8 (round-off)).

Everything downstream works in relative coordinates ``u = x / x0``
(``F_rel = diag(x0) F diag(x0)``), so criteria and condition numbers do not
depend on units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..estimate.problem.cost import ParameterSpace, channel_weights
from ..model.batch import BatchSimulator
from ..errors import ArgumentError
from ..model.equations import CHANNEL_KIND, CHANNELS
from ..data.scenario import scenario_run_input
from .colour import NoiseSpectrum, ar1_grams, padded_length, spectral_grams

#: relative finite-difference step
STEP = 1e-5
#: a channel whose noise-free RMS is below this fraction of the largest RMS of
#: its kind in the run carries no signal (roll rate on a symmetric washboard)
#: and is left out (with ``--noise`` its noise would be zero too: 0/0)
SILENT = 1e-9
#: eigenvalues of the relative Fisher matrix below this fraction of the largest
#: count as zero (condition number above 1e10: parameter rel. std ratios of 1e5)
RANK_TOL = 1e-10


@dataclass(frozen=True)
class NoiseModel:
    """Sensor noise of a run's channels.

    Parameters
    ----------
    fraction : float
        SPEC ``--noise``: standard deviation as a fraction of each channel's
        RMS (noise-free, over the run), per run.
    accel_density : float
        Accelerometer noise density, (m/s²)/√Hz (body and axle channels).
    gyro_density : float
        Gyro noise density, (rad/s)/√Hz (pitch and roll rate).
    bandwidth : float, optional
        Logger bandwidth (Hz) for the densities; default each run's ``fs / 2``
        (white noise sampled without further filtering).
    ar1 : float
        Coloured noise: AR(1) in time with this coefficient per sample, the
        same standard deviation (``rideid simulate --noise-ar1``); 0 is white.
    psd : NoiseSpectrum, optional
        Coloured noise with a measured spectrum (``--noise-psd``). With a
        fraction or a density, only its shape counts: it is scaled per run and
        channel to their standard deviation (as ``ar1``). Alone, it is the
        absolute noise: ``sigma² = ∫ PSD`` over 0..fs/2.

    The white parts are independent: ``sigma² = (fraction RMS)² + density² B``.
    Channels and runs are independent in every case.
    """

    fraction: float = 0.0
    accel_density: float = 0.0
    gyro_density: float = 0.0
    bandwidth: float | None = None
    ar1: float = 0.0
    psd: NoiseSpectrum | None = None

    def __post_init__(self):
        for k in ("fraction", "accel_density", "gyro_density"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v >= 0):
                raise ArgumentError(f"noise {k} must be a non-negative number, got {v!r}")
        if self.bandwidth is not None and not (np.isfinite(self.bandwidth) and self.bandwidth > 0):
            raise ArgumentError(f"noise bandwidth must be a positive number of Hz, got {self.bandwidth!r}")
        if not (np.isfinite(self.ar1) and 0 <= self.ar1 < 1):
            raise ArgumentError(f"--noise-ar1 must be an AR(1) coefficient in [0, 1), got {self.ar1}")
        if self.ar1 > 0 and self.psd is not None:
            raise ArgumentError("--noise-ar1 and --noise-psd both give the noise's colour: give one of them")
        if self.fraction == 0 and self.accel_density == 0 and self.gyro_density == 0 and self.psd is None:
            raise ArgumentError("the noise model is zero: give --noise FRACTION or a noise density "
                                "(without noise every parameter is known exactly and there is nothing to plan)")

    @property
    def white_level(self) -> bool:
        """True when the standard deviation comes from the fraction and densities (not from a PSD alone)."""
        return self.fraction > 0 or self.accel_density > 0 or self.gyro_density > 0

    @property
    def coloured(self) -> bool:
        return self.ar1 > 0 or self.psd is not None

    def sigma(self, rms: np.ndarray, fs: float) -> np.ndarray:
        """Noise standard deviation per channel, shape (10,), for channel RMS ``rms`` (10,)."""
        if not self.white_level:
            return np.sqrt(self.psd.variance(fs))
        bw = self.bandwidth if self.bandwidth is not None else fs / 2
        dens = np.array([self.gyro_density if CHANNEL_KIND[c] == "rate" else self.accel_density for c in CHANNELS])
        return np.sqrt((self.fraction * rms) ** 2 + dens ** 2 * bw)

    def grams(self, J: np.ndarray, fs: float):
        """Per channel (10, d, d): ``J^T J``, ``J^T R^-1 J`` and ``J^T R J`` for sensitivities ``J`` (d, n, 10),
        ``R`` the noise's correlation matrix in time (identity when white)."""
        G = np.einsum("itc,jtc->cij", J, J)
        if self.ar1 > 0:
            return (G, *ar1_grams(J, self.ar1))
        if self.psd is not None:
            M = padded_length(J.shape[1])
            shape = self.psd.at(np.arange(M // 2 + 1) * fs / M)
            return (G, *spectral_grams(J, shape, M))
        return G, G, G

    def to_dict(self) -> dict:
        if self.ar1 > 0:
            corr = (f"AR(1) in time, coefficient {self.ar1:g} per sample (R_ts = rho^|t-s|), the same standard "
                    "deviation; independent between channels and runs")
        elif self.psd is not None:
            corr = ("coloured with the spectrum of the noise PSD file" + (" (its shape; the level is sigma)"
                    if self.white_level else "") + "; independent between channels and runs")
        else:
            corr = "white: independent between samples, channels and runs"
        level = ("sigma^2 = (fraction * channel RMS)^2 + density^2 * bandwidth" if self.white_level
                 else "sigma^2 = integral of the noise PSD over 0..fs/2")
        return {"fraction": self.fraction, "accel_density": self.accel_density, "gyro_density": self.gyro_density,
                "bandwidth": self.bandwidth if self.bandwidth is not None else "fs/2",
                "colour": "ar1" if self.ar1 > 0 else ("psd" if self.psd is not None else "white"),
                "ar1": self.ar1,
                "psd": None if self.psd is None else {**self.psd.to_dict(),
                                                      "scaling": "shape" if self.white_level else "absolute"},
                "definition": f"{level}; {corr}"}

    def describe(self) -> str:
        """One line for the terminal and plan.md."""
        parts = []
        if self.fraction:
            parts.append(f"{self.fraction:g} of RMS")
        if self.accel_density or self.gyro_density:
            parts.append(f"densities accel {self.accel_density:g} (m/s²)/√Hz, gyro {self.gyro_density:g} (rad/s)/√Hz")
        level = " + ".join(parts)
        if self.ar1 > 0:
            return f"{level}, coloured: AR(1) {self.ar1:g} per sample"
        if self.psd is not None:
            return (f"{level}, coloured: the spectrum shape of {self.psd.path}" if level
                    else f"the spectrum of {self.psd.path}")
        return f"{level}, white"


@dataclass
class Information:
    """The information matrices of candidate runs and the channels they come from.

    Attributes
    ----------
    F : ndarray (..., d, d)
        Fisher information.
    A, B : ndarray (..., d, d)
        Identify's weighted normal matrix and its noise term (sandwich).
    sigma, rms, used : ndarray (..., 10)
        Noise sd, noise-free RMS, channels used.
    """

    F: np.ndarray
    A: np.ndarray
    B: np.ndarray
    sigma: np.ndarray
    rms: np.ndarray
    used: np.ndarray


@dataclass
class RunInformation(Information):
    """Information of every candidate run about the free parameters of one car.

    All matrices are in relative coordinates ``u = x / x0``.

    Attributes
    ----------
    F, A, B : ndarray (n_runs, d, d)
        Per run, as :class:`Information`.
    sigma, rms, used : ndarray (n_runs, 10)
        Per run, as :class:`Information`.
    names : list of str
        Free parameter names (d).
    x0 : ndarray (d,)
        The car (free parameters).
    P0 : ndarray (n_params,)
        The full parameter vector of the car.
    """

    names: list
    x0: np.ndarray
    P0: np.ndarray


def simulator(sc) -> BatchSimulator:
    """The batched simulator of all runs of a scenario (SPEC §3 sample times)."""
    runs = [scenario_run_input(sc, r, i) for i, r in enumerate(sc.runs)]
    return BatchSimulator(sc.geometry, runs)


def jacobians(sim: BatchSimulator, space: ParameterSpace, x0, step: float = STEP, method: str = "central"):
    """Sensitivities ``d y / d u`` (relative coordinates) of every run.

    Parameters
    ----------
    method : {"central", "richardson", "forward"}
        Central differences (error O(h²)), their Richardson extrapolation from
        steps h and 2h (O(h⁴)), or forward differences (O(h)).

    Returns
    -------
    Y0 : list of (n_time, 10) nominal outputs per run
    J : list of (d, n_time, 10) per run
    """
    x0 = np.asarray(x0, dtype=float)
    d = x0.size
    E = np.eye(d) * (step * x0)[None, :]
    if method == "central":
        X = np.vstack([x0, x0 + E, x0 - E])
    elif method == "richardson":
        X = np.vstack([x0, x0 + E, x0 - E, x0 + 2 * E, x0 - 2 * E])
    elif method == "forward":
        X = np.vstack([x0, x0 + E])
    else:
        raise ArgumentError(f"unknown sensitivity method {method!r}")
    P = space.full(X)
    if not space.valid(P).all():
        raise ArgumentError("the nominal car is too close to a physical limit for finite differences")
    outs = sim.outputs(P)
    Y0, J = [], []
    for o in outs:
        Y0.append(o[0])
        if method == "central":
            J.append((o[1:1 + d] - o[1 + d:1 + 2 * d]) / (2 * step))
        elif method == "forward":
            J.append((o[1:1 + d] - o[0][None]) / step)
        else:
            c1 = (o[1:1 + d] - o[1 + d:1 + 2 * d]) / (2 * step)
            c2 = (o[1 + 2 * d:1 + 3 * d] - o[1 + 3 * d:1 + 4 * d]) / (4 * step)
            J.append((4 * c1 - c2) / 3)
    return Y0, J


def run_information(sim: BatchSimulator, space: ParameterSpace, x0, noise: NoiseModel, fs,
                    step: float = STEP, method: str = "central") -> RunInformation:
    """Fisher and sandwich matrices of every run of ``sim`` at the car ``x0``.

    ``fs`` : sequence of the runs' sample rates (Hz), for the noise bandwidth.
    """
    x0 = np.asarray(x0, dtype=float)
    Y0, J = jacobians(sim, space, x0, step, method)
    R, d = len(Y0), x0.size
    F = np.zeros((R, d, d))
    A = np.zeros((R, d, d))
    B = np.zeros((R, d, d))
    sig = np.zeros((R, len(CHANNELS)))
    rmss = np.zeros((R, len(CHANNELS)))
    used = np.zeros((R, len(CHANNELS)), bool)
    kinds = np.array([CHANNEL_KIND[c] for c in CHANNELS])
    for r in range(R):
        y, Jr = Y0[r], J[r]
        n = y.shape[0]
        rms = np.sqrt(np.mean(y * y, axis=0))
        s = noise.sigma(rms, fs[r])
        live = np.zeros(len(CHANNELS), bool)
        for k in set(kinds):
            m = kinds == k
            live[m] = rms[m] > SILENT * rms[m].max() if rms[m].max() > 0 else False
        live &= s > 0
        # identify's weights from the expected measured energy (signal + noise): the extra row
        # carries sqrt(n) sigma so that channel_weights sees sum y^2 + n sigma^2 per channel
        # (stationary coloured noise has the same energy n sigma^2)
        W = channel_weights(np.vstack([y, np.sqrt(n) * s[None, :]]))
        # J^T J, J^T R^-1 J, J^T R J per channel (10, d, d); R = identity for white noise
        G, Gi, Gc = noise.grams(Jr, fs[r])
        inv_var = np.where(live, 1.0 / np.where(live, s, 1.0) ** 2, 0.0)
        F[r] = np.einsum("c,cij->ij", inv_var, Gi)
        A[r] = np.einsum("c,cij->ij", W * live, G)
        B[r] = np.einsum("c,cij->ij", (W * live) ** 2 * s ** 2, Gc)
        sig[r], rmss[r], used[r] = s, rms, live
    return RunInformation(F, A, B, sig, rmss, used, names=list(space.names), x0=x0, P0=space.full(x0[None])[0])


# ---------------------------------------------------------------------------
# precision of a subset of runs

@dataclass
class Precision:
    """CRLB and identify's expected spread for one set of runs (one car)."""

    names: list
    x0: np.ndarray
    rel_crlb: np.ndarray          # (d,) relative std; inf where not identifiable
    rel_identify: np.ndarray      # (d,) sandwich relative std; inf where not identifiable
    cov_rel: np.ndarray           # (d, d) CRLB covariance in relative coordinates (NaN if singular)
    cov_identify_rel: np.ndarray  # (d, d)
    rank: int
    condition: float
    eigvals: np.ndarray
    eigvecs: np.ndarray

    @property
    def std(self):
        return self.rel_crlb * np.abs(self.x0)

    @property
    def std_identify(self):
        return self.rel_identify * np.abs(self.x0)

    @property
    def identifiable(self) -> np.ndarray:
        return np.isfinite(self.rel_crlb)

    def correlation(self) -> np.ndarray:
        """CRLB correlation matrix (NaN rows/columns for unidentifiable parameters)."""
        sd = np.sqrt(np.diag(self.cov_rel))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.cov_rel / np.outer(sd, sd)

    def derived_std(self, grad_rel: np.ndarray) -> tuple[float, float]:
        """Std of a derived quantity with gradient ``grad_rel`` (d/du), CRLB and identify."""
        nz = np.nonzero(grad_rel)[0]  # rows of parameters it does not depend on may be NaN (not identifiable)
        g = grad_rel[nz]
        a = float(np.sqrt(max(g @ self.cov_rel[np.ix_(nz, nz)] @ g, 0.0)))
        b = float(np.sqrt(max(g @ self.cov_identify_rel[np.ix_(nz, nz)] @ g, 0.0)))
        return a, b


def precision(F, A, B, names, x0) -> Precision:
    """Precision of a set of runs from its summed Fisher ``F`` and sandwich parts ``A``, ``B``.

    A parameter is identifiable when its unit vector has no component in the
    null space of ``F`` (eigenvalues below ``RANK_TOL`` of the largest); its
    CRLB is then the diagonal of the pseudo-inverse.
    """
    d = F.shape[0]
    F = 0.5 * (F + F.T)
    w, V = np.linalg.eigh(F)
    top = max(w.max(), 0.0)
    ok = w > RANK_TOL * top if top > 0 else np.zeros(d, bool)
    rank = int(ok.sum())
    cond = float(top / w[ok].min()) if rank == d else float("inf")
    null = V[:, ~ok]
    in_null = np.sum(null ** 2, axis=1) > 1e-6 if null.size else np.zeros(d, bool)
    Finv = (V[:, ok] / w[ok]) @ V[:, ok].T
    rel = np.sqrt(np.clip(np.diag(Finv), 0, None))
    rel[in_null] = np.inf
    cov = Finv.copy()
    cov[in_null, :] = np.nan
    cov[:, in_null] = np.nan
    # sandwich on the identifiable subspace
    A = 0.5 * (A + A.T)
    wa, Va = np.linalg.eigh(A)
    oka = wa > RANK_TOL * max(wa.max(), 0.0) if wa.max() > 0 else np.zeros(d, bool)
    Ainv = (Va[:, oka] / wa[oka]) @ Va[:, oka].T
    covs = Ainv @ B @ Ainv
    rels = np.sqrt(np.clip(np.diag(covs), 0, None))
    rels[in_null] = np.inf
    covs[in_null, :] = np.nan
    covs[:, in_null] = np.nan
    return Precision(list(names), np.asarray(x0, float), rel, rels, cov, covs, rank, cond, w, V)


def subset_precision(info: RunInformation, runs) -> Precision:
    """:func:`precision` of the run indices ``runs``."""
    idx = list(runs)
    return precision(info.F[idx].sum(0), info.A[idx].sum(0), info.B[idx].sum(0), info.names, info.x0)


def messages(p: Precision, run_ids=None, pair_limit: float = 0.9) -> list[str]:
    """Plain words: what cannot be identified, what is poorly determined, which pairs trade off."""
    out = []
    names = p.names
    d = len(names)
    if run_ids is not None and len(run_ids) == 0:
        return ["no runs selected: nothing can be identified"]
    where = f" from {', '.join(run_ids)}" if run_ids is not None else ""
    null = p.eigvecs[:, p.eigvals <= RANK_TOL * max(p.eigvals.max(), 0.0)]
    alone = set()
    for k in range(null.shape[1]):
        v = null[:, k]
        j = int(np.argmax(np.abs(v)))
        if abs(v[j]) > 0.95:
            alone.add(j)
    for j in sorted(alone):
        out.append(f"{names[j]} cannot be identified{where}: the signals do not depend on it")
    if null.shape[1] > len(alone):
        # the remaining null directions, after removing the single-parameter ones
        rest = null.copy()
        for j in alone:
            e = np.zeros(d)
            e[j] = 1
            rest = rest - np.outer(e, e @ rest)
        U, s, _ = np.linalg.svd(rest, full_matrices=False)
        for k in range(int(np.sum(s > 1e-6))):
            v = U[:, k]
            big = [i for i in np.argsort(-np.abs(v)) if abs(v[i]) > 0.2]
            terms = " ".join(f"{'+' if v[i] * np.sign(v[big[0]]) > 0 else '-'}{abs(v[i]):.2f} {names[i]}"
                             for i in big)
            out.append(f"not identifiable{where}: {', '.join(names[i] for i in big)} can move together "
                       f"(relative change direction {terms}) without changing any signal; only other "
                       "combinations are fixed")
    for j in range(d):
        if np.isfinite(p.rel_crlb[j]) and p.rel_crlb[j] > 1.0:
            out.append(f"{names[j]} is practically unidentifiable{where}: CRLB ±{100 * p.rel_crlb[j]:.0f} %")
    C = p.correlation()
    strong = np.isfinite(C) & (np.abs(C) > pair_limit)
    np.fill_diagonal(strong, False)
    seen = set()
    for i in range(d):  # clusters of strongly correlated parameters (connected components)
        if i in seen or not strong[i].any():
            continue
        comp, stack = set(), [i]
        while stack:
            k = stack.pop()
            if k not in comp:
                comp.add(k)
                stack.extend(np.nonzero(strong[k])[0].tolist())
        seen |= comp
        comp = sorted(comp)
        if len(comp) == 2:
            a, b = comp
            out.append(f"{names[a]} and {names[b]} trade off (CRLB correlation {C[a, b]:+.3f}): "
                       "the data fix a combination of them better than either")
        else:
            sub = np.abs(C[np.ix_(comp, comp)])
            np.fill_diagonal(sub, 0)
            out.append(f"{', '.join(names[k] for k in comp)} trade off among themselves (CRLB |correlation| up to "
                       f"{sub.max():.3f}): the data fix combinations of them better than each one")
    return out
