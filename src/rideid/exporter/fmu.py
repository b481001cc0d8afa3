"""``car.fmu``: the identified car as an FMI 2.0 FMU, Model Exchange and Co-Simulation in one (SPEC §10, §13).

The FMU is generated C (``c/model.c.in``, the FMI 2.0 API declared in
``c/fmi2_api.h``) with the car's numbers as the parameters' start values,
compiled with the system C compiler into ``binaries/<platform>/car.so``.
It always carries its sources (``sources/``, listed in
``modelDescription.xml``), so another platform's tool can build it.

Variables (value references):

* inputs ``r_fl, r_fr, r_rl, r_rr`` (0-3; road input under each wheel, m:
  the tire envelope of SPEC §2) and ``rdot_fl ... rdot_rr`` (4-7; their
  rates, m/s, which drive the tire dampers of SPEC §6);
* outputs the ten channels of SPEC §1 by name (8-17) and, for a car with a
  powertrain on mounts (SPEC §11, :data:`POWERTRAIN_OUTPUTS`, 18-21), the
  powertrain's CG vertical acceleration and pitch rate and its heave and pitch
  relative to the body (``u_p``, ``psi_p``: the mounts' deflections);
* Real parameters from 100: the sixteen of SPEC §1/§6 (with a powertrain, its
  seven after them: ``m_p, x_p, I_p, f_pb, zeta_pb, f_pp, zeta_pp``), the geometry
  (``wheelbase``, ``track_front``, ``track_rear``, ``cg_height``), ``gravity``,
  the bump stops (``bs_clear_*``, ``bs_rate_*``; rate 0 without stops),
  ``max_step`` (the longest RK4 sub-step, s) and with damper curves the knots
  ``damper_v1..K`` (m/s) and the forces ``F_f1..K``, ``F_r1..K`` (N);
* Boolean parameter ``lift_off`` (0): the tires push but never pull (true
  for a car with damper curves or bump stops, as ``rideid simulate`` has it);
* after all of these in ``modelDescription.xml`` (no index of before moves), the continuous states of Model
  Exchange (:func:`states`: ``state.z ... state.z_rr``, with a powertrain ``state.u_p, state.psi_p``, then their
  rates ``state.z_dot ...``; from 1000) and their derivatives (``der(state.z) ...``; from 2000).

Model Exchange has no event indicators: the bump stops, lift-off and the damper curves' knots are kinks of a
continuous right-hand side. Between the times the master sets them the road inputs are carried on along their
rates, and ``fmi2CompletedIntegratorStep`` asks for an event where the master sets them off that road, so that
the master restarts its integrator at the jump (docs/export.md).
"""

from __future__ import annotations

import math
import os
import shlex
import shutil
import subprocess
import sys
import uuid
import zipfile
from importlib import resources
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from ..model.equations import CHANNELS, CHANNEL_UNITS, state_space
from ..model.params import ALL_NAMES, DESCRIPTIONS, GRAVITY, POWERTRAIN_NAMES, SUSPENSION_NAMES
from ..model.nonlinear import M_MAX, NonlinearLayout, substeps
from .car import CARD_UNITS, Car

#: the FMU's model identifier (the binary's and the FMU's name)
MODEL_IDENTIFIER = "car"
#: RK4 sub-step bound: ``max_step * max|eig|`` of the stiffest linearised car (spring plus bump-stop rate,
#: the steepest damper segment); 0.01 keeps the FMU within 1e-5 of rideid's own simulation (tests/test_export.py)
RHO = 0.01
INPUTS = ("r_fl", "r_fr", "r_rl", "r_rr", "rdot_fl", "rdot_fr", "rdot_rl", "rdot_rr")
VR_OUTPUT0, VR_PAR0 = 8, 100
#: value references of the continuous states (Model Exchange) and of their derivatives
VR_STATE0, VR_DER0 = 1000, 2000
#: the coordinates q of the 7-DOF car (the states are q and q'): name, unit, description
COORDINATES = (("z", "m", "body heave at the sprung-mass CG"), ("theta", "rad", "body pitch (nose-down +)"),
               ("phi", "rad", "body roll (right side down +)"),
               *((f"z_{c}", "m", f"wheel heave {c}") for c in ("fl", "fr", "rl", "rr")))
