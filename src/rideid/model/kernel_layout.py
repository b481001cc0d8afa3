"""Layout of the compiled kernel's coefficient block (used by :mod:`rideid.model.kernel` and its IR).

The kernel integrates :data:`LANES` candidate cars side by side, one per
lane of a ``<4 x double>`` vector. Every parameter-dependent coefficient is
stored for the four candidates of a chunk next to each other (lane index
innermost), so that one unaligned vector load fetches it for all four.

Coefficient block of one chunk: :data:`FIXED` entries, then
:data:`PER_TERM` entries per moment term ``t`` (``G_s[t]`` then
``G_a[t]``), see :func:`coefficient_layout`; each entry is :data:`LANES`
doubles.
"""

from __future__ import annotations

#: Candidates integrated side by side: one AVX2 register of doubles.
LANES = 4
#: Largest number of moment terms the kernel accepts (= rideid.model.discretize.N_MAX).
N_MAX_K = 24

#: (name, shape) of the parameter-dependent blocks, in the order of the coefficient block.
FIXED_BLOCKS = (("Phi_s", (8, 8)), ("Ca_s", (4, 8)), ("Da_s", (4, 2)), ("Dr_s", (4, 2)),
                ("Phi_a", (6, 6)), ("Ca_a", (3, 6)), ("Da_a", (3, 2)), ("Dr_a", (3, 2)),
                ("a", ()), ("b", ()))
TERM_BLOCKS = (("G_s", (8, 2)), ("G_a", (6, 2)))


def _size(shape):
    s = 1
    for d in shape:
        s *= d
    return s


def coefficient_layout():
    """Offsets (in entries per lane) of every block: ``{name: (offset, shape)}``, and the sizes.

    Returns
    -------
    offsets : dict
    fixed : int
        Entries before the first moment term.
    per_term : int
        Entries per moment term.
    """
    off, pos = {}, 0
    for name, shape in FIXED_BLOCKS:
        off[name] = (pos, shape)
        pos += _size(shape)
    fixed, tpos = pos, 0
    for name, shape in TERM_BLOCKS:
        off[name] = (fixed + tpos, shape)
        tpos += _size(shape)
    return off, fixed, tpos


OFFSETS, FIXED, PER_TERM = coefficient_layout()
#: Entries per lane of a full coefficient block.
N_COEF = FIXED + PER_TERM * N_MAX_K


def flat_index(name: str, *ij) -> int:
    """Entry (per lane) of element ``ij`` of block ``name`` in a chunk's coefficient block."""
    off, shape = OFFSETS[name]
    flat = 0
    for i, d in zip(ij, shape):
        flat = flat * d + i
    return off + flat
