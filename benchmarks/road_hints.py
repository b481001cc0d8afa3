"""The road fit's coupling hint on unknown roads: how much a trial high-pass cuts the residual, coupled or not.

On runs whose road nobody measured the road is free at every frequency and
takes up part of an AC coupling's signature, so the hint there names a group
of channels at a smaller cut (:data:`rideid.estimate.assess.sensor_check.FREE_ROAD_HINT_REDUCTION`)
than on tracks (:data:`~rideid.estimate.assess.sensor_check.HINT_REDUCTION`). This
script measures the separation the threshold rests on. Each case is
identified (``rideid.identify(ds, model="base", seed=1)``, the declaration as
the dataset gives it); at the car found, and at the true car, the trials of
:func:`rideid.estimate.assess.sensor_check.road_coupling_hints` (the hubs and the
body accelerometers as groups at every corner, each accelerometer alone at
three) are run and the best few printed as the change of the summed
residual (negative: the trial cuts it; positive: it makes it larger):

* ``hubs 0.5 Hz, undeclared``: the built-in car on two ISO 8608 roads, the hub
  accelerometers through an analog 0.5 Hz high-pass (``tests/coupled_case.py``), 2 % noise;
* ``hubs 0.5 Hz, declared``: the same data with the coupling declared;
* ``class B, not coupled``: ``examples/roads/class_b.toml`` simulated (4 roads, 1 % noise);
* ``class B, hubs 0.3 Hz undeclared``: the same recordings, the hubs through an analog 0.3 Hz high-pass.

Run: ``python benchmarks/road_hints.py`` (about 10 minutes on two cores).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import rideid  # noqa: E402
from rideid.cli import main as cli  # noqa: E402
from rideid.estimate.fit import anyroad  # noqa: E402
from rideid.estimate.problem import roadfit  # noqa: E402
from rideid.estimate.assess.sensor_check import (FREE_ROAD_HINT_REDUCTION, HINT_CORNERS, ROAD_HINT_GROUPS,  # noqa: E402
                                          ROAD_HINT_SINGLE)
from rideid.model.equations import CHANNELS  # noqa: E402
from rideid.model.params import ALL_NAMES, as_vector  # noqa: E402
from rideid.model.sensors import AnalogFilter  # noqa: E402


def trials(P, ds, rruns):
    """Every trial of the hint, best first: ``[(cut, corner Hz, channels)]``."""
    declared = {rr.run_id: [tuple(f) for f in ds.sensor_filters(rr.run_id)] for rr in rruns}

    def total(extra):
        tot = 0.0
        for rr in rruns:
            chain = list(declared[rr.run_id])
            for c, hz in extra.items():
                chain[c] = chain[c] + (AnalogFilter("highpass", hz),)
            e = roadfit.residuals(P, ds.geometry, roadfit.with_sensors(rr, tuple(chain)))
            tot += float(e @ e)
        return tot

    base = total({})
    out = []
    for g in ROAD_HINT_GROUPS:
        idx = [CHANNELS.index(n) for n in g]
        out += [(1 - total({c: hz for c in idx}) / base, hz, f"{g[0][:-3]} (4)") for hz in HINT_CORNERS]
    for c in range(8):
        out += [(1 - total({c: hz}) / base, hz, CHANNELS[c]) for hz in ROAD_HINT_SINGLE]
    return sorted(out, reverse=True)


def coupled_copy(src: Path, dst: Path, hz: float) -> Path:
    """``src`` with the hub accelerometers through an analog first-order high-pass (not declared)."""
    from sensor_case import analog_highpass
    shutil.copytree(src, dst)
    for f in (dst / "runs").glob("*.csv"):
        head = f.read_text().splitlines()[0]
        d = np.loadtxt(f, delimiter=",", skiprows=1)
        for c in range(4, 8):
            d[:, 1 + c] = analog_highpass(d[:, 0], d[:, 1 + c], hz)
        np.savetxt(f, d, delimiter=",", header=head, comments="", fmt="%.9g")
    return dst


def cases(tmp: Path):
    from coupled_case import write_roads_dataset
    yield "hubs 0.5 Hz, undeclared", write_roads_dataset(tmp / "undeclared", declare=False), None
    yield "hubs 0.5 Hz, declared", write_roads_dataset(tmp / "declared", declare=True), None
    sim = tmp / "classb"
    assert cli(["simulate", str(ROOT / "examples" / "roads" / "class_b.toml"), "--out", str(sim), "--noise", "0.01",
                "--seed", "1", "--quiet"]) == 0
    truth = tomllib.loads((sim / "truth.toml").read_text())["truth"]
    yield "class B, not coupled", sim, truth
    yield "class B, hubs 0.3 Hz undeclared", coupled_copy(sim, tmp / "classb_hubs", 0.3), truth


def main() -> int:
    print("# The road fit's coupling hint on unknown roads\n")
    print(f"threshold on unknown roads: a cut of {100 * FREE_ROAD_HINT_REDUCTION:.0f} % (on tracks as built: 50 %)\n")
    print("| case | largest error at the fit | best trials at the fit (residual change, corner, channels) "
          "| best at the truth | hint | time |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="rideid-road-hints-") as d:
        for name, folder, truth in cases(Path(d)):
            if truth is None:
                truth = tomllib.loads((folder / "truth.toml").read_text())["truth"]
            ds = rideid.load_dataset(folder)
            t = time.perf_counter()
            res = rideid.identify(ds, model="base", seed=1)
            wall = time.perf_counter() - t
            worst = max(truth, key=lambda n: abs(res.parameters[n] / truth[n] - 1))
            rruns = anyroad.prepare_road_runs(ds)
            P = as_vector({n: res.parameters.get(n, 0.0) for n in ALL_NAMES}, extended=True)
            Pt = as_vector({n: truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
            fit, at_truth = trials(P, ds, rruns)[:3], trials(Pt, ds, rruns)[:1]
            fmt = lambda ts: "; ".join(f"{-100 * c:+.0f} % at {hz:g} Hz on {g}" for c, hz, g in ts)  # noqa: E731
            hints = (res.adequacy or {}).get("sensor_hints") or []
            named = ", ".join(sorted({h["channel"] for h in hints})) or "none"
            print(f"| {name} | {worst} {100 * (res.parameters[worst] / truth[worst] - 1):+.2f} % | {fmt(fit)} | "
                  f"{fmt(at_truth)} | {named} | {wall:.0f} s |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
