"""Choosing runs: D-, A- and target-optimal subsets under a budget.

Criteria (all in relative coordinates, lower is better, each over a set of
cars ``k`` — the nominal car and, for a robust plan, cars sampled around it —
taking the **worst car** (maximin), so the plan keeps its promise for every
sampled car):

* ``D``: ``-min_k log det(F_k(S) + eps I) / d``  (the volume of the
  confidence ellipsoid, per parameter);
* ``A``: ``max_k trace((F_k(S) + eps I)^-1)``  (sum of squared relative CRLBs);
* ``target``: reach ``rel_std_j <= target_j`` on the named parameters at the
  lowest cost; ``rel_std`` is the larger of the CRLB and identify's expected
  spread (the sandwich, :mod:`rideid.design.fisher`), i.e. what identify will
  deliver. Before the targets are met, the greedy step uses the smooth
  ``sum_j (rel_std_j / target_j)^2``.

``eps = EPS`` is a vanishing prior (relative standard deviation 1e4) that keeps
the criteria finite while a parameter is still unidentifiable, so that greedy
steps which make it identifiable score best.

Search: greedy (largest criterion gain per unit cost: per run, or per second
of track time with the overhead), then local search by single exchanges,
additions and removals until no move improves (a Fedorov-type exchange),
restarted from the greedy completion of every single run; the best result
wins. Exact on every small case the tests enumerate, not guaranteed in
general (the problem is NP-hard).
"""

from __future__ import annotations

import numpy as np

EPS = 1e-8


