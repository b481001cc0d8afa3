"""Road contact: the wheel input ``r`` seen by a rigid disc of radius ``R``.

Two independent methods (SPEC §2, paper §4.2):

* :func:`envelope` (default): the exact upper envelope
  ``r(x) = max_{|s-x|<=R} [h(s) + sqrt(R^2 - (s-x)^2)] - R``, vectorised:
  a coarse search over the disc's footprint, a fine search around the best
  point and a parabolic refinement. Valid for any profile.
* :func:`contact_ode`: the paper's kinematic contact-point model. The
  contact point ``P = (x_p, h(x_p))`` and the wheel centre ``O = P + R n``
  (``n`` the surface normal) are linked by
  ``dx_o/dx_p = 1 - R kappa(x_p)``, ``kappa = h''/(1+h'^2)^{3/2}``, so with
  ``dx_o/dt = V``::

      dx_p/dt = V / (1 - R kappa(x_p))
      z_o = h(x_p) + R / sqrt(1 + h'^2),   r = z_o - R

  solved with SciPy's ``solve_ivp``. It holds only while the wheel keeps a
  single moving contact point, i.e. ``1 - R kappa > 0`` everywhere: the
  wheel radius must be smaller than the smallest radius of curvature of the
  troughs. For a sinusoid ``A sin(2 pi x / L)`` that radius is
  ``L^2 / (4 pi^2 A)``; a larger wheel bridges the troughs (two contact
  points, the contact jumps) and the ODE is singular there:
  :class:`ContactODEError` is raised.

  A slope discontinuity is infinite curvature: where a washboard or
  herringbone begins (flat, then a sine starting with slope ``A 2 pi/L``)
  the real contact point jumps from the flat onto the slope, which the ODE
  cannot do. The ODE is therefore compared with the envelope on smooth
  stretches (inside a sinusoid, started from the exact contact point, or
  over raised-cosine bumps, which are C1).
"""

from __future__ import annotations

import numpy as np

from ..errors import RideidError
from . import backend
from .tracks import WheelPath


class ContactODEError(RideidError):
    """The contact-point ODE is not valid for this profile and radius."""


def envelope(h, x, R: float, n_coarse: int = 201, n_fine: int = 41, chunk: int = 8192):
    """Rigid-disc upper envelope of the profile ``h`` at positions ``x``.

    Parameters
    ----------
    h : callable
        Vectorised road height ``h(s)`` (m).
    x : array_like, shape (n,)
        Wheel-centre positions along the path (m).
    R : float
        Disc radius (m).

    Returns
    -------
    r : ndarray, shape (n,)
        Disc-centre height minus ``R`` (m).
    """
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    d = np.linspace(-R, R, n_coarse)
    circ = np.sqrt(np.maximum(R * R - d * d, 0.0))
    step = d[1] - d[0]
    t = np.linspace(-1.0, 1.0, n_fine)
    for lo in range(0, x.size, chunk):
        xs = x[lo:lo + chunk]
        rows = np.arange(xs.size)
        f = h(xs[:, None] + d[None, :]) + circ[None, :]
        j1 = np.argmax(f, axis=1)
        # a second, separate local peak: where the disc bridges a trough the
        # two contact points nearly tie and the coarse grid may rank them wrongly
        peak = np.zeros_like(f, dtype=bool)
        peak[:, 1:-1] = (f[:, 1:-1] >= f[:, :-2]) & (f[:, 1:-1] >= f[:, 2:])
        peak[rows, j1] = False
        j2 = np.argmax(np.where(peak, f, -np.inf), axis=1)
        best = np.full(xs.size, -np.inf)
        for j in (j1, j2):
            best = np.maximum(best, _refine(h, xs, d[j], step, R, t, rows))
        out[lo:lo + chunk] = best - R
    return out


