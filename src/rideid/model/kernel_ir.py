"""The kernel's inner loop as LLVM IR over ``<4 x double>`` vectors (used by :mod:`rideid.model.kernel`).

One call integrates one chunk of :data:`LANES` candidates over one run.
Every state, input moment accumulator and error sum is one vector of four
lanes (one candidate each); every coefficient is one unaligned vector load
from the chunk's lane-innermost block (:mod:`rideid.model.kernel_layout`
gives the layout); the road inputs are broadcast. ``fast`` multiply-adds
become AVX2 fused multiply-adds (``make bench`` counts them in the
assembly).

Why IR and not Python: the same code written as Python for Numba (one
scalar per state and lane, straight-line, packed into vectors by LLVM's SLP
pass) took Numba's front end ~8 s to type and lower on every fresh
install; written here as vectors it is a quarter of the instructions, LLVM
compiles it in well under a second, and Numba only compiles the small
driver :func:`run_chunks` that calls it (the IR module is linked into the
driver's library and cached on disk with it). Same operations in the same
order: the results are bit for bit those of the former Python kernel.

The function (all pointers as 64-bit integers, doubles otherwise)::

    void rideid_kernel_run(cf, ct, N, k0, k1, UD, RD, MU, M, Y, W, hf, hr, X0, n, mode, OUT, ERR)

``cf``/``ct`` the chunk's fixed and per-term coefficients, ``N`` moment
terms, samples ``k0 <= k < k1``, ``UD``/``RD`` (T, 4) inputs and rates,
``MU`` (T, 4, M) moments, ``Y`` (T, 10) measurements, ``W`` the run's 10
channel weights, ``X0`` the chunk's first initial state (state ``i`` at
``X0 + i n``), ``OUT`` the chunk's channel 0 at sample 0 (channel ``q`` of
sample ``k`` at ``OUT + (10 k + q) n``; written when ``mode == 1``),
``ERR`` the chunk's four error sums (written).
"""

from __future__ import annotations

import numba
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .kernel_layout import LANES, LAYOUTS, flat_index, n_coef

NAME = "rideid_kernel_run"
#: the function's arguments in order: pointers (passed as 64-bit integers), counts and the two half-tracks
ARGS = (("cf", "ptr"), ("ct", "ptr"), ("N", "i64"), ("k0", "i64"), ("k1", "i64"), ("UD", "ptr"), ("RD", "ptr"),
        ("MU", "ptr"), ("M", "i64"), ("Y", "ptr"), ("W", "ptr"), ("hf", "double"), ("hr", "double"),
        ("X0", "ptr"), ("n", "i64"), ("mode", "i64"), ("OUT", "ptr"), ("ERR", "ptr"))
V = f"<{LANES} x double>"


def kernel_name(ns: int = 8) -> str:
    """The IR function's name for a symmetric block of ``ns`` states (:data:`NAME` for the 8-state car)."""
    return NAME if ns == 8 else f"{NAME}_{ns}"


def blocks(ns: int = 8):
    """(block, states, accelerations, first state, first input) of the two blocks, for a symmetric block of
    ``ns`` states (8; 12 with a powertrain on mounts, SPEC §11)."""
    return (("s", ns, 4, 0, 0), ("a", 6, 3, ns, 2))



