"""Per-candidate coefficient slots of the nonlinear car (:mod:`rideid.model.nonlinear`).

Shared by the NumPy backend (:mod:`rideid.model.nonlinear`) and the compiled
kernel (:mod:`rideid.model.kernel_nl`), which therefore import no one another.
"""

from __future__ import annotations

#: coefficient names, per candidate: car-wide ones, then per corner (fl, fr, rl, rr)
COEF = ("inv_ms", "inv_Iyy", "inv_Ixx", "topple", "kar_f", "kar_r",
        *(f"{n}{c}" for n in ("inv_mu", "x", "y", "ks", "cs", "kt", "ct", "L", "bs_clear", "bs_rate")
          for c in range(4)))
CI = {n: i for i, n in enumerate(COEF)}
