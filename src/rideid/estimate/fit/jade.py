"""JADE: adaptive differential evolution with an optional external archive.

Zhang, J. and Sanderson, A. C. (2009), "JADE: Adaptive Differential Evolution
With Optional External Archive", IEEE Trans. Evolutionary Computation 13(5),
945-958. The rules, per generation and individual ``i``:

* ``CR_i ~ N(mu_CR, 0.1)`` truncated to [0, 1]; ``F_i ~ Cauchy(mu_F, 0.1)``,
  set to 1 if >= 1 and drawn again if <= 0;
* current-to-pbest/1: ``v = x_i + F_i (x_pbest - x_i) + F_i (x_r1 - x~_r2)``,
  ``x_pbest`` uniform from the best ``max(2, ceil(p NP))`` of the population,
  ``r1 != i`` from the population, ``x~_r2`` from population + archive,
  distinct from ``i`` and ``r1``;
* a mutant component outside [low, up] becomes the midpoint of the parent's
  component and the violated bound;
* binomial crossover with ``j_rand`` drawn for each ``i``;
* the trial replaces the parent only if strictly better; the parent then goes
  to the archive and ``CR_i, F_i`` are successful;
* the archive is trimmed to NP by random removal; if any trial succeeded,
  ``mu_CR <- (1-c) mu_CR + c mean(S_CR)``,
  ``mu_F <- (1-c) mu_F + c sum(S_F^2)/sum(S_F)``.

:class:`JadeSolver` is an ask/tell object (one generation per ask/tell, the
whole population in one vectorised call). :func:`jade` is a thin loop over it.
All randomness comes from one ``numpy.random.Generator``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import OptimizeResult

from ...errors import ArgumentError


def make_rng(rng=None, seed=None):
    """The one ``rng`` argument of :func:`jade` and :func:`rideid.identify`.

    Parameters
    ----------
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        As SciPy >= 1.15: anything ``numpy.random.default_rng`` accepts. A
        Generator is used as it is (and advanced).
    seed : int, optional
        The older name (SPEC §5); give one of the two.

    Returns
    -------
    generator : numpy.random.Generator
    record : dict
        ``{"seed": int or None, "rng_state": the bit generator's state before
        the first draw}``, JSON-serialisable: with a Generator the state
        reproduces the run (``numpy.random.Generator(PCG64())`` with
        ``bit_generator.state = rng_state``).
    """
    if seed is not None and rng is not None:
        raise ArgumentError("give rng or seed, not both (seed is the older name of rng)")
    src = rng if rng is not None else seed
    if isinstance(src, (bool, np.bool_)) or not (
            src is None or isinstance(src, (int, np.integer, np.random.Generator, np.random.SeedSequence))):
        raise ArgumentError(f"rng must be None, an integer seed, a SeedSequence or a numpy.random.Generator, "
                            f"got {type(src).__name__}")
    if isinstance(src, (int, np.integer)) and src < 0:
        raise ArgumentError(f"seed must be a non-negative integer, got {src}")
    gen = np.random.default_rng(src)
    seed_rec = int(src) if isinstance(src, (int, np.integer)) else None
    return gen, {"seed": seed_rec, "rng_state": gen.bit_generator.state}


def stop_requested(callback, state) -> bool:
    """The one callback protocol: ``callback(state)`` returning True, or raising
    ``StopIteration`` (as SciPy's optimisers), asks to stop."""
    if callback is None:
        return False
    try:
        return bool(callback(state))
    except StopIteration:
        return True


def _check_bounds(bounds):
    try:
        b = np.asarray(bounds, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError("bounds must be a sequence of (low, up) pairs") from None
    if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] < 1:
        raise ArgumentError(f"bounds must have shape (d, 2), got {b.shape}")
    if not np.all(np.isfinite(b)):
        raise ArgumentError("bounds must be finite")
    bad = np.nonzero(b[:, 0] >= b[:, 1])[0]
    if bad.size:
        j = int(bad[0])
        raise ArgumentError(f"bounds[{j}]: low {b[j, 0]} must be less than up {b[j, 1]}")
    return b[:, 0].copy(), b[:, 1].copy()


class JadeSolver:
    """Ask/tell JADE.

    Parameters
    ----------
    bounds : array_like, shape (d, 2)
    population : int
        NP, at least 4.
    rng : numpy.random.Generator or int or None
        See :func:`make_rng`.
    p : float
        Greediness: ``x_pbest`` from the best ``max(2, ceil(p NP))``.
    c : float
        Adaptation rate of ``mu_CR`` and ``mu_F``.
    mu_cr, mu_f : float
        Initial means.
    archive : bool
        Use the external archive.
    init : array_like, shape (NP, d), optional
        Initial population (default: uniform in the bounds).

    Usage
    -----
    ``X = s.ask(); s.tell(f(X))`` repeatedly. The first ``ask`` returns the
    initial population; later ones return trial vectors. :meth:`rescore`
    replaces the costs of the current population (e.g. after the objective
    changed) without a generation.
    """

    def __init__(self, bounds, population: int, rng=None, *, p: float = 0.05, c: float = 0.1,
                 mu_cr: float = 0.5, mu_f: float = 0.5, archive: bool = True, init=None):
        self.low, self.up = _check_bounds(bounds)
        self.dim = self.low.size
        if not isinstance(population, (int, np.integer)) or population < 4:
            raise ArgumentError(f"population must be an integer >= 4, got {population!r}")
        if not (0 < p <= 1):
            raise ArgumentError(f"p must be in (0, 1], got {p}")
        if not (0 < c <= 1):
            raise ArgumentError(f"c must be in (0, 1], got {c}")
        for name, v in (("mu_cr", mu_cr), ("mu_f", mu_f)):
            if not (0 <= v <= 1):
                raise ArgumentError(f"{name} must be in [0, 1], got {v}")
        self.np_ = int(population)
        self.rng = rng if isinstance(rng, np.random.Generator) else make_rng(rng)[0]
        self.p, self.c = float(p), float(c)
        self.mu_cr, self.mu_f = float(mu_cr), float(mu_f)
        self.use_archive = bool(archive)
        self.n_best = max(2, math.ceil(self.p * self.np_))
        if init is None:
            self.pop = self.low + self.rng.random((self.np_, self.dim)) * (self.up - self.low)
        else:
            init = np.array(init, dtype=float)
            if init.shape != (self.np_, self.dim):
                raise ArgumentError(f"init must have shape {(self.np_, self.dim)}, got {init.shape}")
            self.pop = init
        self.costs = None
        self.archive = np.empty((0, self.dim))
        self.nit = 0
        self.nfev = 0
        self._pending = None  # ("init", X) or ("trial", U, F, CR)

    # -- helpers -------------------------------------------------------------
    def _draw_cr(self):
        return np.clip(self.rng.normal(self.mu_cr, 0.1, self.np_), 0.0, 1.0)

    def _draw_f(self):
        n = self.np_
        F = np.empty(n)
        todo = np.arange(n)
        while todo.size:
            f = self.mu_f + 0.1 * np.tan(np.pi * (self.rng.random(todo.size) - 0.5))
            ok = f > 0
            F[todo[ok]] = np.minimum(f[ok], 1.0)
            todo = todo[~ok]
        return F

    def _mutants(self, F):
        n, pop = self.np_, self.pop
        order = np.argsort(self.costs, kind="stable")
        pbest = order[self.rng.integers(0, self.n_best, n)]
        idx = np.arange(n)
        r1 = self.rng.integers(0, n - 1, n)
        r1 += r1 >= idx
        union = np.vstack([pop, self.archive]) if self.use_archive and self.archive.size else pop
        m = union.shape[0]
        lo_, hi_ = np.minimum(idx, r1), np.maximum(idx, r1)
        r2 = self.rng.integers(0, m - 2, n)
        r2 += r2 >= lo_
        r2 += r2 >= hi_
        Fc = F[:, None]
        v = pop + Fc * (pop[pbest] - pop) + Fc * (pop[r1] - union[r2])
        # midpoint repair towards the parent
        low = v < self.low
        high = v > self.up
        v = np.where(low, (self.low + pop) / 2, v)
        v = np.where(high, (self.up + pop) / 2, v)
        return v

    # -- ask / tell ----------------------------------------------------------
    def ask(self) -> np.ndarray:
        """The next population to evaluate, shape (NP, d)."""
        if self._pending is not None:
            raise ArgumentError("ask() called twice without tell()")
        if self.costs is None:
            self._pending = ("init",)
            return self.pop.copy()
        CR = self._draw_cr()
        F = self._draw_f()
        v = self._mutants(F)
        mask = self.rng.random((self.np_, self.dim)) < CR[:, None]
        jrand = self.rng.integers(0, self.dim, self.np_)
        mask[np.arange(self.np_), jrand] = True
        U = np.where(mask, v, self.pop)
        self._pending = ("trial", U, F, CR)
        return U.copy()

    def _check_costs(self, costs):
        f = np.asarray(costs, dtype=float)
        if f.shape != (self.np_,):
            raise ArgumentError(f"costs must have shape ({self.np_},), got {f.shape}")
        if np.any(np.isnan(f)):
            raise ArgumentError(f"costs contain NaN at rows {np.nonzero(np.isnan(f))[0][:5].tolist()}")
        return f

    def tell(self, costs) -> np.ndarray:
        """Costs of the population returned by the last :meth:`ask`.

        Returns the boolean mask of improved individuals (all False after the
        initial evaluation).
        """
        if self._pending is None:
            raise ArgumentError("tell() without a preceding ask()")
        f = self._check_costs(costs)
        kind = self._pending[0]
        self.nfev += self.np_
        if kind == "init":
            self.costs = f
            self._pending = None
            return np.zeros(self.np_, bool)
        _, U, F, CR = self._pending
        self._pending = None
        better = f < self.costs
        if self.use_archive and better.any():
            self.archive = np.vstack([self.archive, self.pop[better]])
            if self.archive.shape[0] > self.np_:
                keep = self.rng.choice(self.archive.shape[0], self.np_, replace=False)
                self.archive = self.archive[np.sort(keep)]
        self.pop = np.where(better[:, None], U, self.pop)
        self.costs = np.where(better, f, self.costs)
        if better.any():
            sf = F[better]
            self.mu_cr = (1 - self.c) * self.mu_cr + self.c * float(np.mean(CR[better]))
            self.mu_f = (1 - self.c) * self.mu_f + self.c * float(np.sum(sf * sf) / np.sum(sf))
        self.nit += 1
        return better

    def rescore(self, costs):
        """Replace the costs of the current population (objective changed)."""
        if self._pending is not None:
            raise ArgumentError("rescore() between ask() and tell()")
        if self.costs is None:
            raise ArgumentError("rescore() before the initial population was evaluated")
        self.costs = self._check_costs(costs)

    @property
    def best_index(self) -> int:
        return int(np.argmin(self.costs))

    @property
    def x(self):
        return self.pop[self.best_index].copy()

    @property
    def fun(self) -> float:
        return float(self.costs[self.best_index])

    def state(self) -> OptimizeResult:
        """Snapshot for callbacks: population, costs, mu_F, mu_CR, archive size, counts."""
        return OptimizeResult(x=self.x, fun=self.fun, population=self.pop, population_costs=self.costs,
                              mu_f=self.mu_f, mu_cr=self.mu_cr, archive_size=self.archive.shape[0],
                              nit=self.nit, nfev=self.nfev)


def jade(fun, bounds, *, population: int = 100, generations: int = 1000, rng=None, seed=None,
         max_evals: int | None = None, target: float | None = None, callback=None,
         p: float = 0.05, c: float = 0.1, archive: bool = True, init=None) -> OptimizeResult:
    """Minimise ``fun`` with JADE.

    Parameters
    ----------
    fun : callable
        Vectorised objective: ``fun(X)`` with ``X`` of shape ``(n, d)``
        returns ``n`` costs.
    bounds : array_like, shape (d, 2)
    population : int
        NP (the paper used 100 at d = 30).
    generations : int
        Largest number of generations.
    rng : int, numpy.random.Generator or None
        Seed or generator of all randomness (see :func:`make_rng`); same
        seed, same bits.
    seed : int, optional
        The older name of ``rng`` (SPEC §5).
    max_evals : int, optional
        Stop when the next generation would exceed this many evaluations.
    target : float, optional
        Stop once the best cost is <= target.
    callback : callable, optional
        ``callback(state)`` after each generation with the solver's
        :meth:`JadeSolver.state`; returning True or raising ``StopIteration``
        stops (:func:`stop_requested`). It may call
        ``state.solver.rescore`` (the solver is passed as ``state.solver``).
    p, c, archive, init
        See :class:`JadeSolver`.

    Returns
    -------
    OptimizeResult
        ``x, fun, nfev, nit, success, message, stop`` (which criterion fired:
        ``"generations"``, ``"max_evals"``, ``"target"`` or ``"callback"``),
        ``mu_f, mu_cr, population, population_costs``.
    """
    if not callable(fun):
        raise ArgumentError("fun must be callable")
    if not isinstance(generations, (int, np.integer)) or generations < 0:
        raise ArgumentError(f"generations must be a non-negative integer, got {generations!r}")
    gen, _ = make_rng(rng, seed)
    s = JadeSolver(bounds, population, gen, p=p, c=c, archive=archive, init=init)

    X = s.ask()
    s.tell(_call(fun, X, s.np_))
    stop = "generations"
    while True:
        if target is not None and s.fun <= target:
            stop = "target"
            break
        if s.nit >= generations:
            stop = "generations"
            break
        if max_evals is not None and s.nfev + s.np_ > max_evals:
            stop = "max_evals"
            break
        X = s.ask()
        s.tell(_call(fun, X, s.np_))
        if callback is not None:
            st = s.state()
            st.solver = s
            if stop_requested(callback, st):
                stop = "callback"
                break
    messages = {
        "generations": "Maximum number of generations reached.",
        "max_evals": "Evaluation budget reached.",
        "target": "Target cost reached.",
        "callback": "Stopped by callback.",
    }
    res = s.state()
    # every criterion is a normal termination; success says the result is usable
    res.update(success=bool(np.isfinite(res.fun)), message=messages[stop], stop=stop)
    return res


def _call(fun, X, n):
    f = np.asarray(fun(X), dtype=float)
    if f.shape not in ((n,), (n, 1)):
        raise ArgumentError(f"fun must return {n} costs for a ({n}, d) population, got shape {f.shape}")
    return f.reshape(n)
