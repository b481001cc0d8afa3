"""The nonlinear kernel's sub-steps as LLVM IR over ``<4 x double>`` vectors (used by :mod:`rideid.model.kernel_nl`).

Four candidates are integrated side by side, one per lane, as the linear
kernel does (:mod:`rideid.model.kernel_ir`): every state, derivative and
switching quantity is one vector, every per-candidate coefficient one
vector load from the chunk's lane-innermost block (:data:`ENTRIES`), the
road inputs are broadcast. Four functions, called by the Numba driver
:func:`run_chunks` (here, beside the IR: Numba's disk cache follows the
source file of the function it compiles, so an edit of the IR renews the
driver's cache):

* :data:`END` evaluates the right-hand side at a state (derivative,
  accelerations and the switching quantities: deflections, damper
  velocities and their rates, tire loads, kink counts);
* :data:`STEP` takes one plain RK4 sub-step from the states in one buffer
  into another and evaluates its end (the next sub-step's first stage); it
  returns the lanes where a switching quantity changed side (a damper
  velocity crossed a kink, a deflection the bump-stop clearance, a tire
  load zero);
* :data:`PIECES` redoes such a sub-step in pieces ending at the crossings,
  every lane its own pieces (``theta``, found and sorted by the driver,
  padded with 1): a lane's piece of zero length leaves it unchanged, and
  only the lanes asked for take the result, so no lane's numbers depend on
  its neighbours';
* :data:`ERR` adds a sample's weighted squared errors of the ten channels
  to the lanes' sums.

The right-hand side is one internal function (three variants: road inputs
broadcast from a table row or a vector per lane, with or without the
switching quantities) that loads its own coefficients: inlined four times
into a sub-step, LLVM kept every coefficient of every stage live across the
step and spilled most of them.

The damper curves: each lane keeps its corners' last two curve segments
(bounds ``[lo, hi)``, intercept ``A``, slope ``S``, kink count; the
segment cache ``SC``); a corner whose four lanes all stay inside their
last takes them as they are (``D(v) = A + S v``), one whose lanes are each
inside one of their two takes those (a sub-step redone in pieces goes back
and forth across a kink), else the segments are found again by one compare
and select per interior knot (the same table entries either way, so the
numbers do not depend on the cache). Segment ``j`` is
the count of interior knots at or below the velocity; ``A_j = F_j - S_j v_j``.
Without curves the table has one segment, ``A = 0``, ``S = c_s``.

Floating-point operations carry only the ``contract`` flag (fused
multiply-adds): no reassociation, and infinities and NaNs keep their IEEE
meaning (a car without bump stops has an infinite clearance). The moments'
products are not fused, so a symmetric car's left and right cancel exactly
(it does not roll).

All pointers are passed as 64-bit integers; each array is laid out
``[entry][lane]`` (four doubles per entry).
"""

from __future__ import annotations

import struct

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .kernel_ir import IRWriter, ir_library
from .nl_coef import PT_COEF, hermite_value_slope

#: candidates per vector: two AVX2 registers of doubles (LLVM splits each operation in two)
LANES = 4
V = f"<{LANES} x double>"
VB = f"<{LANES} x i1>"
FL = "contract"
TRUE = f"<{', '.join(['i1 true'] * LANES)}>"

#: per-candidate entries of a chunk's coefficient block (each ``LANES`` doubles), car-wide then per corner
CAR = ("inv_ms", "inv_Iyy", "inv_Ixx", "topple", "kar_f", "kar_r")
CORNER = ("x", "y", "ks", "kt", "ct", "inv_mu", "ctm", "L", "neg_L", "bs_clear", "bs_rate")
ENTRIES = CAR + tuple(f"{n}{c}" for c in range(4) for n in CORNER)
#: with a powertrain on mounts (SPEC §11) its entries follow (:data:`rideid.model.nl_coef.PT_COEF`): the car's
#: keep their places
ENTRIES_PT = ENTRIES + PT_COEF
E = {n: i for i, n in enumerate(ENTRIES_PT)}
#: states per candidate: the car's 14, and with a powertrain its heave and pitch on the mounts and their rates
NX = {False: 14, True: 18}
#: the switching quantities per corner, in the SW arrays ``[quantity][corner][lane]``
SWQ = ("d", "v", "g", "vd", "kap")
N_SW = len(SWQ) * 4
#: the damper segment cache, two entries per corner, ``SC[entry][quantity][corner][lane]``: bounds
#: ``[lo, hi)``, intercept, slope, kink count
SEG = ("lo", "hi", "A", "S", "kap")
N_SC = 2 * len(SEG) * 4

END = "rideid_nl_end"
STEP = "rideid_nl_step"
PIECES = "rideid_nl_pieces"
ERR = "rideid_nl_err"

#: common leading arguments: coefficients, curve tables (intercepts then slopes, ``[corner][segment][lane]``),
#: interior knots then inf (nk + 1), kink flags (2 axles x nk, 1.0 or 0.0), interior knot count, segments per
#: curve (nk + 1), segment cache
COMMON = (("cf", "ptr"), ("tb", "ptr"), ("xk", "ptr"), ("kf", "ptr"), ("nk", "i64"), ("ns", "i64"), ("SC", "ptr"))
ARGS = {
    END: COMMON + (("X", "ptr"), ("u", "ptr"), ("r", "ptr"), ("D", "ptr"), ("Q", "ptr"), ("SW", "ptr")),
    STEP: COMMON + (("Xa", "ptr"), ("Da", "ptr"), ("SWa", "ptr"), ("Xb", "ptr"), ("Db", "ptr"), ("Qb", "ptr"),
                    ("SWb", "ptr"), ("u1", "ptr"), ("r1", "ptr"), ("u2", "ptr"), ("r2", "ptr"), ("h", "double")),
    PIECES: COMMON + (("Xa", "ptr"), ("Da", "ptr"), ("Xb", "ptr"), ("Db", "ptr"), ("Qb", "ptr"), ("SWb", "ptr"),
                      ("TH", "ptr"), ("np", "i64"), ("u0", "ptr"), ("r0", "ptr"), ("u1", "ptr"), ("r1", "ptr"),
                      ("u2", "ptr"), ("r2", "ptr"), ("h", "double"), ("mask", "i64")),
}
ARGS[ERR] = (("cf", "ptr"), ("X", "ptr"), ("Q", "ptr"), ("Y", "ptr"), ("W", "ptr"), ("E", "ptr"))
RETURNS = {END: "void", STEP: "i64", PIECES: "void", ERR: "void"}
#: the right-hand side's variants: (inputs as table rows to broadcast, switching quantities)
RHS = {(True, False): "rideid_nl_rhs_row", (True, True): "rideid_nl_rhs_row_end",
       (False, False): "rideid_nl_rhs_vec"}