class IRWriter:
    """IR lines with numbered temporaries; ``opaque``: LLVM's opaque pointers (LLVM >= 17), else typed ones."""

    def __init__(self, opaque: bool = True):
        self.lines = []
        self.n = 0
        self.dp = "ptr" if opaque else "double*"  # a pointer to doubles
        self.vp = "ptr" if opaque else f"{V}*"  # a pointer to a vector
        self.opaque = opaque

    def __call__(self, line):
        self.lines.append(line)

    def tmp(self, expr):
        self.n += 1
        name = f"%t{self.n}"
        self.lines.append(f"  {name} = {expr}")
        return name

    def ptr(self, base, offset):
        """A pointer ``offset`` doubles after ``base`` (a constant or an i64 value)."""
        return self.tmp(f"getelementptr inbounds double, {self.dp} {base}, i64 {offset}")

    def vptr(self, p):
        """``p`` (a pointer to doubles) as a pointer to a vector."""
        return p if self.opaque else self.tmp(f"bitcast double* {p} to {V}*")

    def vstore(self, value, p):
        self(f"  store {V} {value}, {self.vp} {self.vptr(p)}, align 8")

    def vload(self, base, offset):
        return self.tmp(f"load {V}, {self.vp} {self.vptr(self.ptr(base, offset))}, align 8")

    def coef(self, base, index):
        """The four lanes of coefficient ``index`` of a lane-innermost block."""
        return self.vload(base, index * LANES)

    def bcast(self, base, offset):
        """The double ``offset`` after ``base`` in all four lanes."""
        return self.splat(self.tmp(f"load double, {self.dp} {self.ptr(base, offset)}, align 8"))

    def splat(self, s):
        """The double value ``s`` in all four lanes."""
        v = self.tmp(f"insertelement {V} poison, double {s}, i64 0")
        return self.tmp(f"shufflevector {V} {v}, {V} poison, <{LANES} x i32> zeroinitializer")

    def fma(self, acc, a, b):
        m = self.tmp(f"fmul fast {V} {a}, {b}")
        return m if acc is None else self.tmp(f"fadd fast {V} {acc}, {m}")

    def add(self, a, b):
        return self.tmp(f"fadd fast {V} {a}, {b}")

    def sub(self, a, b):
        return self.tmp(f"fsub fast {V} {a}, {b}")