def _refine(h, xs, dj, step, R, t, rows):
    """Fine search within one coarse step of ``dj`` plus a parabolic step."""
    n_fine = t.size
    df = np.clip(dj[:, None] + step * t[None, :], -R, R)
    ff = h(xs[:, None] + df) + np.sqrt(np.maximum(R * R - df * df, 0.0))
    k = np.argmax(ff, axis=1)
    fk = ff[rows, k]
    km = np.clip(k, 1, n_fine - 2)
    f0, f1, f2 = ff[rows, km - 1], ff[rows, km], ff[rows, km + 1]
    den = f0 - 2 * f1 + f2
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = 0.5 * (f0 - f2) / den
    ok = (den < 0) & (np.abs(delta) <= 1) & (k == km)
    s = np.clip(df[rows, km] + np.where(ok, delta, 0.0) * (df[rows, km + 1] - df[rows, km]), -R, R)
    fr = h(xs + s) + np.sqrt(np.maximum(R * R - s * s, 0.0))
    return np.maximum(fk, np.where(ok, fr, -np.inf))


def lattice_max(H, circ):
    """``max_j H[i + j] + circ[j]`` and its (first) argmax for every ``i`` (``circ`` a disc's height on the
    lattice, a concave sequence): the compiled divide-and-conquer search
    (:func:`rideid.model.kernel_contact.lattice_max`) where it can be built, else the same maxima by
    :func:`lattice_max_numpy` (exactly: both are the brute-force search's)."""
    if backend.compiled_available("contact"):
        return backend.module("contact").lattice_max(H, circ)
    return lattice_max_numpy(H, circ)


def lattice_max_numpy(H, circ, rows: int = 2048):
    """:func:`lattice_max` by brute force in NumPy (blocks of ``rows`` positions): ``O(n m)``, the backend
    without the compiled kernels."""
    H = np.asarray(H, dtype=float)
    circ = np.asarray(circ, dtype=float)
    n, m = H.size - circ.size + 1, circ.size
    best = np.empty(max(n, 0))
    arg = np.empty(max(n, 0), dtype=np.int64)
    if n <= 0:
        return best, arg
    win = np.lib.stride_tricks.sliding_window_view(H, m)
    for lo in range(0, n, rows):
        block = win[lo:lo + rows] + circ[None, :]
        k = np.argmax(block, axis=1)
        arg[lo:lo + rows] = k
        best[lo:lo + rows] = block[np.arange(k.size), k]
    return best, arg


def envelope_grid(path: WheelPath, R: float, dx: float = 5e-4, n_fine: int = 9):
    """The envelope of a wheel path tabulated on a uniform grid.

    The disc's footprint offsets are taken on the grid's own lattice, so the
    profile is evaluated once per lattice point and the search is a compiled
    loop; the best offset is then refined with the exact profile (a fine
    search of +-1 lattice step and a parabolic step), as :func:`envelope`.

    Returns ``(x0, dx, values)``; outside ``[x0, x0 + dx (n-1)]`` the input is
    zero (flat road). Cached on the path.
    """
    key = (float(R), float(dx))
    if key in path._env_cache:
        return path._env_cache[key]
    if path.extent is None:
        res = (0.0, dx, np.zeros(2))
    else:
        lo, hi = path.extent
        lo -= R + 2 * dx
        hi += R + 2 * dx
        n = int(np.ceil((hi - lo) / dx)) + 1
        xg = lo + dx * np.arange(n)
        m = int(np.floor(R / dx))
        offs = dx * np.arange(-m, m + 1)
        circ = np.sqrt(np.maximum(R * R - offs * offs, 0.0))
        H = path.h(lo + dx * np.arange(-m, n + m))
        best, arg = lattice_max(H, circ)
        # refine: exact profile on +-1 lattice step around the best offset
        t = np.linspace(-1.0, 1.0, n_fine)
        vals = np.empty(n)
        contact = np.zeros(n)  # contact offset s - x of each grid point (for the slope)
        chunk = 65536
        for a in range(0, n, chunk):
            b = min(n, a + chunk)
            d = np.clip(offs[arg[a:b], None] + dx * t[None, :], -R, R)
            f = path.h(xg[a:b, None] + d) + np.sqrt(np.maximum(R * R - d * d, 0.0))
            k = np.clip(np.argmax(f, axis=1), 1, n_fine - 2)
            rows = np.arange(b - a)
            f0, f1, f2 = f[rows, k - 1], f[rows, k], f[rows, k + 1]
            den = f0 - 2 * f1 + f2
            with np.errstate(divide="ignore", invalid="ignore"):
                delta = 0.5 * (f0 - f2) / den
            ok = (den < 0) & (np.abs(delta) <= 1)
            s = np.clip(d[rows, k] + np.where(ok, delta, 0.0) * (d[rows, k + 1] - d[rows, k]), -R, R)
            fr = path.h(xg[a:b] + s) + np.sqrt(np.maximum(R * R - s * s, 0.0))
            fmax = f.max(axis=1)
            vals[a:b] = np.maximum(np.maximum(fmax, fr), best[a:b]) - R
            contact[a:b] = np.where(ok & (fr >= fmax), s, d[rows, np.argmax(f, axis=1)])
        res = (lo, dx, vals)
        contact.flags.writeable = False
        path._env_cache[key + ("contact",)] = contact
    res[2].flags.writeable = False  # shared by every track of the path's kind and keys (rideid.model.tracks)
    path._env_cache[key] = res
    return res