#: the powertrain's variant of a function: its name with this suffix (the same arguments)
PT = "_pt"
_LINKAGE = "internal"
_RHS_PARAMS = ("cf", "tb", "tbs", "xk", "kf", "nk", "ns", "SC")


def _dconst(x: float) -> str:
    """An LLVM double literal (hexadecimal: exact)."""
    return "0x%016X" % struct.unpack("<Q", struct.pack("<d", float(x)))[0]


class _W(IRWriter):
    """IR lines with numbered temporaries (as :class:`rideid.model.kernel_ir.IRWriter`, over vectors of
    :data:`LANES`); ``opaque``: LLVM's opaque pointers (LLVM >= 17), else typed ones. Tracks the current
    basic block (for phi nodes)."""

    def __init__(self, opaque: bool = True, pt: bool = False):
        super().__init__(opaque)
        self.pt = pt
        self.nx = NX[pt]
        self.sfx = PT if pt else ""
        self.block = "entry"
        self.labels = 0
        self.invariant = False  # loads marked !invariant.load (memory that the function does not write)

    def vload(self, base, offset):
        inv = ", !invariant.load !1" if self.invariant else ""
        return self.tmp(f"load {V}, {self.vp} {self.vptr(self.ptr(base, offset))}, align 8{inv}")

    def bcast(self, base, offset):
        """The double ``offset`` after ``base`` in every lane."""
        inv = ", !invariant.load !1" if self.invariant else ""
        return self.splat(self.tmp(f"load double, {self.dp} {self.ptr(base, offset)}, align 8{inv}"))

    def splat(self, s):
        """The double value ``s`` in every lane."""
        v = self.tmp(f"insertelement {V} poison, double {s}, i64 0")
        return self.tmp(f"shufflevector {V} {v}, {V} poison, <{LANES} x i32> zeroinitializer")

    def label(self, name):
        self.labels += 1
        return f"{name}{self.labels}"

    def start(self, label):
        self(f"{label}:")
        self.block = label

    def e(self, name):
        """Coefficient entry ``name`` of the chunk (four lanes)."""
        return self.coef("%cf", E[name])

    def at(self, base, i):
        """Vector ``i`` of a ``[entry][lane]`` array."""
        return self.vload(base, i * LANES)

    def put(self, value, base, i):
        self.vstore(value, self.ptr(base, i * LANES))

    def c(self, x):
        """A double constant in all lanes."""
        return self.splat(_dconst(x))

    def stack(self, n):
        """A pointer (to doubles) to ``n`` vectors on the stack."""
        p = self.tmp(f"alloca {V}, i64 {n}, align 32")
        return p if self.opaque else self.tmp(f"bitcast {V}* {p} to double*")

    def fmul(self, a, b):
        return self.tmp(f"fmul {FL} {V} {a}, {b}")

    def fadd(self, a, b):
        return self.tmp(f"fadd {FL} {V} {a}, {b}")

    def fsub(self, a, b):
        return self.tmp(f"fsub {FL} {V} {a}, {b}")

    def xop(self, op, a, b):
        """``a op b`` rounded on its own (never fused)."""
        return self.tmp(f"{op} {V} {a}, {b}")

    def madd(self, a, b, c):
        """``a * b + c`` (contracted to one fused multiply-add)."""
        return self.fadd(self.fmul(a, b), c)

    def cmp(self, op, a, b):
        return self.tmp(f"fcmp {op} {V} {a}, {b}")

    def sel(self, m, a, b):
        return self.tmp(f"select {VB} {m}, {V} {a}, {V} {b}")

    def call_rhs(self, row, ends, X, u, r, D, Q=None, SW=None):
        dp = self.dp
        args = [f"{dp} %{p}" if p not in ("nk", "ns") else f"i64 %{p}" for p in _RHS_PARAMS]
        args += [f"{dp} {p}" for p in (X, u, r, D) + ((Q, SW) if ends else ())]
        self(f"  call fastcc void @{RHS[row, ends]}{self.sfx}({', '.join(args)})")


def _seg_at(entry, k, c):
    """Row of the segment cache ``%SC`` holding quantity ``k`` of corner ``c`` in cache entry ``entry``."""
    return 4 * (len(SEG) * entry + SEG.index(k)) + c