#: the two a powertrain on mounts adds (SPEC §11)
POWERTRAIN_COORDINATES = (("u_p", "m", "powertrain heave relative to the body point beneath it"),
                          ("psi_p", "rad", "powertrain pitch relative to the body"))
#: SI base-unit exponents of every unit the FMU names (FMI 2.0 ``<BaseUnit>``), so a tool can convert them
BASE_UNITS = {"m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "m/s^2": {"m": 1, "s": -2}, "rad/s": {"rad": 1, "s": -1},
              "s": {"s": 1}, "kg": {"kg": 1}, "kg m^2": {"kg": 1, "m": 2}, "N": {"kg": 1, "m": 1, "s": -2},
              "N/m": {"kg": 1, "s": -2}, "N s/m": {"kg": 1, "s": -1}, "Hz": {"s": -1}, "rad": {"rad": 1},
              "rad/s^2": {"rad": 1, "s": -2}}
#: the parameters of the FMU's equations: the twelve and SPEC §6's four; a car with a powertrain on mounts
#: (SPEC §11) has :data:`rideid.model.params.POWERTRAIN_NAMES` after them
FMU_NAMES = SUSPENSION_NAMES
#: the outputs a car with a powertrain on mounts adds after the ten channels: name, unit, description
POWERTRAIN_OUTPUTS = (
    ("powertrain_az", "m/s^2", "vertical acceleration of the powertrain CG (z'' - x_p theta'' + u_p'')"),
    ("powertrain_pitch_rate", "rad/s", "powertrain pitch rate (theta' + psi_p', ISO 8855 sign)"),
    ("u_p", "m", "powertrain heave relative to the body point beneath it (mount deflection)"),
    ("psi_p", "rad", "powertrain pitch relative to the body (mount deflection)"),
)
#: the relative tolerance the FMU proposes to a variable-step solver of its Model Exchange interface
#: (``<DefaultExperiment tolerance>``; FMPy's CVode takes it): 1e-8 keeps every channel within 1e-4 of its RMS of
#: ``rideid simulate`` at a 20x finer grid than the data (docs/export.md); the states' nominal values (1 mm, 1 cm/s)
#: scale the absolute tolerances
TOLERANCE = 1e-8
#: the big clearance standing for "no bump stop" (m); with rate 0 it is never reached anyway
NO_STOP = 1e6


def platform_folder() -> str:
    """FMI 2.0 binaries folder of this platform (``linux64``, ``darwin64``, ``win64``)."""
    bits = "64" if sys.maxsize > 2 ** 32 else "32"
    return {"linux": "linux", "darwin": "darwin", "win32": "win"}.get(sys.platform, sys.platform) + bits


def binary_suffix() -> str:
    """The shared library's file suffix on this platform."""
    return {"darwin": ".dylib", "win32": ".dll"}.get(sys.platform, ".so")


def outputs(car: Car) -> list[tuple[str, str, str]]:
    """The FMU's outputs in value-reference order: ``[(name, unit, description), ...]``."""
    out = [(c, CHANNEL_UNITS[c], f"SPEC channel {c}") for c in CHANNELS]
    return out + (list(POWERTRAIN_OUTPUTS) if car.powertrain else [])


def states(car: Car) -> list[tuple[str, str, str]]:
    """The continuous states in the order of ``fmi2GetContinuousStates``: ``[(name, unit, description), ...]``:
    the coordinates (``state.z`` ...), then their rates (``state.z_dot`` ...); value references from
    :data:`VR_STATE0`, their derivatives (``der(state.z)`` ...) from :data:`VR_DER0`."""
    q = list(COORDINATES) + (list(POWERTRAIN_COORDINATES) if car.powertrain else [])
    return ([(f"state.{n}", u, d + " (from static equilibrium)") for n, u, d in q]
            + [(f"state.{n}_dot", u + "/s", f"rate of {n}") for n, u, _ in q])