def generate_ir(opaque: bool | None = None, ns: int = 8) -> str:
    """LLVM IR (textual) of :func:`kernel_name` ``(ns)`` for a symmetric block of ``ns`` states (8, or 12
    with a powertrain on mounts; the antisymmetric block has 6); pointers opaque (LLVM >= 17) or typed
    (older LLVM), as the installed llvmlite's LLVM reads them (``opaque=None``).

    The states are ``ns + 6`` vectors: the symmetric block's (positions, then rates from ``ns / 2``) then
    the antisymmetric block's; the gyros read the pitch rate (state ``ns / 2 + 1``) and the roll rate
    (state ``ns + 3``). A powertrain's two more coordinates enter the state update and the accelerations
    (its columns of ``Ca_s``) and nothing else."""
    if opaque is None:
        import llvmlite.binding as llvm
        opaque = llvm.llvm_version_info[0] >= 17
    w = IRWriter(opaque)
    nx = ns + 6

    def _flat(name, *ij):
        return flat_index(name, *ij, ns=ns)

    fixed, per_term = LAYOUTS[ns][1], LAYOUTS[ns][2]
    args = ", ".join(f"i64 %i{a}" if kind == "ptr" else f"{kind} %{a}" for a, kind in ARGS)
    w(f"define void @{kernel_name(ns)}({args}) nounwind {{")
    w("entry:")
    for a, kind in ARGS:
        if kind == "ptr":
            w(f"  %{a} = inttoptr i64 %i{a} to {w.dp}")
    la = w.coef("%cf", _flat("a"))
    lb = w.coef("%cf", _flat("b"))
    hf = w.splat("%hf")
    hr = w.splat("%hr")
    x0 = []
    for i in range(nx):
        off = w.tmp(f"mul i64 %n, {i}")
        x0.append(w.vload("%X0", off))
    w("  %any = icmp slt i64 %k0, %k1")
    w("  br i1 %any, label %sample, label %empty")

    # -- one sample: accelerations, channels, errors
    w("sample:")
    xs = [f"%x{i}" for i in range(nx)]
    w("  %k = phi i64 [ %k0, %entry ], [ %knext, %update ]")
    for i in range(nx):
        w(f"  %x{i} = phi {V} [ {x0[i]}, %entry ], [ %nx{i}, %update ]")
    w(f"  %e = phi {V} [ zeroinitializer, %entry ], [ %enew, %update ]")
    k4 = w.tmp("mul i64 %k, 4")
    g = {}
    for blk, S, R, xo, uo in blocks(ns):
        u = [w.bcast("%UD", w.tmp(f"add i64 {k4}, {uo + c}")) for c in range(2)]
        r = [w.bcast("%RD", w.tmp(f"add i64 {k4}, {uo + c}")) for c in range(2)]
        for i in range(R):
            acc = None
            for c in range(2):
                acc = w.fma(acc, w.coef("%cf", _flat("Da_" + blk, i, c)), u[c])
                acc = w.fma(acc, w.coef("%cf", _flat("Dr_" + blk, i, c)), r[c])
            for j in range(S):
                acc = w.fma(acc, w.coef("%cf", _flat("Ca_" + blk, i, j)), xs[xo + j])
            g[blk, i] = acc
    # the channels (the output map of rideid.model.equations.output_map, tested against it)
    fa = w.sub(g["s", 0], w.tmp(f"fmul fast {V} {la}, {g['s', 1]}"))
    ra = w.add(g["s", 0], w.tmp(f"fmul fast {V} {lb}, {g['s', 1]}"))
    hfa = w.tmp(f"fmul fast {V} {hf}, {g['a', 0]}")
    hra = w.tmp(f"fmul fast {V} {hr}, {g['a', 0]}")
    ys = [w.add(fa, hfa), w.sub(fa, hfa), w.add(ra, hra), w.sub(ra, hra),
          w.add(g["s", 2], g["a", 1]), w.sub(g["s", 2], g["a", 1]),
          w.add(g["s", 3], g["a", 2]), w.sub(g["s", 3], g["a", 2]), xs[ns // 2 + 1], xs[ns + 3]]
    k10 = w.tmp("mul i64 %k, 10")
    e = "%e"
    for q, y in enumerate(ys):
        d = w.sub(y, w.bcast("%Y", w.tmp(f"add i64 {k10}, {q}")))
        wq = w.bcast("%W", q)
        e = w.fma(e, w.tmp(f"fmul fast {V} {wq}, {d}"), d)
    w(f"  %enew = fadd fast {V} {e}, zeroinitializer")
    w("  %write = icmp eq i64 %mode, 1")
    w("  br i1 %write, label %store, label %next")
    w("store:")
    for q, y in enumerate(ys):
        row = w.tmp(f"add i64 {k10}, {q}")
        off = w.tmp(f"mul i64 %n, {row}")
        w.vstore(y, w.ptr("%OUT", off))
    w("  br label %next")
    w("next:")
    w("  %knext = add i64 %k, 1")
    w("  %last = icmp eq i64 %knext, %k1")
    w("  br i1 %last, label %done, label %terms_s")

    # -- the moment terms over [k, k + 1], one loop per block
    pred = "next"
    acc_end = {}
    for blk, S, _R, xo, uo in blocks(ns):
        lab = f"terms_{blk}"
        w(f"{lab}:")
        w(f"  %t_{blk} = phi i64 [ 0, %{pred} ], [ %t_{blk}1, %{lab} ]")
        for i in range(S):
            w(f"  %v{xo + i} = phi {V} [ zeroinitializer, %{pred} ], [ %vn{xo + i}, %{lab} ]")
        base = w.tmp(f"mul i64 %t_{blk}, {per_term * LANES}")
        tb = w.ptr("%ct", base)
        m = []
        for c in range(2):
            row = w.tmp(f"add i64 {k4}, {uo + c}")
            start = w.tmp(f"mul i64 {row}, %M")
            m.append(w.bcast("%MU", w.tmp(f"add i64 {start}, %t_{blk}")))
        for i in range(S):
            acc = f"%v{xo + i}"
            for c in range(2):
                acc = w.fma(acc, w.coef(tb, _flat("G_" + blk, i, c) - fixed), m[c])
            w(f"  %vn{xo + i} = fadd fast {V} {acc}, zeroinitializer")
        w(f"  %t_{blk}1 = add i64 %t_{blk}, 1")
        w(f"  %more_{blk} = icmp slt i64 %t_{blk}1, %N")
        nxt = "terms_a" if blk == "s" else "update"
        w(f"  br i1 %more_{blk}, label %{lab}, label %{nxt}")
        pred = lab
        acc_end.update({xo + i: f"%vn{xo + i}" for i in range(S)})
    # -- the transition over [k, k + 1]
    w("update:")
    for blk, S, _R, xo, _uo in blocks(ns):
        for i in range(S):
            acc = acc_end[xo + i]
            for j in range(S):
                acc = w.fma(acc, w.coef("%cf", _flat("Phi_" + blk, i, j)), xs[xo + j])
            w(f"  %nx{xo + i} = fadd fast {V} {acc}, zeroinitializer")
    w("  br label %sample")
    w("done:")
    w.vstore("%enew", "%ERR")
    w("  ret void")
    w("empty:")
    w.vstore("zeroinitializer", "%ERR")
    w("  ret void")
    w("}")
    return "\n".join(w.lines) + "\n"


_LIBRARY = {}


def ir_library(context, name: str, generate, cache: dict):
    """The IR module ``generate()`` returns as text, optimised and finalised once per process (and code
    generator, the key into ``cache``) as the library ``name``, to link into a driver's library."""
    codegen = context.codegen()
    if id(codegen) not in cache:
        import llvmlite.binding as llvm
        lib = codegen.create_library(name)
        mod = llvm.parse_assembly(generate())
        mod.verify()
        lib.add_llvm_module(mod)
        lib.finalize()
        cache[id(codegen)] = lib
    return cache[id(codegen)]


def _library(context, ns: int = 8):
    """This kernel's IR module for a symmetric block of ``ns`` states, to link into the driver's library
    (:func:`ir_library`)."""
    cache = _LIBRARY.setdefault(ns, {})
    return ir_library(context, f"rideid_kernel_ir_{ns}" if ns != 8 else "rideid_kernel_ir",
                      lambda: generate_ir(ns=ns), cache)


_ARG_TYPES = [types.float64 if kind == "double" else types.int64 for _, kind in ARGS]


def _run_block_intrinsic(ns: int):
    """The intrinsic calling :func:`kernel_name` ``(ns)``, whose IR module is linked into the caller's
    library."""
    name = kernel_name(ns)

    def run_block(typingctx, cf, ct, N, k0, k1, UD, RD, MU, M, Y, W, hf, hr, X0, n, mode, OUT, ERR):
        sig = types.void(*_ARG_TYPES)

        def codegen(context, builder, signature, args):
            context.add_linking_libs([_library(context, ns)])
            fnty = ir.FunctionType(ir.VoidType(), [ir.DoubleType() if kind == "double" else ir.IntType(64)
                                                   for _, kind in ARGS])
            fn = cgutils.get_or_insert_function(builder.module, fnty, name)
            builder.call(fn, args)
            return context.get_dummy_value()

        return sig, codegen

    run_block.__name__ = run_block.__qualname__ = f"_run_block_{ns}"
    return intrinsic(run_block)


#: a call of :data:`NAME` (the 8-state car) and of its 12-state specialisation (a powertrain on mounts)
_run_block = _run_block_intrinsic(8)
_run_block_12 = _run_block_intrinsic(12)
#: doubles per chunk's coefficient block, and before its first moment term, per symmetric block size
_COEF = n_coef(8) * LANES
_FIXED_L = LAYOUTS[8][1] * LANES
_COEF_12 = n_coef(12) * LANES
_FIXED_L_12 = LAYOUTS[12][1] * LANES


@numba.njit(cache=True, nogil=True)
def run_chunks(ch0, ch1, CO, n_chunks, nterms, hf, hr, X0, run_start, run_group, UD, RD, MU, Y, W,
               mode, ERR, OUT):  # pragma: no cover - compiled
    """Integrate chunks ``ch0 <= ch < ch1`` of LANES candidates over every run (arguments: see
    :func:`rideid.model.kernel.run_kernel`), one :data:`NAME` call per chunk and run; its 12-state
    specialisation when ``X0`` holds 18 states (a powertrain on mounts), else the 8-state car's."""
    n = X0.shape[2]
    nx = X0.shape[1]
    M = MU.shape[2]
    coef, fixed = (_COEF_12, _FIXED_L_12) if nx == 18 else (_COEF, _FIXED_L)
    pco, pud, prd, pmu, py = CO.ctypes.data, UD.ctypes.data, RD.ctypes.data, MU.ctypes.data, Y.ctypes.data
    pw, px0, pout, perr = W.ctypes.data, X0.ctypes.data, OUT.ctypes.data, ERR.ctypes.data
    for ch in range(ch0, ch1):
        c0 = ch * LANES
        for r in range(run_group.size):
            g = run_group[r]
            cb = pco + 8 * (g * n_chunks + ch) * coef
            ct, x0, w, err = cb + 8 * fixed, px0 + 8 * (r * nx * n + c0), pw + 8 * 10 * r, perr + 8 * (r * n + c0)
            if nx == 18:
                _run_block_12(cb, ct, nterms[g, ch], run_start[r], run_start[r + 1], pud, prd, pmu, M, py, w,
                              hf, hr, x0, n, mode, pout + 8 * c0, err)
            else:
                _run_block(cb, ct, nterms[g, ch], run_start[r], run_start[r + 1], pud, prd, pmu, M, py, w,
                           hf, hr, x0, n, mode, pout + 8 * c0, err)
