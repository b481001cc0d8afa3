"""Driving ``car.fmu`` with FMPy: a master loop of rideid's own, for the closest match to ``rideid simulate``.

Any FMI master drives the FMU, through either interface (FMPy's ``simulate_fmu``
at 1/20 of a data sample per step: every channel within 3e-5 of ``rideid
simulate`` in Co-Simulation, 7e-5 in Model Exchange with CVode;
docs/export.md): in Co-Simulation without input derivatives the FMU follows each road input
along its rate input and takes a step again once the inputs at its end are
set. :func:`drive_fmu` does better at coarser steps because it sets the
inputs of an instant before it reads that instant's outputs (they are direct
feedthrough of the inputs) and hands the FMU the cubic Hermite through the
road and its rate at both ends of each step as input derivatives
(``fmi2SetRealInputDerivatives``, orders 1-3), on FMPy's ``FMU2Slave``.
``pip install fmpy`` (the ``test`` extra has it)."""

from __future__ import annotations

import shutil

import numpy as np

from ..errors import ArgumentError
from ..model.equations import CHANNELS
from .fmu import INPUTS

#: communication points per sample interval: the road between the samples as a cubic Hermite (docs/export.md)
DEFAULT_SUB = 16


def drive_fmu(path, t, r, rdot, sub: int = DEFAULT_SUB, outputs=CHANNELS) -> np.ndarray:
    """The outputs of ``car.fmu`` (default the ten channels) at the samples ``t``, driven with the road inputs
    ``r``, ``rdot``.

    Parameters
    ----------
    path : str or Path
        The FMU (:func:`rideid.export`).
    t : ndarray, shape (n,)
        Uniform sample times (s); the outputs are read there.
    r, rdot : ndarray, shape ((n - 1) * sub + 1, 4)
        Road input under each wheel (m; the tire envelope, SPEC §2) and its rate (m/s) at ``sub`` points per
        sample interval, e.g. ``rideid.model.simulate.prepare_run(track, geometry, speed, t).inputs_at(tf)``
        at ``tf = t[0] + arange((n - 1) * sub + 1) * (t[1] - t[0]) / sub``.
    sub : int
        Communication points per sample interval.
    outputs : sequence of str
        The outputs to read, by name: the ten SPEC channels by default; a car with a powertrain on mounts also
        has ``powertrain_az, powertrain_pitch_rate, u_p, psi_p`` (:data:`rideid.exporter.fmu.POWERTRAIN_OUTPUTS`).

    Returns
    -------
    ndarray, shape (n, len(outputs))
        The outputs in the order asked (default SPEC order, ``body_az_fl ... roll_rate``). The FMU starts at rest
        on the road of the first point, as ``rideid simulate`` starts.

    Raises
    ------
    ArgumentError
        FMPy missing, inputs of the wrong shape, an output the FMU does not have (named).
    """
    try:
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
    except ImportError:
        raise ArgumentError("driving an FMU needs FMPy: pip install fmpy") from None
    t, r, rdot = np.asarray(t, dtype=float), np.asarray(r, dtype=float), np.asarray(rdot, dtype=float)
    m = (t.size - 1) * sub + 1
    if r.shape != (m, 4) or rdot.shape != (m, 4):
        raise ArgumentError(f"r and rdot must have shape ({m}, 4): (len(t) - 1) * sub + 1 points, got {r.shape} "
                            f"and {rdot.shape}")
    md = read_model_description(str(path))
    unzipped = extract(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    vin = [vr[n] for n in INPUTS]
    unknown = [c for c in outputs if c not in vr]
    if unknown:
        shutil.rmtree(unzipped, ignore_errors=True)
        raise ArgumentError(f"outputs: {path} has no variable {unknown[0]!r}")
    vout = [vr[c] for c in outputs]
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="car")
    s.instantiate()
    try:
        s.setupExperiment(startTime=float(t[0]))
        s.enterInitializationMode()
        s.setReal(vin, list(np.r_[r[0], rdot[0]]))
        s.exitInitializationMode()
        dt = (t[1] - t[0]) / sub
        Y = np.empty((t.size, len(vout)))
        for k in range(m):
            s.setReal(vin, list(np.r_[r[k], rdot[k]]))
            if k % sub == 0:
                Y[k // sub] = s.getReal(vout)
            if k + 1 < m:
                dr, d0, d1 = r[k + 1] - r[k], rdot[k], rdot[k + 1]
                s.setRealInputDerivatives(vin[:4], [1] * 4, list(d0))
                s.setRealInputDerivatives(vin[:4], [2] * 4, list((6 * dr / dt - 4 * d0 - 2 * d1) / dt))
                s.setRealInputDerivatives(vin[:4], [3] * 4, list((-12 * dr / dt + 6 * (d0 + d1)) / dt ** 2))
                s.setRealInputDerivatives(vin[4:], [1] * 4, list((d1 - d0) / dt))
                s.doStep(float(t[0] + k * dt), dt)
        s.terminate()
    finally:
        s.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
    return Y


__all__ = ["drive_fmu", "DEFAULT_SUB"]