class Selector:
    """Evaluate criteria of run subsets over one or more cars.

    Parameters
    ----------
    F, A, B : ndarray (K, R, d, d)
        Per car and run: Fisher information and identify's sandwich parts
        (relative coordinates).
    cost : ndarray (R,)
        Cost of each run (1 per run, or seconds of track time).
    criterion : {"D", "A", "target"}
    target_idx, target_rel : sequences
        Targeted parameter indices and their relative-std targets.
    """

    def __init__(self, F, A, B, cost, criterion="D", target_idx=(), target_rel=()):
        self.F, self.A, self.B = F, A, B
        self.K, self.R, self.d = F.shape[:3]
        self.cost = np.asarray(cost, dtype=float)
        self.criterion = criterion
        self.ti = np.asarray(target_idx, dtype=int)
        self.tr = np.asarray(target_rel, dtype=float)
        self.I = np.eye(self.d)
        self.nevals = 0

    # -- values ---------------------------------------------------------------
    def rel_std(self, S) -> np.ndarray:
        """(K, d) relative std: max of the regularised CRLB and identify's sandwich."""
        idx = list(S)
        if not idx:
            return np.full((self.K, self.d), 1 / np.sqrt(EPS))
        F = self.F[:, idx].sum(1) + EPS * self.I
        A = self.A[:, idx].sum(1)
        B = self.B[:, idx].sum(1)
        crlb = np.sqrt(np.abs(np.diagonal(np.linalg.inv(F), axis1=1, axis2=2)))
        tr = np.trace(A, axis1=1, axis2=2)[:, None, None]
        Ai = np.linalg.inv(A + 1e-12 * np.maximum(tr, 1e-300) * self.I)
        sand = np.sqrt(np.abs(np.diagonal(Ai @ B @ Ai, axis1=1, axis2=2)))
        return np.maximum(crlb, np.where(np.isfinite(sand), sand, np.inf))

    def value(self, S) -> float:
        """The criterion (lower is better); for ``target`` the worst ratio ``rel_std / target``."""
        self.nevals += 1
        idx = list(S)
        F = self.F[:, idx].sum(1) + EPS * self.I
        if self.criterion == "D":
            return float(-np.linalg.slogdet(F)[1].min() / self.d)
        if self.criterion == "A":
            return float(np.trace(np.linalg.inv(F), axis1=1, axis2=2).max())
        return float((self.rel_std(S)[:, self.ti] / self.tr).max())

    def smooth(self, S) -> float:
        """Greedy score: the criterion, or for ``target`` ``max_k sum_j (rel_j / target_j)^2``."""
        if self.criterion != "target":
            return self.value(S)
        self.nevals += 1
        return float(((self.rel_std(S)[:, self.ti] / self.tr) ** 2).sum(1).max())

    def met(self, S) -> bool:
        return self.criterion == "target" and self.value(S) <= 1.0

    def key(self, S) -> tuple:
        """Order of subsets: criterion; for ``target`` met first, then cheapest, then best ratio."""
        if self.criterion != "target":
            return (self.value(S),)
        v = self.value(S)
        c = float(self.cost[list(S)].sum())
        return (0, c, v) if v <= 1.0 else (1, v, c)

    # -- search ---------------------------------------------------------------
    def greedy(self, fits, start=(), stop_when_met=True) -> list[int]:
        """Add runs one at a time: the largest drop of :meth:`smooth` per unit cost.

        ``fits(S)`` says whether a subset is within the budget. Returns the
        runs in the order added (the greedy path).
        """
        S = list(start)
        cur = self.smooth(S)
        while len(S) < self.R:
            if stop_when_met and S and self.met(S):
                break
            best, best_gain, best_v = None, -np.inf, None
            for j in range(self.R):
                if j in S or not fits(S + [j]):
                    continue
                v = self.smooth(S + [j])
                gain = (cur - v) / self.cost[j]
                if gain > best_gain:
                    best, best_gain, best_v = j, gain, v
            if best is None:
                break
            S.append(best)
            cur = best_v
        return S

    def exchange(self, S, fits, max_rounds: int = 200) -> list[int]:
        """Local search from ``S``: best single swap, addition or removal while :meth:`key` improves."""
        S = sorted(S)
        cur = self.key(S)
        for _ in range(max_rounds):
            best, best_key = None, cur
            out = [j for j in range(self.R) if j not in S]
            moves = [sorted(S + [j]) for j in out]
            moves += [[k for k in S if k != i] for i in S if len(S) > 1]
            moves += [sorted([k for k in S if k != i] + [j]) for i in S for j in out]
            for T in moves:
                if not fits(T):
                    continue
                k = self.key(T)
                if _better(k, best_key):
                    best, best_key = T, k
            if best is None:
                break
            S, cur = best, best_key
        return S

    def best(self, fits, starts: int | None = None) -> list[int]:
        """Greedy then exchange under the budget ``fits``, from several starts; the best result.

        Single exchanges can stall in a local optimum (seen with the A
        criterion on two runs), so the search restarts from the greedy
        completion of each of the ``starts`` best single runs (default all)
        as well as from the plain greedy subset.
        """
        cands = [self.greedy(fits)]
        singles = [j for j in range(self.R) if fits([j])]
        singles.sort(key=lambda j: self.key([j]))
        for j in singles[:starts]:
            cands.append(self.greedy(fits, start=[j]))
        best, best_key, seen = [], None, set()
        for S in cands:
            if not S or tuple(sorted(S)) in seen:
                continue
            seen.add(tuple(sorted(S)))
            T = self.exchange(S, fits)
            k = self.key(T)
            if best_key is None or _better(k, best_key):
                best, best_key = T, k
        return best


def _better(k1, k2, rtol=1e-10) -> bool:
    """Tuple ``k1`` strictly better (smaller) than ``k2``, ignoring round-off."""
    for a, b in zip(k1, k2):
        if abs(a - b) > rtol * max(abs(a), abs(b), 1e-300):
            return a < b
    return False


def brute_force(sel: Selector, size: int) -> tuple[list[int], float]:
    """Best subset of exactly ``size`` runs by exhaustive search (small catalogues; for tests)."""
    from itertools import combinations
    best, bv = None, np.inf
    for S in combinations(range(sel.R), size):
        v = sel.value(S)
        if v < bv:
            best, bv = list(S), v
    return best, bv
