"""The 7-DOF full-car ride model of SPEC §1, batched over parameter sets.

Generalised coordinates ``q = [z, theta, phi, z_fl, z_fr, z_rl, z_rr]``
(body heave, pitch nose-down +, roll right-side-down +, wheel heaves), road
inputs ``r = [r_fl, r_fr, r_rl, r_rr]``. Corner ``i`` sits at ``(x_i, y_i)``
relative to the CG; the body moves there by ``z_bi = G_i q_b`` with
``G_i = [1, -x_i, y_i]``. The suspension force on the body is
``F_i = k_s (z_i - z_bi) + c_s (dz_i - dz_bi)`` so that

    m_s z''   =  sum F_i
    I_yy th'' = -sum x_i F_i
    I_xx ph'' =  sum y_i F_i
    m_u z_i'' = -F_i + k_t (r_i - z_i)

Written as ``M q'' + C q' + K q = Bf r + Bd r'`` with ``K = sum k_i e_i e_i^T +
diag(0,0,0,k_t)``, ``e_i = [-G_i, unit_i]``; the same form for ``C``.

CG height (SPEC §8, ``geom.cg_height = h``, 0 by default): each wheel's
swing about the CG adds ``m_u h^2`` to the pitch and roll inertias
(``M[theta] = I_yy + 2 (m_uf + m_ur) h^2``, likewise ``M[phi]`` with
``I_xx``) and gravity adds the toppling stiffness ``-m_s g h`` to the pitch
and roll diagonal of ``K``. Both are diagonal in pitch and roll, so the
symmetric/antisymmetric split below still holds; with ``h = 0`` nothing
changes (bit for bit).

Extensions (SPEC §6, 0 when absent). An anti-roll bar of rate ``k_ar`` on the
axle with corners ``i, j`` adds ``k_ar (d_i - d_j)`` to ``F_i`` (``d_i = e_i q``
the suspension deflection), i.e. ``K += k_ar (e_i - e_j)(e_i - e_j)^T``: heave
(``d_i = d_j``) leaves it unloaded, in roll the axle's roll stiffness is
``(k_s + 2 k_ar) track^2 / 2``. Tire damping ``c_t`` adds ``c_t`` to ``C`` at
the wheel and the road-rate input ``Bd r'`` (``Bd = diag(c_t)`` on the wheels).

Powertrain on mounts (SPEC §11, group ``powertrain``, present when
``m_p > 0``): a rigid body of mass ``m_p`` and pitch inertia ``I_p`` (about
its own CG) inside the sprung mass, its CG ``x_p`` ahead of the whole sprung
mass's CG, on mounts in bounce and pitch. Two more coordinates
(:data:`POWERTRAIN_COORDS`): ``u`` its heave relative to the body point
beneath it (``z_p = z - x_p theta + u``) and ``psi`` its pitch relative to
the body (``theta_p = theta + psi``). ``m_s``, ``I_yy`` and ``a`` stay the
whole sprung mass's (powertrain included as if rigid): the kinetic energy
``1/2 m_b (z' - x_b theta')^2 + 1/2 I_b theta'^2 + 1/2 m_p (z' - x_p theta'
+ u')^2 + 1/2 I_p (theta' + psi')^2`` of the body (``m_b = m_s - m_p``, CG at
``x_b = -m_p x_p / m_b``, ``I_b`` about its own CG) and the powertrain is,
with ``m_b x_b + m_p x_p = 0`` and ``I_b + m_b x_b^2 + I_p + m_p x_p^2 =
I_yy``,

    M[z, z] = m_s, M[theta, theta] = I_yy, M[u, u] = M[z, u] = m_p,
    M[theta, u] = -m_p x_p, M[psi, psi] = M[theta, psi] = I_p,

so with the mounts locked (``u = psi = 0``) the model of SPEC §1 is
recovered exactly. The mounts are a spring and damper on each relative
coordinate, given by the frequencies and damping ratios with the body held
(``K[u, u] = m_p (2 pi f_pb)^2``, ``C[u, u] = 2 zeta_pb m_p 2 pi f_pb``, and
in pitch with ``I_p``, ``f_pp``, ``zeta_pp``). The suspension acts on the
body frame, which ``z``, ``theta`` still describe, so ``K``, ``C`` and the
outputs are unchanged on the body coordinates and the accelerometers and
gyros read the body as before. The powertrain coordinates join the
symmetric block (12 states instead of 8); rows of a batch without a
powertrain (``m_p = 0``) get a unit-mass dummy there, decoupled from the car.
The CG height's terms are the whole sprung mass's (the powertrain's small
relative motion does not change them).

State ``x = [q, q']`` (14; 18 with a powertrain), ``x' = A x + B r + Br r'``. Outputs (SPEC channel
order, :data:`CHANNELS`) ``y = Cy x + Dy r + Dyr r'`` (:func:`state_space`,
:func:`rate_input`): the accelerometers read ``Omega q''`` (:func:`output_map`:
body corner ``i`` reads ``G_i q_b''``, axle ``i`` reads ``z_i''``) and the
gyros ``theta'``, ``phi'`` (:data:`RATE_COORDS`). This is the one definition
of the output map; the compiled kernel and the reference simulation are
tested against it.

With equal left/right parameters the model splits exactly into a symmetric
part (heave, pitch and the in-phase wheel motions, 8 states) and an
antisymmetric part (roll and the anti-phase wheel motions, 6 states):
:func:`blocks` returns both; the compiled kernel integrates them separately.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .params import ALL_NAMES, GRAVITY, INDEX, NAMES, Geometry, full_rows, has_powertrain

CHANNELS: tuple[str, ...] = (
    "body_az_fl", "body_az_fr", "body_az_rl", "body_az_rr",
    "axle_az_fl", "axle_az_fr", "axle_az_rl", "axle_az_rr",
    "pitch_rate", "roll_rate",
)
CHANNEL_UNITS = {c: ("rad/s" if c.endswith("rate") else "m/s^2") for c in CHANNELS}
#: Channel kinds used for normalisation floors: body, axle, rate.
CHANNEL_KIND = {c: ("rate" if c.endswith("rate") else c.split("_")[0]) for c in CHANNELS}

COORDS = ("z", "theta", "phi", "z_fl", "z_fr", "z_rl", "z_rr")
#: Coordinates of the symmetric / antisymmetric decomposition:
#: ``[z, theta, zf_s, zr_s | phi, zf_a, zr_a]`` with ``zf_s = (z_fl+z_fr)/2``,
#: ``zf_a = (z_fl-z_fr)/2`` (likewise rear); inputs
#: ``[rf_s, rr_s | rf_a, rr_a]``.
SYM_COORDS = ("z", "theta", "zf_s", "zr_s")
ANTI_COORDS = ("phi", "zf_a", "zr_a")

#: The powertrain's coordinates (SPEC §11), after :data:`COORDS` and after :data:`SYM_COORDS` in the
#: symmetric block: its heave relative to the body point beneath it, its pitch relative to the body.
POWERTRAIN_COORDS = ("u_p", "psi_p")
#: Frequency (Hz) of the decoupled unit-mass dummy that stands in for the powertrain of a row without one
#: in a batch with powertrains (its damping ratio 0.5): below the fastest wheel hop, so it never sets the
#: discretisation's series length.
DUMMY_HZ = 10.0

#: Coordinate index (in :data:`COORDS`) whose rate each gyro channel reads.
RATE_COORDS = {"pitch_rate": 1, "roll_rate": 2}

# q = T qt  (qt in decomposed order), r = TR rt
_T = np.zeros((7, 7))
_T[0, 0] = 1  # z
_T[1, 1] = 1  # theta
_T[2, 4] = 1  # phi
_T[3, 2], _T[3, 5] = 1, 1    # z_fl = zf_s + zf_a
_T[4, 2], _T[4, 5] = 1, -1   # z_fr = zf_s - zf_a
_T[5, 3], _T[5, 6] = 1, 1    # z_rl
_T[6, 3], _T[6, 6] = 1, -1   # z_rr
_TR = np.array([[1, 0, 1, 0], [1, 0, -1, 0], [0, 1, 0, 1], [0, 1, 0, -1]], dtype=float)
#: Corner inputs -> decomposed inputs (inverse of ``_TR``).
CORNER_TO_DECOMPOSED = np.linalg.inv(_TR)
#: Decomposed coordinates ``[z, theta, zf_s, zr_s, phi, zf_a, zr_a]`` -> :data:`COORDS`.
DECOMPOSED_TO_COORDS = _T.copy()
# with a powertrain: q = [COORDS, u, psi], decomposed [z, theta, zf_s, zr_s, u, psi | phi, zf_a, zr_a]
_T9 = np.zeros((9, 9))
_T9[:7, :4] = _T[:, :4]
_T9[:7, 6:] = _T[:, 4:]
_T9[7, 4] = _T9[8, 5] = 1.0


def _transform(nq: int) -> np.ndarray:
    """``q = T qt`` for ``nq`` coordinates (7, or 9 with a powertrain)."""
    return _T if nq == 7 else _T9


def _cols(P):
    P = full_rows(P)
    return {n: P[:, i] for i, n in enumerate(ALL_NAMES)}, P.shape[0]


def _corner_vectors(P, geom, nq: int = 7):
    """Rows ``e_i = [-G_i, unit_i]`` (n, 4, nq): ``d_i = e_i q`` is corner i's deflection
    (wheel minus body corner motion, both read off the output map; 0 on the powertrain's coordinates)."""
    Om = output_map(P, geom)
    E = np.zeros(Om.shape[:1] + (4, nq))
    E[:, :, :7] = Om[:, 4:] - Om[:, :4]
    return E


def output_map(P, geom: Geometry) -> np.ndarray:
    """The accelerometer channels as a linear map of the generalised accelerations.

    Body corner ``i`` at ``(x_i, y_i)`` from the CG reads
    ``z'' - x_i theta'' + y_i phi''`` (pitch nose-down +, roll right-side-down
    +); axle ``i`` reads its wheel's ``z_i''``.

    Parameters
    ----------
    P : array_like, shape (n, len(NAMES))
    geom : Geometry

    Returns
    -------
    Omega : ndarray, shape (n, 8, 7)
        ``y[:8] = Omega q''`` for the first eight :data:`CHANNELS`, ``q`` in
        :data:`COORDS` order.
    """
    p, n = _cols(P)
    x, y = geom.corner_xy(p["a"])
    Om = np.zeros((n, 8, 7))
    Om[:, :4, 0] = 1.0
    Om[:, :4, 1] = -x
    Om[:, :4, 2] = y
    Om[:, 4 + np.arange(4), 3 + np.arange(4)] = 1.0
    return Om


def n_coords(P) -> int:
    """Generalised coordinates of the model of rows ``P``: 7, or 9 when any row has a powertrain."""
    return 9 if has_powertrain(P) else 7


def mck(P, geom: Geometry):
    """Mass, damping, stiffness and input matrices for a batch.

    Parameters
    ----------
    P : array_like, shape (n, 12), (n, 16) or (n, 23)
        Parameter rows in :data:`rideid.model.params.NAMES` order, optionally
        followed by the extensions (:data:`rideid.model.params.EXT_NAMES`;
        absent means 0).
    geom : Geometry

    Returns
    -------
    M, C, K : ndarray, shape (n, nq, nq)
        ``nq`` = 7, or 9 when a row has a powertrain (:func:`n_coords`:
        :data:`COORDS` then :data:`POWERTRAIN_COORDS`).
    Bf : ndarray, shape (n, nq, 4)
        Generalised force per unit road input (tire springs).
    """
    nq = n_coords(P)
    p, n = _cols(P)
    ks = np.stack([p["k_sf"], p["k_sf"], p["k_sr"], p["k_sr"]], -1)
    cs = np.stack([p["c_sf"], p["c_sf"], p["c_sr"], p["c_sr"]], -1)
    kt = np.stack([p["k_tf"], p["k_tf"], p["k_tr"], p["k_tr"]], -1)
    ct = np.stack([p["c_tf"], p["c_tf"], p["c_tr"], p["c_tr"]], -1)
    mu = np.stack([p["m_uf"], p["m_uf"], p["m_ur"], p["m_ur"]], -1)
    E = _corner_vectors(P, geom, nq)
    K = np.einsum("nij,ni,nik->njk", E, ks, E)
    C = np.einsum("nij,ni,nik->njk", E, cs, E)
    # anti-roll bars: k_ar (e_i - e_j)(e_i - e_j)^T per axle
    for (i, j), kar in (((0, 1), p["k_arf"]), ((2, 3), p["k_arr"])):
        De = E[:, i] - E[:, j]
        K += kar[:, None, None] * De[:, :, None] * De[:, None, :]
    K[:, 3 + np.arange(4), 3 + np.arange(4)] += kt
    C[:, 3 + np.arange(4), 3 + np.arange(4)] += ct
    M = np.zeros((n, nq, nq))
    M[:, 0, 0] = p["m_s"]
    M[:, 1, 1] = p["I_yy"]
    M[:, 2, 2] = p["I_xx"]
    M[:, 3 + np.arange(4), 3 + np.arange(4)] = mu
    h = geom.cg_height
    if h > 0:  # SPEC §8: the wheels swing about the CG, gravity topples the body
        swing = 2.0 * (p["m_uf"] + p["m_ur"]) * h * h
        M[:, 1, 1] += swing
        M[:, 2, 2] += swing
        topple = p["m_s"] * GRAVITY * h
        K[:, 1, 1] -= topple
        K[:, 2, 2] -= topple
    if nq == 9:
        _powertrain(M, C, K, p)
    Bf = np.zeros((n, nq, 4))
    Bf[:, 3 + np.arange(4), np.arange(4)] = kt
    return M, C, K, Bf


def _powertrain(M, C, K, p):
    """In place: the powertrain's coordinates 7 (``u``) and 8 (``psi``) of ``M``, ``C``, ``K`` (module
    docstring); a unit-mass dummy (:data:`DUMMY_HZ`, decoupled) where a row has no powertrain."""
    m_p, x_p, I_p = p["m_p"], p["x_p"], p["I_p"]
    for j, mass, f, zeta in ((7, m_p, p["f_pb"], p["zeta_pb"]), (8, I_p, p["f_pp"], p["zeta_pp"])):
        on = (m_p > 0) & (mass > 0)
        m = np.where(on, mass, 1.0)
        w = 2 * np.pi * np.where(on, f, DUMMY_HZ)
        M[:, j, j] = m
        K[:, j, j] = m * w * w
        C[:, j, j] = 2 * np.where(on, zeta, 0.5) * m * w
    on_b = m_p > 0
    M[:, 0, 7] = M[:, 7, 0] = np.where(on_b, m_p, 0.0)
    M[:, 1, 7] = M[:, 7, 1] = np.where(on_b, -m_p * x_p, 0.0)
    M[:, 1, 8] = M[:, 8, 1] = np.where(on_b & (I_p > 0), I_p, 0.0)


def rate_input(P, geom: Geometry):
    """Generalised force per unit road-input rate (tire dampers), shape (n, nq, 4) (:func:`n_coords`).

    Zero without tire damping.
    """
    p, n = _cols(P)
    Bd = np.zeros((n, n_coords(P), 4))
    ct = np.stack([p["c_tf"], p["c_tf"], p["c_tr"], p["c_tr"]], -1)
    Bd[:, 3 + np.arange(4), np.arange(4)] = ct
    return Bd


def _state_space(M, C, K, Bf, *more):
    """``A`` and ``B`` of ``M q'' + C q' + K q = Bf r``, and one more ``B`` for each input matrix in ``more``."""
    nq = M.shape[-1]
    Minv = np.linalg.inv(M)
    n = M.shape[0]
    A = np.zeros((n, 2 * nq, 2 * nq))
    A[:, :nq, nq:] = np.eye(nq)
    A[:, nq:, :nq] = -Minv @ K
    A[:, nq:, nq:] = -Minv @ C
    Bs = []
    for F in (Bf, *more):
        B = np.zeros((n, 2 * nq, F.shape[-1]))
        B[:, nq:, :] = Minv @ F
        Bs.append(B)
    return (A, *Bs)


def _output_rows(acc, Om):
    """Ten channels' rows from generalised-acceleration rows ``acc`` (n, nq, k) (the first 7, :data:`COORDS`,
    are read); gyro rows left 0."""
    out = np.zeros((acc.shape[0], 10, acc.shape[-1]))
    out[:, :8] = Om @ acc[:, :7]
    return out


def state_space(P, geom: Geometry, rate: bool = False):
    """Full model (14 states; 18 with a powertrain) with the ten SPEC output channels.

    ``x' = A x + B r + Br r'``, ``y = Cy x + Dy r + Dyr r'``; states
    ``[q, q']``, ``q`` in :data:`COORDS` order then, with a powertrain,
    :data:`POWERTRAIN_COORDS`.

    Returns
    -------
    A : (n, 2nq, 2nq), B : (n, 2nq, 4), Cy : (n, 10, 2nq), Dy : (n, 10, 4)
        and, with ``rate``, also ``Br : (n, 2nq, 4)``, ``Dyr : (n, 10, 4)``
        (zero without tire damping); ``nq`` = 7 or 9 (:func:`n_coords`).
    """
    M, C, K, Bf = mck(P, geom)
    nq = M.shape[-1]
    A, B, *Br = _state_space(M, C, K, Bf, *([rate_input(P, geom)] if rate else []))
    Om = output_map(P, geom)
    Cy = _output_rows(A[:, nq:, :], Om)
    Dy = _output_rows(B[:, nq:, :], Om)
    for c, k in RATE_COORDS.items():
        Cy[:, CHANNELS.index(c), nq + k] = 1.0
    if not rate:
        return A, B, Cy, Dy
    return A, B, Cy, Dy, Br[0], _output_rows(Br[0][:, nq:, :], Om)


def force_input(P, geom: Geometry):
    """The car's response to a force pair at each corner: ``+u_i`` on the body at corner ``i`` and ``-u_i`` on its
    wheel (a suspension force, compression +, as the damper's :func:`rideid.model.nonlinear.damper_force`), so
    that ``x' = A x + Bu u``, ``y = Cy x + Dyu u`` with :func:`state_space`'s ``A`` and ``Cy``.

    Its generalised force is ``-e_i u_i`` (``e_i`` the corner's deflection row): a linear damper's ``-C q'``
    is ``-sum_i e_i c v_i``, so ``u_i = D(v_i) - c v_i`` turns the linear car's damper into the curve.

    Returns
    -------
    Bu : (n, 2nq, 4), Dyu : (n, 10, 4)
    """
    M, C, K, _ = mck(P, geom)
    nq = M.shape[-1]
    _, Bu = _state_space(M, C, K, -np.swapaxes(_corner_vectors(P, geom, nq), 1, 2))
    return Bu, _output_rows(Bu[:, nq:, :], output_map(P, geom))


def decomposed_mck(P, geom: Geometry, rate: bool = False):
    """``M, C, K, Bf`` (and with ``rate`` also ``Bd``) in the symmetric/antisymmetric coordinates.

    Exact congruence ``T^T M T`` etc.; the off-diagonal blocks vanish
    because left and right share parameters (tested). The anti-roll bars
    enter only the antisymmetric block.
    """
    M, C, K, Bf = mck(P, geom)
    T = _transform(M.shape[-1])
    f = lambda X: T.T @ X @ T  # noqa: E731
    out = (f(M), f(C), f(K), T.T @ Bf @ _TR)
    if rate:
        out += (T.T @ rate_input(P, geom) @ _TR,)
    return out


def blocks(P, geom: Geometry):
    """Symmetric and antisymmetric state-space blocks.

    Returns
    -------
    dict with
      ``As`` (n, 8, 8), ``Bs`` (n, 8, 2), ``Brs`` (n, 8, 2): states
      ``[z, theta, zf_s, zr_s, rates]``, inputs ``[rf_s, rr_s]`` and their rates
      (with a powertrain 12 states: ``[z, theta, zf_s, zr_s, u, psi, rates]``);
      ``Aa`` (n, 6, 6), ``Ba`` (n, 6, 2), ``Bra`` (n, 6, 2): states
      ``[phi, zf_a, zr_a, rates]``, inputs ``[rf_a, rr_a]`` and their rates.
      ``x' = A x + B u + Br u'``; ``Br`` is zero without tire damping.
    """
    M, C, K, Bf, Bd = decomposed_mck(P, geom, rate=True)
    ns = M.shape[-1] - 3
    s, a = np.arange(ns), np.arange(ns, ns + 3)
    sel = lambda X, r, c: X[:, r][:, :, c]  # noqa: E731
    As, Bs, Brs = _state_space(sel(M, s, s), sel(C, s, s), sel(K, s, s), sel(Bf, s, np.arange(2)),
                               sel(Bd, s, np.arange(2)))
    Aa, Ba, Bra = _state_space(sel(M, a, a), sel(C, a, a), sel(K, a, a), sel(Bf, a, np.arange(2, 4)),
                               sel(Bd, a, np.arange(2, 4)))
    return {"As": As, "Bs": Bs, "Aa": Aa, "Ba": Ba, "Brs": Brs, "Bra": Bra}


def static_state(A, B, u0):
    """Static equilibrium state for constant input ``u0``: ``x = -A^{-1} B u0``.

    A : (n, m, m), B : (n, m, k), u0 : (k,) -> (n, m)
    """
    u0 = np.asarray(u0, dtype=float)
    if not np.any(u0):
        return np.zeros(A.shape[:2])
    return -np.linalg.solve(A, (B @ u0)[..., None])[..., 0]


def static_corner_loads(P, geom: Geometry, g: float = GRAVITY):
    """Static vertical tire loads (N) at fl, fr, rl, rr, shape (n, 4)."""
    p, n = _cols(P)
    b = geom.wheelbase - p["a"]
    front = p["m_s"] * g * b / geom.wheelbase / 2 + p["m_uf"] * g
    rear = p["m_s"] * g * p["a"] / geom.wheelbase / 2 + p["m_ur"] * g
    return np.stack([front, front, rear, rear], -1)


# ---------------------------------------------------------------------------
# Modal summary

MODES = ("bounce", "pitch", "roll", "front hop (in phase)", "rear hop (in phase)",
         "front hop (anti-phase)", "rear hop (anti-phase)")
#: The two more modes of a car with a powertrain on mounts (SPEC §11).
POWERTRAIN_MODES = ("powertrain bounce", "powertrain pitch")


def _block_modes(M, C, K, names_by_coord):
    """Undamped modes named by their dominant (kinetic-energy) coordinate,
    damped frequency/damping from the matching state-space eigenpair."""
    w2, V = scipy.linalg.eigh(K, M)
    A, _ = _state_space(M[None], C[None], K[None], np.zeros((1, M.shape[0], 1)))
    lam, W = np.linalg.eig(A[0])
    nq = M.shape[0]
    out = {}
    used = set()
    for j in np.argsort(w2):
        phi = V[:, j]
        energy = phi ** 2 * np.diag(M)
        name = names_by_coord(int(np.argmax(energy)), phi, used)
        used.add(name)
        wn = float(np.sqrt(max(w2[j], 0.0)))
        # match the damped eigenvector (position part) by MAC, weighted by M
        best, best_mac = None, 0.0
        for k in range(lam.size):
            if lam[k].imag <= 0:
                continue
            v = W[:nq, k]
            mac = abs(np.vdot(v, M @ phi)) ** 2 / (np.vdot(v, M @ v).real * (phi @ M @ phi))
            if mac > best_mac:
                best, best_mac = k, mac
        if best is not None and best_mac > 0.5:
            wd = abs(lam[best])
            zeta = -lam[best].real / wd
            fn = wd / (2 * np.pi)
        else:  # overdamped: undamped frequency, modal damping estimate
            fn = wn / (2 * np.pi)
            zeta = float(phi @ C @ phi / (2 * wn * (phi @ M @ phi))) if wn > 0 else np.inf
        out[name] = {"frequency_hz": float(fn), "damping_ratio": float(zeta),
                     "undamped_frequency_hz": wn / (2 * np.pi)}
    return out


def modal_summary(params, geom: Geometry) -> dict[str, dict[str, float]]:
    """Natural frequency (Hz) and damping ratio of the seven modes of one car (nine with a powertrain).

    Parameters
    ----------
    params : array_like, shape (12,), (16,) or (23,), or dict (absent extensions 0)
    geom : Geometry

    Returns
    -------
    dict
        mode name (:data:`MODES`, then :data:`POWERTRAIN_MODES` when the car
        has a powertrain) -> ``{"frequency_hz", "damping_ratio",
        "undamped_frequency_hz"}``. ``frequency_hz`` is the natural frequency
        ``|lambda|/2pi`` of the damped eigenvalue pair, ``damping_ratio``
        ``-Re(lambda)/|lambda|``; for an overdamped mode the undamped
        frequency and the modal damping estimate are given. The powertrain's
        modes are those of the whole car (body free), not the mounts' own
        ``f_pb``, ``f_pp`` (body held).
    """
    if isinstance(params, dict):
        params = [params.get(n, 0.0) if n not in NAMES else params[n] for n in ALL_NAMES]
    P = full_rows(np.asarray(params, dtype=float).reshape(1, -1))
    M, C, K, _ = decomposed_mck(P, geom)
    ns = M.shape[-1] - 3
    s, a = np.arange(ns), np.arange(ns, ns + 3)

    sym_modes = MODES[:2] + MODES[3:5] + (POWERTRAIN_MODES if ns == 6 else ())
    anti_modes = (MODES[2],) + MODES[5:]  # roll, front/rear hop anti-phase
    # dominant coordinate -> preferred names (bounce, pitch, front/rear hop in phase, powertrain bounce, pitch)
    sym_pref = {0: (0, 1), 1: (1, 0), 2: (2, 3), 3: (3, 2), 4: (4, 5), 5: (5, 4)}
    anti_pref = {0: (0,), 1: (1, 2), 2: (2, 1)}

    def namer(block, pref):
        # the dominant coordinate's names first, then any name of the block still free: two modes
        # dominated by the same coordinate (a light roll inertia beside heavy wheels) still get
        # distinct names, and every name of the block is given once
        def name(k, phi, used):
            for n in [block[i] for i in pref[k]] + list(block):
                if n not in used:
                    return n
            raise AssertionError("more modes than names")  # pragma: no cover - block sizes match
        return name

    sym_name, anti_name = namer(sym_modes, sym_pref), namer(anti_modes, anti_pref)

    res = {}
    res.update(_block_modes(M[0][np.ix_(s, s)], C[0][np.ix_(s, s)], K[0][np.ix_(s, s)], sym_name))
    res.update(_block_modes(M[0][np.ix_(a, a)], C[0][np.ix_(a, a)], K[0][np.ix_(a, a)], anti_name))
    return {m: res[m] for m in MODES + (POWERTRAIN_MODES if ns == 6 else ())}


def format_modal_summary(summary) -> str:
    lines = [f"{'mode':<24} {'f_n (Hz)':>9} {'zeta':>7}"]
    for m, v in summary.items():
        lines.append(f"{m:<24} {v['frequency_hz']:9.3f} {v['damping_ratio']:7.3f}")
    return "\n".join(lines)


__all__ = ["CHANNELS", "POWERTRAIN_COORDS", "POWERTRAIN_MODES", "n_coords",
           "mck", "output_map", "rate_input", "state_space", "blocks", "modal_summary",
           "static_corner_loads", "static_state", "INDEX"]