def _damper(w: _W, c, v):
    """Damper force ``A + S v`` of corner ``c`` at velocities ``v``, through the segment cache ``%SC``: two
    entries per lane (the last segment first; a sub-step redone in pieces goes back and forth across a
    kink), the knots scanned only when a lane is in neither."""
    e1 = {k: w.at("%SC", _seg_at(0, k, c)) for k in ("lo", "hi", "A", "S")}
    in1 = w.tmp(f"and {VB} {w.cmp('oge', v, e1['lo'])}, {w.cmp('olt', v, e1['hi'])}")
    hit = w.tmp(f"icmp eq i{LANES} {w.tmp(f'bitcast {VB} {in1} to i{LANES}')}, -1")
    pre = w.block
    second, swap, miss, loop, found, join = (w.label(n) for n in ("seg_second", "seg_swap", "seg_miss",
                                                                    "seg_loop", "seg_found", "seg_join"))
    w(f"  br i1 {hit}, label %{join}, label %{second}, !prof !0")
    # a lane outside its last segment: the entry before it, lane by lane
    w.start(second)
    old = [{k: w.at("%SC", _seg_at(j, k, c)) for k in SEG} for j in range(2)]
    in2 = w.tmp(f"and {VB} {w.cmp('oge', v, old[1]['lo'])}, {w.cmp('olt', v, old[1]['hi'])}")
    either = w.tmp(f"or {VB} {in1}, {in2}")
    hit2 = w.tmp(f"icmp eq i{LANES} {w.tmp(f'bitcast {VB} {either} to i{LANES}')}, -1")
    w(f"  br i1 {hit2}, label %{swap}, label %{miss}")
    w.start(swap)
    for k in SEG:  # the entry a lane is in goes first
        w.put(w.sel(in1, old[0][k], old[1][k]), "%SC", _seg_at(0, k, c))
        w.put(w.sel(in1, old[1][k], old[0][k]), "%SC", _seg_at(1, k, c))
    sw_A, sw_S = w.sel(in1, old[0]["A"], old[1]["A"]), w.sel(in1, old[0]["S"], old[1]["S"])
    w(f"  br label %{join}")
    # else every lane's segment from the knots: one compare and select per knot
    w.start(miss)
    row0 = w.tmp(f"mul i64 %ns, {c * LANES}")
    init = {"lo": w.c(-float("inf")), "hi": w.bcast("%xk", 0), "A": w.vload("%tb", row0),
            "S": w.vload("%tbs", row0), "kap": w.c(0.0)}
    w(f"  br i1 {w.tmp('icmp sgt i64 %nk, 0')}, label %{loop}, label %{found}")
    w.start(loop)
    i = w.tmp(f"phi i64 [ 0, %{miss} ], [ %{loop}_i1, %{loop} ]")
    cur = {k: w.tmp(f"phi {V} [ {init[k]}, %{miss} ], [ %{loop}_{k}, %{loop} ]") for k in SEG}
    i1 = f"%{loop}_i1"
    w(f"  {i1} = add i64 {i}, 1")
    xi = w.bcast("%xk", i)
    m = w.cmp("oge", v, xi)
    row = w.tmp(f"add i64 {row0}, {w.tmp(f'mul i64 {i1}, {LANES}')}")
    kf = w.bcast("%kf", w.tmp(f"add i64 {w.tmp(f'mul i64 %nk, {c // 2}')}, {i}"))
    new = {"lo": xi, "hi": w.bcast("%xk", i1), "A": w.vload("%tb", row), "S": w.vload("%tbs", row),
           "kap": w.fadd(cur["kap"], kf)}
    for k in SEG:
        w(f"  %{loop}_{k} = select {VB} {m}, {V} {new[k]}, {V} {cur[k]}")
    w(f"  br i1 {w.tmp(f'icmp slt i64 {i1}, %nk')}, label %{loop}, label %{found}")
    w.start(found)
    res = {k: w.tmp(f"phi {V} [ {init[k]}, %{miss} ], [ %{loop}_{k}, %{loop} ]") for k in SEG}
    for k in SEG:  # the lanes that had moved keep their last segment second
        w.put(res[k], "%SC", _seg_at(0, k, c))
        w.put(w.sel(in1, old[1][k], old[0][k]), "%SC", _seg_at(1, k, c))
    w(f"  br label %{join}")
    w.start(join)
    A = w.tmp(f"phi {V} [ {e1['A']}, %{pre} ], [ {sw_A}, %{swap} ], [ {res['A']}, %{found} ]")
    S = w.tmp(f"phi {V} [ {e1['S']}, %{pre} ], [ {sw_S}, %{swap} ], [ {res['S']}, %{found} ]")
    return w.madd(S, v, A)