def wheel_input(path: WheelPath, x, R: float, dx: float = 5e-4, shift: float = 0.0, out=None):
    """Envelope input at positions ``x + shift`` (1-D) by linear interpolation on the grid; written into ``out``
    (a 1-D view, a column of a wider array say) when given."""
    x0, step, vals = envelope_grid(path, R, dx)
    x = np.asarray(x, dtype=float)
    out = np.empty(x.shape) if out is None else out
    if vals.size >= 2 and backend.compiled_available("contact"):
        backend.module("contact").interp_grid(x, float(shift), float(x0), float(step), vals, out)
    else:
        out[...] = np.interp(x + shift, x0 + step * np.arange(vals.size), vals, left=0.0, right=0.0)
    return out


def wheel_input_slope(path: WheelPath, x, R: float, dx: float = 5e-4, shift: float = 0.0, out=None):
    """Slope ``dr/dx`` of the envelope input at positions ``x + shift`` (1-D, dimensionless; written into ``out``
    when given, as :func:`wheel_input`).

    From the contact geometry: a disc touching the road at offset ``d = s - x``
    from its centre has ``dr/dx = d / sqrt(R^2 - d^2)`` (envelope theorem).
    Between two grid points on the same contact branch the slopes are
    interpolated linearly (second order); where the contact point jumps
    between them (the envelope's slope kinks: a concave corner, a bridged
    trough) the branch that is higher at ``x`` is the contact, and its own
    slope is used, so a kink is resolved exactly, as the height's kinks are
    in the input moments.
    """
    x0, step, vals = envelope_grid(path, R, dx)
    x = np.asarray(x, dtype=float)
    out = np.empty(x.shape) if out is None else out
    if vals.size < 3:
        out[...] = 0.0
        return out
    off = path._env_cache[(float(R), float(dx), "contact")]
    if backend.compiled_available("contact"):
        backend.module("contact").slope_grid(x, float(shift), float(x0), float(step), vals, off, float(R), out)
        return out
    x = x + shift
    out[...] = 0.0
    pos = (x - x0) / step
    inside = (pos >= 0) & (pos <= vals.size - 1)
    p = pos[inside]
    j = np.minimum(np.floor(p).astype(np.int64), vals.size - 2)
    w = p - j
    d0, d1 = off[j], off[j + 1]
    s0, s1 = d0 / np.sqrt(R * R - d0 * d0), d1 / np.sqrt(R * R - d1 * d1)
    smooth = s0 + w * (s1 - s0)
    # contact jump between the grid points: pick the higher circle at x
    xs = x[inside]
    xj = x0 + step * j
    c0, c1 = xj + d0, xj + step + d1  # contact points (absolute)
    jump = np.abs(c1 - c0) > 4 * step
    if jump.any():
        h0 = vals[j] + R - np.sqrt(R * R - d0 * d0)  # road height at the contact points
        h1 = vals[j + 1] + R - np.sqrt(R * R - d1 * d1)
        e0, e1 = c0 - xs, c1 - xs
        v0 = h0 + np.sqrt(np.maximum(R * R - e0 * e0, 0.0))
        v1 = h1 + np.sqrt(np.maximum(R * R - e1 * e1, 0.0))
        e = np.clip(np.where(v0 >= v1, e0, e1), -0.999 * R, 0.999 * R)
        smooth = np.where(jump, e / np.sqrt(R * R - e * e), smooth)
    out[inside] = smooth
    return out


