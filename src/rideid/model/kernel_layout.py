"""Layout of the compiled kernel's coefficient block (used by :mod:`rideid.model.kernel` and its IR).

The kernel integrates :data:`LANES` candidate cars side by side, one per
lane of a ``<4 x double>`` vector. Every parameter-dependent coefficient is
stored for the four candidates of a chunk next to each other (lane index
innermost), so that one unaligned vector load fetches it for all four.

Coefficient block of one chunk: a fixed part, then a part per moment term
``t`` (``G_s[t]`` then ``G_a[t]``), see :func:`coefficient_layout`; each
entry is :data:`LANES` doubles.

The symmetric block has :data:`SYM_STATES` states: 8, or 12 with a
powertrain on mounts (SPEC §11: its heave and pitch relative to the body).
The kernel is compiled once per size; :data:`LAYOUTS` holds each size's
layout, :func:`n_coef` its block's length (:data:`N_COEF` the 8-state
car's).
"""

from __future__ import annotations

#: Candidates integrated side by side: one AVX2 register of doubles.
LANES = 4
#: Largest number of moment terms the kernel accepts (= rideid.model.discretize.N_MAX).
N_MAX_K = 24

#: Sizes of the symmetric block the kernel is compiled for: the car, and the car with a powertrain on mounts.
SYM_STATES = (8, 12)


def fixed_blocks(ns: int = 8):
    """(name, shape) of the parameter-dependent blocks, in the order of the coefficient block, for a
    symmetric block of ``ns`` states."""
    return (("Phi_s", (ns, ns)), ("Ca_s", (4, ns)), ("Da_s", (4, 2)), ("Dr_s", (4, 2)),
            ("Phi_a", (6, 6)), ("Ca_a", (3, 6)), ("Da_a", (3, 2)), ("Dr_a", (3, 2)),
            ("a", ()), ("b", ()))


def term_blocks(ns: int = 8):
    """(name, shape) of the blocks of one moment term, for a symmetric block of ``ns`` states."""
    return (("G_s", (ns, 2)), ("G_a", (6, 2)))


def _size(shape):
    s = 1
    for d in shape:
        s *= d
    return s


def coefficient_layout(ns: int = 8):
    """Offsets (in entries per lane) of every block: ``{name: (offset, shape)}``, and the sizes, for a
    symmetric block of ``ns`` states.

    Returns
    -------
    offsets : dict
    fixed : int
        Entries before the first moment term.
    per_term : int
        Entries per moment term.
    """
    off, pos = {}, 0
    for name, shape in fixed_blocks(ns):
        off[name] = (pos, shape)
        pos += _size(shape)
    fixed, tpos = pos, 0
    for name, shape in term_blocks(ns):
        off[name] = (fixed + tpos, shape)
        tpos += _size(shape)
    return off, fixed, tpos


#: symmetric block size -> (offsets, fixed, per_term) of :func:`coefficient_layout`
LAYOUTS = {ns: coefficient_layout(ns) for ns in SYM_STATES}


def n_coef(ns: int = 8) -> int:
    """Entries per lane of a full coefficient block, for a symmetric block of ``ns`` states."""
    _, fixed, per_term = LAYOUTS[ns]
    return fixed + per_term * N_MAX_K


#: Entries per lane of a full coefficient block (the 8-state car).
N_COEF = n_coef(8)


def flat_index(name: str, *ij, ns: int = 8) -> int:
    """Entry (per lane) of element ``ij`` of block ``name`` in a chunk's coefficient block (symmetric block
    of ``ns`` states)."""
    off, shape = LAYOUTS[ns][0][name]
    flat = 0
    for i, d in zip(ij, shape):
        flat = flat * d + i
    return off + flat
