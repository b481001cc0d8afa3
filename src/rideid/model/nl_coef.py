"""Per-candidate coefficient slots of the nonlinear car (:mod:`rideid.model.nonlinear`), and the plain
arithmetic both its backends share.

Shared by the NumPy backend (:mod:`rideid.model.nonlinear`) and the compiled
kernel (:mod:`rideid.model.kernel_nl`), which therefore import no one another
(the compiled kernel is imported only when it runs, :mod:`rideid.model.backend`).
"""

from __future__ import annotations

#: coefficient names, per candidate: car-wide ones, then per corner (fl, fr, rl, rr)
COEF = ("inv_ms", "inv_Iyy", "inv_Ixx", "topple", "kar_f", "kar_r",
        *(f"{n}{c}" for n in ("inv_mu", "x", "y", "ks", "cs", "kt", "ct", "L", "bs_clear", "bs_rate")
          for c in range(4)))
#: with a powertrain on mounts (SPEC §11): the inverse of the mass matrix over ``(z, theta, u, psi)`` (its ten
#: entries on and above the diagonal, ``pt_m{row}{column}``) and the mounts' rates ``k``, ``c`` in bounce (``u``)
#: and pitch (``psi``); appended, so the car without the group keeps its slots
PT_COEF = ("pt_m00", "pt_m01", "pt_m02", "pt_m03", "pt_m11", "pt_m12", "pt_m13", "pt_m22", "pt_m23", "pt_m33",
           "pt_ku", "pt_cu", "pt_kpsi", "pt_cpsi")
COEF = COEF + PT_COEF
CI = {n: i for i, n in enumerate(COEF)}


def hermite_value_slope(t, s0, s1, m0, m1):
    """Value and derivative at ``theta = t`` of the cubic Hermite with values ``s0, s1`` and slopes ``m0, m1``
    (per unit ``theta``) at 0 and 1. Plain arithmetic: the same operations on scalars in the compiled kernel
    and on arrays in :func:`rideid.model.nonlinear.hermite_root`."""
    t2 = t * t
    t3 = t2 * t
    val = ((2.0 * t3 - 3.0 * t2 + 1.0) * s0 + (t3 - 2.0 * t2 + t) * m0 + (3.0 * t2 - 2.0 * t3) * s1
           + (t3 - t2) * m1)
    der = (6.0 * t2 - 6.0 * t) * (s0 - s1) + (3.0 * t2 - 4.0 * t + 1.0) * m0 + (3.0 * t2 - 2.0 * t) * m1
    return val, der