def _gen_rhs(w: _W, row: bool, ends: bool):
    """The internal function :data:`RHS` ``[row, ends]``: the right-hand side at states ``X`` with inputs
    ``u`` and rates ``r`` (four doubles of a table row to broadcast, or four vectors): the derivative into
    ``D``, and with ``ends`` the accelerations into ``Q`` and the switching quantities into ``SW`` (as
    :func:`rideid.model.nonlinear.accelerations` and ``switching``). Axle by axle, every result stored
    as soon as it is known, the loads of inputs and coefficients marked invariant: few values live at once
    (16 vector registers), so few spills."""
    dp = w.dp
    nb = 8 * LANES
    size = {"cf": nb * len(ENTRIES_PT if w.pt else ENTRIES), "X": nb * w.nx, "u": 32 if row else nb * 4,
            "r": 32 if row else nb * 4}
    params = []
    for p in _RHS_PARAMS + ("X", "u", "r", "D") + (("Q", "SW") if ends else ()):
        if p in ("nk", "ns"):
            params.append(f"i64 %{p}")
        else:
            params.append(f"{dp} noalias {f'dereferenceable({size[p]}) ' if p in size else ''}%{p}")
    w(f"define {_LINKAGE} fastcc void @{RHS[row, ends]}{w.sfx}({', '.join(params)}) noinline nounwind {{")
    w.start("entry")
    w.invariant = True
    X = lambda i: w.at("%X", i)  # noqa: E731
    if row:
        u, r = (lambda c: w.bcast("%u", c)), (lambda c: w.bcast("%r", c))
    else:
        u, r = (lambda c: w.at("%u", c)), (lambda c: w.at("%r", c))
    zero = "zeroinitializer"
    sf = sx = sy = None
    for ax in range(2):
        d, v, wv = {}, {}, {}
        for c in (2 * ax, 2 * ax + 1):
            xc, yc = w.e(f"x{c}"), w.e(f"y{c}")
            wv[c] = w.madd(w.e(f"ctm{c}"), u(c), X(10 + c))
            w.put(wv[c], "%D", 3 + c)
            zb = w.madd(yc, X(2), w.fsub(X(0), w.fmul(xc, X(1))))
            d[c] = w.fsub(X(3 + c), zb)
            vb = w.madd(w.e(f"y{c}"), X(9), w.fsub(X(7), w.fmul(w.e(f"x{c}"), X(8))))
            v[c] = w.fsub(wv[c], vb)
        bar = w.fmul(w.e(f"kar_{'fr'[ax]}"), w.fsub(d[2 * ax], d[2 * ax + 1]))
        for c in (2 * ax, 2 * ax + 1):
            w.invariant = False
            damp = _damper(w, c, v[c])
            w.invariant = True
            f = w.fmul(w.e(f"ks{c}"), d[c])
            f = w.fadd(f, bar) if c % 2 == 0 else w.fsub(f, bar)
            f = w.fadd(f, damp)
            e = w.fsub(d[c], w.e(f"bs_clear{c}"))
            f = w.sel(w.cmp("ogt", e, zero), w.madd(w.e(f"bs_rate{c}"), e, f), f)
            L, ct = w.e(f"L{c}"), w.e(f"ct{c}")
            t0 = w.fsub(w.madd(w.e(f"kt{c}"), w.fsub(u(c), X(3 + c)), L), w.fmul(ct, wv[c]))
            crd = w.fmul(w.e(f"ct{c}"), r(c))
            gc = w.fadd(t0, crd)
            a_on = w.fsub(w.fsub(t0, w.e(f"L{c}")), f)
            a_off = w.fsub(w.fsub(w.e(f"neg_L{c}"), f), crd)
            dpc = w.fmul(w.sel(w.cmp("oge", gc, zero), a_on, a_off), w.e(f"inv_mu{c}"))
            w.put(dpc, "%D", 10 + c)
            if ends:
                for n, val in (("d", d[c]), ("v", v[c]), ("g", gc)):
                    w.put(val, "%SW", 4 * SWQ.index(n) + c)
                w.put(w.madd(w.e(f"ctm{c}"), r(c), dpc), "%Q", 3 + c)
            # the moments' products rounded one by one (not fused): a symmetric car's left and right
            # cancel exactly, and it does not roll
            sf = f if sf is None else w.fadd(sf, f)
            px, py = w.xop("fmul", w.e(f"x{c}"), f), w.xop("fmul", w.e(f"y{c}"), f)
            sx = px if sx is None else w.xop("fadd", sx, px)
            sy = py if sy is None else w.xop("fadd", sy, py)
    if w.pt:
        # the powertrain (SPEC §11): the generalised forces on (z, theta, u, psi), the mounts' on their own
        # coordinates, through the inverse mass matrix (as rideid.model.nonlinear.accelerations)
        g = (sf, w.madd(w.e("topple"), X(1), w.tmp(f"fneg {V} {sx}")),
             w.tmp(f"fneg {V} {w.madd(w.e('pt_ku'), X(14), w.fmul(w.e('pt_cu'), X(16)))}"),
             w.tmp(f"fneg {V} {w.madd(w.e('pt_kpsi'), X(15), w.fmul(w.e('pt_cpsi'), X(17)))}"))
        acc = []
        for i in range(4):
            a = None
            for j in range(4):
                m = w.e(f"pt_m{min(i, j)}{max(i, j)}")
                a = w.fmul(m, g[j]) if a is None else w.madd(m, g[j], a)
            acc.append(a)
        q0, q1 = acc[0], acc[1]
        w.put(X(16), "%D", 14)
        w.put(X(17), "%D", 15)
        w.put(acc[2], "%D", 16)
        w.put(acc[3], "%D", 17)
    else:
        q0 = w.fmul(sf, w.e("inv_ms"))
        q1 = w.fmul(w.madd(w.e("topple"), X(1), w.tmp(f"fneg {V} {sx}")), w.e("inv_Iyy"))
    q2 = w.fmul(w.madd(w.e("topple"), X(2), sy), w.e("inv_Ixx"))
    for i, val in enumerate((X(7), X(8), X(9))):
        w.put(val, "%D", i)
    for i, val in enumerate((q0, q1, q2)):
        w.put(val, "%D", 7 + i)
    if ends:
        for i, val in enumerate((q0, q1, q2)):
            w.put(val, "%Q", i)
        w.invariant = False
        for c in range(4):
            body = w.madd(w.e(f"y{c}"), q2, w.fsub(q0, w.fmul(w.e(f"x{c}"), q1)))
            w.put(w.fsub(w.at("%Q", 3 + c), body), "%SW", 4 * SWQ.index("vd") + c)
            w.put(w.at("%SC", _seg_at(0, "kap", c)), "%SW", 4 * SWQ.index("kap") + c)
    w.invariant = False
    w("  ret void")
    w("}")


def _prologue(w: _W, name):
    args = ARGS[name]
    sig = ", ".join(f"i64 %i{a}" if kind == "ptr" else f"{kind} %{a}" for a, kind in args)
    w(f"define {RETURNS[name]} @{name}{w.sfx}({sig}) nounwind {{")
    w.start("entry")
    for a, kind in args:
        if kind == "ptr":
            w(f"  %{a} = inttoptr i64 %i{a} to {w.dp}")
    # the slopes follow the intercepts: 4 corners x ns segments x LANES each
    w(f"  %tbs = getelementptr inbounds double, {w.dp} %tb, i64 {w.tmp(f'mul i64 %ns, {4 * LANES}')}")