def contact_ode(path: WheelPath, R: float, speed: float, t, x0: float = 0.0,
                rtol: float = 1e-10, atol: float = 1e-13):
    """Wheel input by the paper's contact-point ODE (see module docstring).

    Parameters
    ----------
    path : WheelPath
        Must be analytic (``d1`` and ``d2`` given).
    R : float
        Wheel radius (m).
    speed : float
        Constant forward speed V (m/s).
    t : array_like, shape (n,)
        Output times (s), increasing from 0.
    x0 : float
        Wheel-centre position at ``t = 0`` (on flat road).

    Returns
    -------
    r : ndarray, shape (n,)

    Raises
    ------
    ContactODEError
        If the path has no derivatives, or if ``1 - R kappa`` reaches zero
        (the wheel would bridge a trough: the single-contact ODE is invalid).
    """
    if path.d1 is None or path.d2 is None:
        raise ContactODEError("contact ODE needs an analytic profile (h', h''); use the envelope")
    if R >= path.min_trough_radius:
        raise ContactODEError(
            f"contact ODE invalid: wheel radius {R} m exceeds the smallest trough radius of "
            f"curvature {path.min_trough_radius:.4g} m, so the wheel bridges troughs")
    t = np.asarray(t, dtype=float)
    # initial contact point: x_o(x_p) = x0, monotone in x_p while 1 - R kappa > 0
    xp0 = x0
    if abs(float(path.d1(np.array(x0)))) > 0 or abs(float(path.h(np.array(x0)))) > 0:
        from scipy.optimize import brentq
        xp0 = brentq(lambda s: float(wheel_centre_x(path, np.array(s), R)) - x0, x0 - R, x0 + R, xtol=1e-14)

    def kappa(xp):
        d1 = path.d1(xp)
        return path.d2(xp) / (1 + d1 * d1) ** 1.5

    def rhs(_t, y):
        return [speed / (1 - R * kappa(np.array(y[0])))]

    def singular(_t, y):
        return 1 - R * kappa(np.array(y[0])) - 1e-9

    singular.terminal = True
    # the disc must start on flat road: its footprint clear of features
    from scipy.integrate import solve_ivp  # here: SciPy's integrators take 0.4 s to import

    sol = solve_ivp(rhs, (t[0], t[-1]), [xp0], method="DOP853", t_eval=t, rtol=rtol, atol=atol,
                    events=singular, max_step=_max_step(path, speed))
    if sol.status == 1 or sol.y.shape[1] != t.size:
        raise ContactODEError("contact ODE became singular (1 - R*kappa = 0): the wheel bridges a trough")
    xp = sol.y[0]
    d1 = path.d1(xp)
    return path.h(xp) + R / np.sqrt(1 + d1 * d1) - R


def _max_step(path, speed):
    # do not step over a whole feature on the flat lead-in
    if path.extent is None:
        return np.inf
    return max((path.extent[1] - path.extent[0]) / speed / 200, 1e-5)


def wheel_centre_x(path: WheelPath, xp, R: float):
    """Wheel-centre position for a contact point (for checks): x_p - R h'/sqrt(1+h'^2)."""
    d1 = path.d1(xp)
    return xp - R * d1 / np.sqrt(1 + d1 * d1)
