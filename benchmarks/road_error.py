"""How close the estimated road of an unknown-road identification is to the true road, by wavelength band.

For each run of a simulated dataset with generated roads (``rideid simulate`` of a scenario whose runs have a
``road_class``: ``road_truth/<run>.csv``) and its identification (``FIT/road/<run>.csv``), both wheel
paths, the true road read at the estimate's ``x`` (both are measured from the front axle at the first
sample); the error is RMS(estimate - truth) / RMS(truth), over the run away from its first and last 20 m
("inner") and over the whole run ("whole"):

* "as filtered": the estimate against the truth through the same zero-phase 4th-order Butterworth
  band-pass to 0.5-20 m that the estimate is made with (:func:`rideid.estimate.problem.roadfit.band_pass`: half
  the amplitude at 0.5 m and 20 m);
* each band of :data:`BANDS`: the estimate's and the truth's content at those wavelengths alone (a DFT
  cut), with the estimate's least-squares amplitude on the truth's (``gain``; 1: the right size).

Run (docs/any-road.md, "Measured")::

    rideid simulate examples/roads/class_b.toml --out sim --noise 0.02 --seed 2
    rideid identify sim --out fit --seed 1 --no-report
    python benchmarks/road_error.py sim fit
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from rideid.estimate.problem.roadfit import band_pass

#: the estimated road's band (m), then the sub-bands reported
BANDS = ((0.5, 20.0), (0.5, 2.0), (2.0, 10.0), (10.0, 20.0))
#: the run's ends left out of the "inner" figures (m), as docs/any-road.md says they are less certain
ENDS = 20.0


def ideal_band(z: np.ndarray, dx: float, band) -> np.ndarray:
    """``z`` (n,) sampled every ``dx`` m with only its content at wavelengths within ``band`` (m) kept (DFT)."""
    Z = np.fft.rfft(z)
    n = np.fft.rfftfreq(z.size, dx)  # cycles/m
    Z[(n < 1.0 / band[1]) | (n > 1.0 / band[0])] = 0.0
    return np.fft.irfft(Z, n=z.size)


def run_errors(est: np.ndarray, tru: np.ndarray) -> list[dict]:
    """Per wheel path (left, right): ``{"filtered": {part: error}, band: {part: error, "gain": g}}``.

    ``est``: rows ``x, z_left, z_right`` of ``road/<run>.csv``; ``tru``: the same of ``road_truth/<run>.csv``.
    ``filtered``: against the truth through the same zero-phase band-pass the estimate is made with
    (:func:`rideid.estimate.problem.roadfit.band_pass`); each band of :data:`BANDS`: both with only their content at
    those wavelengths (:func:`ideal_band`), ``gain`` the least-squares amplitude of the estimate's on the
    truth's (1: the right size). ``part``: ``"inner"`` (away from the first and last 20 m) or ``"whole"``.
    """
    x = est[:, 0]
    dx = x[1] - x[0]
    parts = {"inner": (x > x[0] + ENDS) & (x < x[-1] - ENDS), "whole": np.ones(x.size, dtype=bool)}

    def rel(e, t):
        return {p: float(np.sqrt(np.mean((e[m] - t[m]) ** 2) / np.mean(t[m] ** 2))) for p, m in parts.items()}
    out = []
    for k in (1, 2):
        zt = np.interp(x, tru[:, 0], tru[:, k])
        rec = {"filtered": rel(est[:, k], band_pass(zt, dx, BANDS[0]))}
        for band in BANDS:
            e, t = ideal_band(est[:, k], dx, band), ideal_band(zt, dx, band)
            m = parts["inner"]
            rec[band] = {**rel(e, t), "gain": float(e[m] @ t[m] / (t[m] @ t[m]))}
        out.append(rec)
    return out


def main(sim: Path, fit: Path) -> list[dict]:
    rows = []
    for path in sorted((fit / "road").glob("*.csv")):
        if path.name.endswith(".response.csv"):
            continue
        rid = path.stem
        est = np.loadtxt(path, delimiter=",", skiprows=1)
        tru = np.loadtxt(sim / "road_truth" / f"{rid}.csv", delimiter=",", skiprows=1)
        for side, rec in zip(("left", "right"), run_errors(est, tru)):
            rows.append({"run": rid, "path": side, **rec})
    keys = ["filtered"] + list(BANDS)
    name = {k: "as filtered" if k == "filtered" else f"{k[0]:g}-{k[1]:g} m" for k in keys}
    print("RMS error / RMS of the truth, away from the ends (whole run) [gain]")
    print(" | ".join(["run", "path"] + [name[k] for k in keys]))
    for r in rows:
        cells = [f"{100 * r[k]['inner']:.1f} % ({100 * r[k]['whole']:.1f} %)"
                 + (f" [{r[k]['gain']:.3f}]" if "gain" in r[k] else "") for k in keys]
        print(" | ".join([r["run"], r["path"]] + cells))
    for k in keys:
        line = [f"{min(100 * r[k][p] for r in rows):.1f}-{max(100 * r[k][p] for r in rows):.1f} % {p}"
                for p in ("inner", "whole")]
        if k != "filtered":
            line.append(f"gain {min(r[k]['gain'] for r in rows):.3f}-{max(r[k]['gain'] for r in rows):.3f}")
        print(f"{name[k]}: " + ", ".join(line))
    return rows


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python benchmarks/road_error.py SIM_DIR FIT_DIR")
    main(Path(sys.argv[1]), Path(sys.argv[2]))