def _rk4(w: _W, Xp, k1, h, mid, end, T, K, Xout=None):
    """One RK4 step of length ``h`` (a vector) from the states at ``Xp`` (read again after each call of the
    right-hand side rather than kept live across it: no spills) with first stage ``k1`` (``w.nx`` vectors),
    inputs ``mid`` and ``end`` (``(row, u, r)``: pointers, table rows or vectors), through the stack arrays
    ``T`` (stage states) and ``K`` (stage derivatives): the new states (as the scalar kernel: the stages
    summed into ``acc``, then ``X + (h / 6) (acc + k4)``), stored into ``Xout`` too if given."""
    hh = w.fmul(w.c(0.5), h)
    two = w.c(2.0)
    acc = list(k1)
    nx = w.nx
    for stage, (hs, inp) in enumerate(((hh, mid), (hh, mid), (h, end))):
        k = k1 if stage == 0 else [w.at(K, i) for i in range(nx)]
        if stage:
            acc = [w.madd(two, k[i], acc[i]) for i in range(nx)]
        for i in range(nx):
            w.put(w.madd(hs, k[i], w.at(Xp, i)), T, i)
        w.call_rhs(inp[0], False, T, inp[1], inp[2], K)
    k4 = [w.at(K, i) for i in range(nx)]
    h6 = w.tmp(f"fdiv {FL} {V} {h}, {w.c(6.0)}")
    Xn = [w.madd(h6, w.fadd(acc[i], k4[i]), w.at(Xp, i)) for i in range(nx)]
    if Xout is not None:
        for i in range(nx):
            w.put(Xn[i], Xout, i)
    return Xn


def _gen_err(w: _W):
    """:data:`ERR`: the ten channels of the states ``X`` and accelerations ``Q`` (as
    :func:`rideid.model.nonlinear.channels`), their squared errors against the sample's measurements ``Y``
    (10 doubles) weighted by ``W`` (10) added to the lanes' sums ``E``."""
    args = ARGS[ERR]
    w(f"define void @{ERR}({', '.join(f'i64 %i{a}' for a, _ in args)}) nounwind {{")
    w.start("entry")
    for a, _ in args:
        w(f"  %{a} = inttoptr i64 %i{a} to {w.dp}")
    q = [w.at("%Q", i) for i in range(7)]
    ys = []
    for c in range(4):
        t = w.xop("fsub", q[0], w.xop("fmul", w.e(f"x{c}"), q[1]))
        ys.append(w.xop("fadd", t, w.xop("fmul", w.e(f"y{c}"), q[2])))
    ys += q[3:] + [w.at("%X", 8), w.at("%X", 9)]
    e = w.at("%E", 0)
    for i, y in enumerate(ys):
        dq = w.xop("fsub", y, w.bcast("%Y", i))
        e = w.xop("fadd", e, w.xop("fmul", w.xop("fmul", w.bcast("%W", i), dq), dq))
    w.put(e, "%E", 0)
    w("  ret void")
    w("}")


def _gen_end(w: _W):
    _prologue(w, END)
    w.call_rhs(True, True, "%X", "%u", "%r", "%D", "%Q", "%SW")
    w("  ret void")
    w("}")


def _crossed(w: _W):
    """Lanes (i64 bit mask) where a corner's kink count, bump-stop side or tire-load sign differs between
    ``SWa`` and ``SWb``."""
    anyc = None
    zero = "zeroinitializer"
    for c in range(4):
        q = {n: [w.at(s, 4 * SWQ.index(n) + c) for s in ("%SWa", "%SWb")] for n in ("d", "g", "kap")}
        k = w.cmp("une", *q["kap"])
        clr = w.e(f"bs_clear{c}")
        b0, b1 = (w.cmp("ogt", w.fsub(x, clr), zero) for x in q["d"])
        t0, t1 = (w.cmp("oge", x, zero) for x in q["g"])
        x = w.tmp(f"or {VB} {k}, {w.tmp(f'xor {VB} {b0}, {b1}')}")
        x = w.tmp(f"or {VB} {x}, {w.tmp(f'xor {VB} {t0}, {t1}')}")
        anyc = x if anyc is None else w.tmp(f"or {VB} {anyc}, {x}")
    bits = w.tmp(f"bitcast {VB} {anyc} to i{LANES}")
    return w.tmp(f"zext i{LANES} {bits} to i64")


def _gen_step(w: _W):
    _prologue(w, STEP)
    T, K = w.stack(w.nx), w.stack(w.nx)
    k1 = [w.at("%Da", i) for i in range(w.nx)]
    _rk4(w, "%Xa", k1, w.splat("%h"), (True, "%u1", "%r1"), (True, "%u2", "%r2"), T, K, "%Xb")
    w.call_rhs(True, True, "%Xb", "%u2", "%r2", "%Db", "%Qb", "%SWb")
    w(f"  ret i64 {_crossed(w)}")
    w("}")


def _inputs_at(w: _W, tau, rows, hh, U, R):
    """Road inputs and rates at fractions ``tau`` (a vector) of the sub-step whose table rows ``js .. js + 2``
    are ``rows`` ((u, r) pointers) into the stack arrays ``U``, ``R`` (4 vectors each): cubic Hermite of the
    inputs over the half sub-step ``hh`` (a vector), rates linear (as
    :func:`rideid.model.nonlinear.inputs_within`)."""
    one = w.c(1.0)
    x = w.fmul(w.c(2.0), tau)
    first = w.cmp("olt", x, one)
    s = w.sel(first, x, w.fsub(x, one))
    s2 = w.fmul(s, s)
    om = w.fsub(one, s)
    omom = w.fmul(om, om)
    h00 = w.fmul(w.madd(w.c(2.0), s, one), omom)
    h10 = w.fmul(w.fmul(s, omom), hh)
    h01 = w.fmul(s2, w.fsub(w.c(3.0), w.fmul(w.c(2.0), s)))
    h11 = w.fmul(w.fmul(s2, w.fsub(s, one)), hh)
    ub = [[w.bcast(p[0], c) for c in range(4)] for p in rows]
    rb = [[w.bcast(p[1], c) for c in range(4)] for p in rows]
    for c in range(4):
        ua, ue = w.sel(first, ub[0][c], ub[1][c]), w.sel(first, ub[1][c], ub[2][c])
        ra, re_ = w.sel(first, rb[0][c], rb[1][c]), w.sel(first, rb[1][c], rb[2][c])
        val = w.fmul(h00, ua)
        val = w.madd(h10, ra, val)
        val = w.madd(h01, ue, val)
        w.put(w.madd(h11, re_, val), U, c)
        w.put(w.madd(s, re_, w.fmul(om, ra)), R, c)