def _parameters(car: Car):
    """``[(name, value, unit, description, variability), ...]`` in value-reference order."""
    v, g = car.values, car.geometry
    names = FMU_NAMES + (POWERTRAIN_NAMES if car.powertrain else ())
    out = [(n, v[n], "" if CARD_UNITS[n] == "1" else CARD_UNITS[n], DESCRIPTIONS[n], "tunable")  # ratio: no unit
           for n in names]
    out += [("wheelbase", g.wheelbase, "m", "wheelbase", "fixed"),
            ("track_front", g.track_front, "m", "front track", "fixed"),
            ("track_rear", g.track_rear, "m", "rear track", "fixed"),
            ("cg_height", g.cg_height, "m", "sprung-mass CG above the wheel centres", "fixed"),
            ("gravity", GRAVITY, "m/s^2", "gravity (CG height terms, static loads for lift-off)", "fixed")]
    bs = car.bump_stops
    for ax, axle in (("f", "front"), ("r", "rear")):
        clear = bs.get(f"bs_clear_{ax}", NO_STOP)
        out.append((f"bs_clear_{ax}", clear if math.isfinite(clear) else NO_STOP, "m",
                    f"bump-stop clearance, {axle} (compression from static ride height)", "tunable"))
    for ax, axle in (("f", "front"), ("r", "rear")):
        out.append((f"bs_rate_{ax}", bs.get(f"bs_rate_{ax}", 0.0), "N/m", f"bump-stop rate, {axle}", "tunable"))
    out.append(("max_step", max_step(car), "s", "longest RK4 sub-step within a communication step", "fixed"))
    if car.dampers is not None:
        d = car.dampers
        out += [(f"damper_v{k + 1}", x, "m/s", "damper curve knot velocity (compression +)", "fixed")
                for k, x in enumerate(d.velocity)]
        out += [(f"F_f{k + 1}", F, "N", f"front damper force at damper_v{k + 1}", "tunable")
                for k, F in enumerate(d.front)]
        out += [(f"F_r{k + 1}", F, "N", f"rear damper force at damper_v{k + 1}", "tunable")
                for k, F in enumerate(d.rear)]
    return out


def max_step(car: Car, rho: float = RHO) -> float:
    """Longest RK4 sub-step (s): ``rho / max|eig|`` of the stiffest linearised car
    (:func:`rideid.model.nonlinear.substeps`: at most ``M_MAX`` sub-steps a second; with a powertrain, of the
    9-DOF car's state matrix too)."""
    layout = NonlinearLayout(knots=None if car.dampers is None else car.dampers.velocity,
                             bump_stops=bool(car.bump_stops))
    row = [car.values.get(n, 0.0) for n in FMU_NAMES]
    if car.bump_stops:
        bs = car.bump_stops
        row += [bs.get("bs_clear_f", 1.0), bs.get("bs_clear_r", 1.0), bs.get("bs_rate_f", 0.0),
                bs.get("bs_rate_r", 0.0)]
        row[-4:-2] = [c if math.isfinite(c) else 1.0 for c in row[-4:-2]]
    if car.dampers is not None:
        row += list(car.dampers.front) + list(car.dampers.rear)
    m = substeps(np.array(row)[None], car.geometry, layout, 1.0, rho=rho)
    if car.powertrain:  # linear (no curves, no stops: refused by rideid.export); the same bound, M_MAX included
        A = state_space(np.array([[car.values.get(n, 0.0) for n in ALL_NAMES]]), car.geometry)[0][0]
        lam = float(np.abs(np.linalg.eigvals(A)).max())
        m = max(m, min(M_MAX, math.ceil(lam / rho - 1e-9)))
    return 1.0 / m


def _num(x: float) -> str:
    return repr(float(x))


def c_source(car: Car, guid: str) -> str:
    """``model.c``: the template with this car's parameter table."""
    pars = _parameters(car)
    defines = [f"#define P_{n} {i}" for i, (n, *_rest) in enumerate(pars)
               if not (n.startswith("damper_v") or n.startswith("F_"))]
    K = 0 if car.dampers is None else len(car.dampers.velocity)
    if K:
        names = [p[0] for p in pars]
        defines += [f"#define P_V0 {names.index('damper_v1')}", f"#define P_FF0 {names.index('F_f1')}",
                    f"#define P_FR0 {names.index('F_r1')}"]
    text = (resources.files(__package__) / "c" / "model.c.in").read_text()
    subs = {"@GUID@": guid, "@N_PAR@": str(len(pars)), "@N_KNOTS@": str(K), "@PARAM_DEFINES@": "\n".join(defines),
            "@DEFAULTS@": ",\n".join(f"    {_num(p[1])} /* {p[0]} */" for p in pars),
            "@LIFT_OFF@": "1" if car.nonlinear else "0", "@POWERTRAIN@": "1" if car.powertrain else "0"}
    for k, s in subs.items():
        text = text.replace(k, s)
    return text