def _gen_pieces(w: _W):
    """RK4 over the sub-step in pieces ``[theta_{q-1}, theta_q]`` (``theta_{-1} = 0``, ``theta_np = 1``),
    from the start ``Xa``/``Da``, lane by lane: a piece of zero length is skipped, the first piece of
    positive length starts from ``Da``, later ones re-evaluate at their start (as the scalar kernel did)."""
    _prologue(w, PIECES)
    nx = w.nx
    T, K, P = w.stack(nx), w.stack(nx), w.stack(nx)
    UM, RM, UE, RE = (w.stack(4) for _ in range(4))
    rows = (("%u0", "%r0"), ("%u1", "%r1"), ("%u2", "%r2"))
    h = w.splat("%h")
    hh = w.fmul(w.c(0.5), h)
    for i in range(nx):
        w.put(w.at("%Xa", i), P, i)
    pre = w.block
    loop, body, done = w.label("piece"), w.label("piece_body"), w.label("pieces_done")
    w(f"  br label %{loop}")
    w.start(loop)
    q = w.tmp(f"phi i64 [ 0, %{pre} ], [ %{body}_q1, %{body}_k0 ]")
    a = w.tmp(f"phi {V} [ zeroinitializer, %{pre} ], [ %{body}_b, %{body}_k0 ]")
    fresh = w.tmp(f"phi {VB} [ {TRUE}, %{pre} ], [ %{body}_fresh, %{body}_k0 ]")
    w(f"  br i1 {w.tmp(f'icmp sle i64 {q}, %np')}, label %{body}, label %{done}")
    w.start(body)
    last = w.tmp(f"icmp eq i64 {q}, %np")
    thq = w.tmp(f"select i1 {last}, i64 0, i64 {q}")  # a valid row to load when q == np
    bq = w.vload("%TH", w.tmp(f"mul i64 {thq}, {LANES}"))
    w(f"  %{body}_b = select i1 {last}, {V} {w.c(1.0)}, {V} {bq}")
    b = f"%{body}_b"
    hp = w.fmul(w.fsub(b, a), h)
    active = w.cmp("ogt", hp, "zeroinitializer")
    # the first stage: the start's derivative while the lane is fresh, else re-evaluated at the piece's start
    w(f"  br i1 {w.tmp(f'icmp eq i64 {q}, 0')}, label %{body}_k0, label %{body}_kn")
    w.start(f"{body}_kn")
    w.call_rhs(False, False, P, UE, RE, K)  # the previous piece's end inputs: this one's start
    w(f"  br label %{body}_k0")
    w.start(f"{body}_k0")
    first = w.tmp(f"phi {VB} [ {TRUE}, %{body} ], [ {fresh}, %{body}_kn ]")
    k1 = [w.sel(first, w.at("%Da", i), w.at(K, i)) for i in range(nx)]
    _inputs_at(w, w.fmul(w.c(0.5), w.fadd(a, b)), rows, hh, UM, RM)
    _inputs_at(w, b, rows, hh, UE, RE)
    Xn = _rk4(w, P, k1, hp, (False, UM, RM), (False, UE, RE), T, K)
    for i in range(nx):
        w.put(w.sel(active, Xn[i], w.at(P, i)), P, i)
    w(f"  %{body}_fresh = and {VB} {fresh}, {w.tmp(f'xor {VB} {active}, {TRUE}')}")
    w(f"  %{body}_q1 = add i64 {q}, 1")
    w(f"  br label %{loop}")
    w.start(done)
    # the lanes asked for take the pieces' end state, the others keep theirs; then the end's evaluation
    mv = w.tmp(f"bitcast i{LANES} {w.tmp(f'trunc i64 %mask to i{LANES}')} to {VB}")
    for i in range(nx):
        w.put(w.sel(mv, w.at(P, i), w.at("%Xb", i)), "%Xb", i)
    w.call_rhs(True, True, "%Xb", "%u2", "%r2", "%Db", "%Qb", "%SWb")
    w("  ret void")
    w("}")


def generate_ir(opaque: bool | None = None) -> str:
    """LLVM IR (textual) of :data:`END`, :data:`STEP` and :data:`PIECES`; pointers opaque (LLVM >= 17) or
    typed, as the installed llvmlite's LLVM reads them (``opaque=None``)."""
    if opaque is None:
        import llvmlite.binding as llvm
        opaque = llvm.llvm_version_info[0] >= 17
    lines = []
    for pt in (False, True):  # the car, then the car with a powertrain on mounts (names suffixed PT)
        w = _W(opaque, pt)
        for row, ends in RHS:
            _gen_rhs(w, row, ends)
        for gen in (_gen_end, _gen_step, _gen_pieces) + (() if pt else (_gen_err,)):
            gen(w)
        lines += w.lines
    lines += ['!0 = !{!"branch_weights", i32 1000, i32 1}', "!1 = !{}"]
    return "\n".join(lines) + "\n"


_LIBRARY = {}


def _library(context):
    """This kernel's IR module, to link into the driver's library
    (:func:`rideid.model.kernel_ir.ir_library`)."""
    return ir_library(context, "rideid_kernel_nl_ir", generate_ir, _LIBRARY)


def _codegen(name, sfx=""):
    """Code generation of a call of the IR function ``name`` (its variant ``name + sfx``; linked into the
    caller's library)."""
    args = ARGS[name]
    i64 = RETURNS[name] == "i64"

    def codegen(context, builder, signature, cargs):
        context.add_linking_libs([_library(context)])
        fnty = ir.FunctionType(ir.IntType(64) if i64 else ir.VoidType(),
                               [ir.DoubleType() if kind == "double" else ir.IntType(64) for _, kind in args])
        fn = cgutils.get_or_insert_function(builder.module, fnty, name + sfx)
        res = builder.call(fn, cargs)
        return res if i64 else context.get_dummy_value()

    return codegen


def _sig(name):
    args = [types.float64 if kind == "double" else types.int64 for _, kind in ARGS[name]]
    return (types.int64 if RETURNS[name] == "i64" else types.void)(*args)