def _description(car: Car) -> str:
    if car.powertrain:
        return "9-DOF ride model of the identified car, a powertrain on mounts in it (rideid, SPEC 1, 6, 11)"
    return "7-DOF ride model of the identified car (rideid, SPEC 1, 6, 8)"


def model_description(car: Car, guid: str) -> str:
    """``modelDescription.xml`` (FMI 2.0: Model Exchange and Co-Simulation)."""
    pars = _parameters(car)
    outs = outputs(car)
    xs = states(car)
    ders = [(f"der({n})", _der_unit(u), f"derivative of {n}") for n, u, _ in xs]
    units = sorted({p[2] for p in pars} | {o[1] for o in outs} | {x[1] for x in xs + ders} | {"m", "m/s"})
    units = [u for u in units if u]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<fmiModelDescription fmiVersion="2.0" modelName="rideid car" '
             f'guid="{guid}" description="{_description(car)}" '
             'generationTool="rideid export" variableNamingConvention="flat" numberOfEventIndicators="0">',
             f'  <ModelExchange modelIdentifier="{MODEL_IDENTIFIER}" completedIntegratorStepNotNeeded="false" '
             'canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true">',
             '    <SourceFiles>', '      <File name="model.c"/>', '    </SourceFiles>',
             '  </ModelExchange>',
             f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" canHandleVariableCommunicationStepSize="true" '
             'canInterpolateInputs="true" maxOutputDerivativeOrder="0" canBeInstantiatedOnlyOncePerProcess="false" '
             'canNotUseMemoryManagementFunctions="true">',
             '    <SourceFiles>', '      <File name="model.c"/>', '    </SourceFiles>',
             '  </CoSimulation>', '  <UnitDefinitions>']
    for u in units:
        base = " ".join(f'{k}="{v}"' for k, v in BASE_UNITS[u].items())
        lines += [f'    <Unit name="{escape(u)}">', f'      <BaseUnit {base}/>', '    </Unit>']
    lines += ['  </UnitDefinitions>',
              f'  <DefaultExperiment startTime="0.0" stopTime="10.0" tolerance="{TOLERANCE:g}"/>',
              '  <ModelVariables>']
    idx = 0

    def var(name, vr, causality, variability, description, inner):
        nonlocal idx
        idx += 1
        lines.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
                     f'variability="{variability}" description="{escape(description)}">')
        lines.append(f'      {inner}')
        lines.append('    </ScalarVariable>')
        return idx

    for k, n in enumerate(INPUTS):
        corner = n.split("_")[1]
        desc = (f"road input under wheel {corner} (tire envelope), m" if k < 4
                else f"rate of the road input under wheel {corner}, m/s")
        var(n, k, "input", "continuous", desc, f'<Real unit="{"m" if k < 4 else "m/s"}" start="0.0"/>')
    indices = [var(c, VR_OUTPUT0 + k, "output", "continuous", desc, f'<Real unit="{escape(unit)}"/>')
               for k, (c, unit, desc) in enumerate(outs)]
    for k, (n, v, unit, desc, variability) in enumerate(pars):
        u = f' unit="{escape(unit)}"' if unit else ""
        var(n, VR_PAR0 + k, "parameter", variability, desc, f'<Real{u} start="{_num(v)}"/>')
    var("lift_off", 0, "parameter", "fixed", "tires push but never pull (the nonlinear car of SPEC 8)",
        f'<Boolean start="{"true" if car.nonlinear else "false"}"/>')
    # the continuous states (start: static equilibrium for the inputs at the end of initialisation) and their
    # derivatives; q' is a state itself, so der(q) depends on that state alone
    x_idx = [var(n, VR_STATE0 + k, "local", "continuous", d, f'<Real unit="{escape(u)}"/>')
             for k, (n, u, d) in enumerate(xs)]
    d_idx = [var(n, VR_DER0 + k, "local", "continuous", d,
                 f'<Real unit="{escape(u)}" derivative="{x_idx[k]}"/>') for k, (n, u, d) in enumerate(ders)]
    nq = len(xs) // 2
    lines += ['  </ModelVariables>', '  <ModelStructure>', '    <Outputs>']
    lines += [f'      <Unknown index="{i}"/>' for i in indices]
    lines += ['    </Outputs>', '    <Derivatives>']
    lines += [f'      <Unknown index="{i}" dependencies="{x_idx[k + nq]}" dependenciesKind="constant"/>'
              if k < nq else f'      <Unknown index="{i}"/>' for k, i in enumerate(d_idx)]
    lines += ['    </Derivatives>', '    <InitialUnknowns>']
    lines += [f'      <Unknown index="{i}"/>' for i in indices + x_idx + d_idx]
    lines += ['    </InitialUnknowns>', '  </ModelStructure>', '</fmiModelDescription>']
    return "\n".join(lines) + "\n"


def _der_unit(unit: str) -> str:
    """The unit of a quantity's time derivative (m -> m/s, m/s -> m/s^2)."""
    return unit[:-2] + "/s^2" if unit.endswith("/s") else unit + "/s"


class NoBinary(Exception):
    """Why ``car.fmu`` carries no binary: no C compiler, or the compiler failed (its message)."""


def find_compiler() -> list[str]:
    """The C compiler: ``$CC`` (with its flags) if set, else ``cc`` on the PATH.

    Raises
    ------
    NoBinary
        ``$CC`` names no program on the PATH, or neither is set nor ``cc`` found.
    """
    cc = os.environ.get("CC")
    if cc:
        args = shlex.split(cc)
        if not args or not shutil.which(args[0]):
            raise NoBinary(f"the C compiler CC={cc!r} is not on the PATH")
        return args
    found = shutil.which("cc")
    if not found:
        raise NoBinary("no C compiler found (set CC or install cc)")
    return [found]


def write_fmu(car: Car, path, compiler="auto", workdir=None) -> str | None:
    """Write ``car.fmu`` at ``path``.

    Parameters
    ----------
    car : Car
    path : Path
        The FMU file to write.
    compiler : "auto", None or list of str
        ``"auto"``: :func:`find_compiler`; None: write a source-only FMU.
    workdir : Path, optional
        Scratch folder for the build (default: beside ``path``).

    Returns
    -------
    str or None
        None when the FMU carries a binary; else why it carries its sources only (no compiler, or the
        compiler's first error line), one line to show the user.
    """
    path = Path(path)
    guid = "{" + str(uuid.uuid4()) + "}"
    build = Path(workdir or path.parent) / "fmu-build"
    src = build / "sources"
    src.mkdir(parents=True, exist_ok=True)
    (src / "model.c").write_text(c_source(car, guid))
    (src / "fmi2_api.h").write_text((resources.files(__package__) / "c" / "fmi2_api.h").read_text())
    (build / "modelDescription.xml").write_text(model_description(car, guid))
    try:
        _compile(find_compiler() if compiler == "auto" else compiler, build, src)
        why = None
    except NoBinary as e:
        shutil.rmtree(build / "binaries", ignore_errors=True)
        why = str(e)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(build.rglob("*")):
            if f.is_file():
                z.write(f, f.relative_to(build).as_posix())
    shutil.rmtree(build, ignore_errors=True)
    return why


def _compile(cc, build: Path, src: Path) -> None:
    """Build ``binaries/<platform>/car.<suffix>`` in ``build`` with compiler command ``cc`` (None: none).

    Raises
    ------
    NoBinary
        No compiler, or the compiler failed to start or to build (its first error line).
    """
    if not cc:
        raise NoBinary("no C compiler asked for")
    bdir = build / "binaries" / platform_folder()
    bdir.mkdir(parents=True, exist_ok=True)
    binary = bdir / f"{MODEL_IDENTIFIER}{binary_suffix()}"
    cmd = [*cc, "-shared", "-fPIC", "-O2", "-fvisibility=hidden", "-o", str(binary), str(src / "model.c"), "-lm"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as e:
        raise NoBinary(f"the C compiler {cc[0]!r} could not be run: {e.strerror or e}") from None
    if proc.returncode != 0 or not binary.is_file():
        first = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}, no message"])[0]
        raise NoBinary(f"the C compiler {shlex.join(cc)!r} failed: {first}")


__all__ = ["write_fmu", "model_description", "c_source", "find_compiler", "max_step", "outputs", "states", "INPUTS",
           "MODEL_IDENTIFIER", "POWERTRAIN_OUTPUTS", "NoBinary"]