@intrinsic
def call_end(typingctx, cf, tb, xk, kf, nk, ns, SC, X, u, r, D, Q, SW):
    """:data:`END` (arguments: :data:`ARGS`)."""
    return _sig(END), _codegen(END)


@intrinsic
def call_err(typingctx, cf, X, Q, Y, W, E):
    """:data:`ERR` (arguments: :data:`ARGS`)."""
    return _sig(ERR), _codegen(ERR)


@intrinsic
def call_step(typingctx, cf, tb, xk, kf, nk, ns, SC, Xa, Da, SWa, Xb, Db, Qb, SWb, u1, r1, u2, r2, h):
    """:data:`STEP` (arguments: :data:`ARGS`); the lanes that crossed a kink, as bits."""
    return _sig(STEP), _codegen(STEP)


@intrinsic
def call_pieces(typingctx, cf, tb, xk, kf, nk, ns, SC, Xa, Da, Xb, Db, Qb, SWb, TH, np_, u0, r0, u1, r1, u2, r2, h,
                mask):
    """:data:`PIECES` (arguments: :data:`ARGS`)."""
    return _sig(PIECES), _codegen(PIECES)


@intrinsic
def call_end_pt(typingctx, cf, tb, xk, kf, nk, ns, SC, X, u, r, D, Q, SW):
    """:data:`END` of the car with a powertrain (:data:`PT`)."""
    return _sig(END), _codegen(END, PT)


@intrinsic
def call_step_pt(typingctx, cf, tb, xk, kf, nk, ns, SC, Xa, Da, SWa, Xb, Db, Qb, SWb, u1, r1, u2, r2, h):
    """:data:`STEP` of the car with a powertrain (:data:`PT`)."""
    return _sig(STEP), _codegen(STEP, PT)


@intrinsic
def call_pieces_pt(typingctx, cf, tb, xk, kf, nk, ns, SC, Xa, Da, Xb, Db, Qb, SWb, TH, np_, u0, r0, u1, r1, u2, r2,
                   h, mask):
    """:data:`PIECES` of the car with a powertrain (:data:`PT`)."""
    return _sig(PIECES), _codegen(PIECES, PT)


# ---------------------------------------------------------------------------
# the driver (Numba), here with the IR it calls so that Numba's disk cache, which follows this file, is
# renewed with it

#: the coefficient block's entries in the driver's terms
_EX, _EY, _ECT, _EMU, _EBC = (E[f"{n}0"] for n in ("x", "y", "ct", "inv_mu", "bs_clear"))
_CSTRIDE = len(CORNER)
#: rows of the switching quantities in the SW arrays
_SD, _SV, _SG, _SVD, _SK = (4 * SWQ.index(n) for n in SWQ)


_hermite_value_slope = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(hermite_value_slope)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _root(s0, s1, m0, m1):
    """Crossing ``0 < theta <= 1`` of the cubic Hermite ``s`` with values ``s0, s1`` and slopes ``m0, m1`` (per
    unit ``theta``) at 0 and 1, ``s0 != s1`` of opposite signs: the chord's root, then two Newton steps kept
    in ``[0, 1]`` (as :func:`rideid.model.nonlinear.hermite_root`)."""
    t = s0 / (s0 - s1)
    for _ in range(2):
        val, der = _hermite_value_slope(t, s0, s1, m0, m1)
        if der != 0.0:
            t = t - val / der
        if t < 0.0:
            t = 0.0
        if t > 1.0:
            t = 1.0
    return t




@numba.njit(cache=True, nogil=True, error_model="numpy")
def _lane_crossings(XK, KF, nk, CF, ch, lane, h, S0, S1, th):
    """Sorted fractions ``theta`` (into ``th``) of the sub-step where lane ``lane``'s damper velocity crosses
    a kink (interior knot ``XK[i]`` with ``KF[axle, i]``), its deflection the bump-stop clearance or its tire
    load zero, from the switching quantities ``S0``, ``S1`` at the sub-step's ends; returns their number (as
    :func:`rideid.model.nonlinear.crossings`)."""
    nc = 0
    for c in range(4):
        va = S0[_SV + c, lane]
        vb = S1[_SV + c, lane]
        ma = h * S0[_SVD + c, lane]
        mb = h * S1[_SVD + c, lane]
        ax = c // 2
        for i in range(nk if S0[_SK + c, lane] != S1[_SK + c, lane] else 0):
            kn = XK[i]
            if KF[ax * nk + i] != 0 and (va < kn) != (vb < kn):
                th[nc] = _root(va - kn, vb - kn, ma, mb)
                nc += 1
        clear = CF[ch, (_EBC + _CSTRIDE * c) * LANES + lane]
        ea = S0[_SD + c, lane] - clear
        eb = S1[_SD + c, lane] - clear
        if (ea > 0.0) != (eb > 0.0):
            th[nc] = _root(ea, eb, h * va, h * vb)
            nc += 1
        ga = S0[_SG + c, lane]
        gb = S1[_SG + c, lane]
        if (ga >= 0.0) != (gb >= 0.0):
            th[nc] = ga / (ga - gb)
            nc += 1
    for i in range(1, nc):  # insertion sort
        t = th[i]
        k = i - 1
        while k >= 0 and th[k] > t:
            th[k + 1] = th[k]
            k -= 1
        th[k + 1] = t
    return nc


@numba.njit(cache=True, nogil=True, error_model="numpy")
def run_chunks(ch0, ch1, n, CF, TB, XK, KF, nk, ns, split, X0, run_start, hs, ms, fine_start, UF, RF, Y, W, mode,
               err, out, states, pt):
    """Chunks ``ch0 <= ch < ch1`` of :data:`LANES` candidates over every run (see :func:`run`; ``n`` real
    candidates, the lanes past them copy the last; ``pt``: the car with a powertrain, 18 states)."""
    # two buffers of states, derivatives and switching quantities: a sub-step goes from one to the other
    nx = 18 if pt else 14
    XB = np.empty((2, nx, LANES))
    DB = np.empty((2, nx, LANES))
    SB = np.empty((2, N_SW, LANES))
    Q = np.empty((7, LANES))
    SC = np.empty((N_SC, LANES))
    mx = 4 * (nk + 2) + 1
    TH = np.ones((mx, LANES))
    th = np.empty(mx)
    y = np.empty(10)
    e_sum = np.zeros(LANES)
    n_runs = run_start.shape[0] - 1
    pxk, pkf, puf, prf = XK.ctypes.data, KF.ctypes.data, UF.ctypes.data, RF.ctypes.data
    px, pd, psw = XB.ctypes.data, DB.ctypes.data, SB.ctypes.data
    pq, pth, psc = Q.ctypes.data, TH.ctypes.data, SC.ctypes.data
    py, pw, pe = Y.ctypes.data, W.ctypes.data, e_sum.ctypes.data
    bx = 8 * nx * LANES  # bytes per buffer of X and D
    bs = 8 * N_SW * LANES
    row4 = 8 * 4  # bytes per row of UF, RF
    for ch in range(ch0, ch1):
        pcf = CF.ctypes.data + 8 * ch * CF.shape[1]
        ptb = TB.ctypes.data + 8 * ch * TB.shape[1]
        for j in range(2):  # no damper segment known yet: bounds [inf, -inf)
            SC[j * N_SC // 2:j * N_SC // 2 + 4] = np.inf
            SC[j * N_SC // 2 + 4:j * N_SC // 2 + 8] = -np.inf
        for r in range(n_runs):
            cur = 0
            for lane in range(LANES):
                p = min(ch * LANES + lane, n - 1)
                for i in range(nx):
                    XB[0, i, lane] = X0[r, p, i]
                e_sum[lane] = 0.0
            m = ms[r]
            h = hs[r]
            f0 = fine_start[r]
            nrow = run_start[r + 1] - run_start[r]
            if pt:
                call_end_pt(pcf, ptb, pxk, pkf, nk, ns, psc, px, puf + row4 * f0, prf + row4 * f0, pd, pq, psw)
            else:
                call_end(pcf, ptb, pxk, pkf, nk, ns, psc, px, puf + row4 * f0, prf + row4 * f0, pd, pq, psw)
            for k in range(nrow):
                jf = f0 + 2 * m * k
                row = run_start[r] + k
                if mode == 0:
                    call_err(pcf, px + bx * cur, pq, py + 8 * 10 * row, pw + 8 * 10 * r, pe)
                for lane in range(LANES):
                    if mode == 0:
                        break
                    p = ch * LANES + lane
                    if p >= n:
                        break
                    for c in range(4):
                        xc = CF[ch, (_EX + _CSTRIDE * c) * LANES + lane]
                        yc = CF[ch, (_EY + _CSTRIDE * c) * LANES + lane]
                        y[c] = Q[0, lane] - xc * Q[1, lane] + yc * Q[2, lane]
                        y[4 + c] = Q[3 + c, lane]
                    y[8] = XB[cur, 8, lane]
                    y[9] = XB[cur, 9, lane]
                    if mode & 2:  # the states, wheel velocities shifted back (nonlinear.shifted)
                        for i in range(10):
                            states[p, row, i] = XB[cur, i, lane]
                        for c in range(4):
                            ctm = (CF[ch, (_ECT + _CSTRIDE * c) * LANES + lane]
                                   * CF[ch, (_EMU + _CSTRIDE * c) * LANES + lane])
                            states[p, row, 10 + c] = XB[cur, 10 + c, lane] + ctm * UF[jf, c]
                        for i in range(14, nx):
                            states[p, row, i] = XB[cur, i, lane]
                    if mode & 1:
                        for q in range(10):
                            out[p, row, q] = y[q]
                if k + 1 == nrow:
                    break
                for s in range(m):
                    js = jf + 2 * s
                    u0 = puf + row4 * js
                    r0 = prf + row4 * js
                    a, b = cur, 1 - cur
                    if pt:
                        mask = call_step_pt(pcf, ptb, pxk, pkf, nk, ns, psc, px + bx * a, pd + bx * a, psw + bs * a,
                                            px + bx * b, pd + bx * b, pq, psw + bs * b, u0 + row4, r0 + row4,
                                            u0 + 2 * row4, r0 + 2 * row4, h)
                    else:
                        mask = call_step(pcf, ptb, pxk, pkf, nk, ns, psc, px + bx * a, pd + bx * a, psw + bs * a,
                                         px + bx * b, pd + bx * b, pq, psw + bs * b, u0 + row4, r0 + row4,
                                         u0 + 2 * row4, r0 + 2 * row4, h)
                    cur = b
                    if mask == 0 or not split:
                        continue
                    # a kink inside the step in some lanes: their crossings, then the step redone in pieces
                    npc = 0
                    for lane in range(LANES):
                        if (mask >> lane) & 1:
                            nc = _lane_crossings(XK, KF, nk, CF, ch, lane, h, SB[a], SB[b], th)
                            for i in range(nc):
                                TH[i, lane] = th[i]
                            npc = max(npc, nc)
                    if npc == 0:
                        continue
                    if pt:
                        call_pieces_pt(pcf, ptb, pxk, pkf, nk, ns, psc, px + bx * a, pd + bx * a, px + bx * b,
                                       pd + bx * b, pq, psw + bs * b, pth, npc, u0, r0, u0 + row4, r0 + row4,
                                       u0 + 2 * row4, r0 + 2 * row4, h, mask)
                    else:
                        call_pieces(pcf, ptb, pxk, pkf, nk, ns, psc, px + bx * a, pd + bx * a, px + bx * b,
                                    pd + bx * b, pq, psw + bs * b, pth, npc, u0, r0, u0 + row4, r0 + row4,
                                    u0 + 2 * row4, r0 + 2 * row4, h, mask)
                    for lane in range(LANES):
                        for i in range(npc):
                            TH[i, lane] = 1.0
            for lane in range(LANES):
                p = ch * LANES + lane
                if p < n:
                    err[r, p] = e_sum[lane]


