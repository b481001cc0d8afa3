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

State ``x = [q, q']`` (14), ``x' = A x + B r + Br r'``. Outputs (SPEC channel
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

from .params import ALL_NAMES, GRAVITY, INDEX, NAMES, Geometry, full_rows

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


def _cols(P):
    P = full_rows(P)
    return {n: P[:, i] for i, n in enumerate(ALL_NAMES)}, P.shape[0]


def _corner_vectors(P, geom):
    """Rows ``e_i = [-G_i, unit_i]`` (n, 4, 7): ``d_i = e_i q`` is corner i's deflection
    (wheel minus body corner motion, both read off the output map)."""
    Om = output_map(P, geom)
    return Om[:, 4:] - Om[:, :4]


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


def mck(P, geom: Geometry):
    """Mass, damping, stiffness and input matrices for a batch.

    Parameters
    ----------
    P : array_like, shape (n, 12) or (n, 16)
        Parameter rows in :data:`rideid.model.params.NAMES` order, optionally
        followed by the extensions (:data:`rideid.model.params.EXT_NAMES`;
        absent means 0).
    geom : Geometry

    Returns
    -------
    M, C, K : ndarray, shape (n, 7, 7)
    Bf : ndarray, shape (n, 7, 4)
        Generalised force per unit road input (tire springs).
    """
    p, n = _cols(P)
    ks = np.stack([p["k_sf"], p["k_sf"], p["k_sr"], p["k_sr"]], -1)
    cs = np.stack([p["c_sf"], p["c_sf"], p["c_sr"], p["c_sr"]], -1)
    kt = np.stack([p["k_tf"], p["k_tf"], p["k_tr"], p["k_tr"]], -1)
    ct = np.stack([p["c_tf"], p["c_tf"], p["c_tr"], p["c_tr"]], -1)
    mu = np.stack([p["m_uf"], p["m_uf"], p["m_ur"], p["m_ur"]], -1)
    E = _corner_vectors(P, geom)
    K = np.einsum("nij,ni,nik->njk", E, ks, E)
    C = np.einsum("nij,ni,nik->njk", E, cs, E)
    # anti-roll bars: k_ar (e_i - e_j)(e_i - e_j)^T per axle
    for (i, j), kar in (((0, 1), p["k_arf"]), ((2, 3), p["k_arr"])):
        De = E[:, i] - E[:, j]
        K += kar[:, None, None] * De[:, :, None] * De[:, None, :]
    K[:, 3 + np.arange(4), 3 + np.arange(4)] += kt
    C[:, 3 + np.arange(4), 3 + np.arange(4)] += ct
    M = np.zeros((n, 7, 7))
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
    Bf = np.zeros((n, 7, 4))
    Bf[:, 3 + np.arange(4), np.arange(4)] = kt
    return M, C, K, Bf


def rate_input(P, geom: Geometry):
    """Generalised force per unit road-input rate (tire dampers), shape (n, 7, 4).

    Zero without tire damping.
    """
    p, n = _cols(P)
    Bd = np.zeros((n, 7, 4))
    ct = np.stack([p["c_tf"], p["c_tf"], p["c_tr"], p["c_tr"]], -1)
    Bd[:, 3 + np.arange(4), np.arange(4)] = ct
    return Bd


def _state_space(M, C, K, Bf):
    nq = M.shape[-1]
    Minv = np.linalg.inv(M)
    n = M.shape[0]
    A = np.zeros((n, 2 * nq, 2 * nq))
    A[:, :nq, nq:] = np.eye(nq)
    A[:, nq:, :nq] = -Minv @ K
    A[:, nq:, nq:] = -Minv @ C
    B = np.zeros((n, 2 * nq, Bf.shape[-1]))
    B[:, nq:, :] = Minv @ Bf
    return A, B


def _output_rows(acc, Om):
    """Ten channels' rows from generalised-acceleration rows ``acc`` (n, 7, k); gyro rows left 0."""
    out = np.zeros((acc.shape[0], 10, acc.shape[-1]))
    out[:, :8] = Om @ acc
    return out


def state_space(P, geom: Geometry, rate: bool = False):
    """Full 14-state model with the ten SPEC output channels.

    ``x' = A x + B r + Br r'``, ``y = Cy x + Dy r + Dyr r'``.

    Returns
    -------
    A : (n, 14, 14), B : (n, 14, 4), Cy : (n, 10, 14), Dy : (n, 10, 4)
        and, with ``rate``, also ``Br : (n, 14, 4)``, ``Dyr : (n, 10, 4)``
        (zero without tire damping).
    """
    M, C, K, Bf = mck(P, geom)
    A, B = _state_space(M, C, K, Bf)
    p, n = _cols(P)
    Om = output_map(P, geom)
    Cy = _output_rows(A[:, 7:, :], Om)
    Dy = _output_rows(B[:, 7:, :], Om)
    for c, k in RATE_COORDS.items():
        Cy[:, CHANNELS.index(c), 7 + k] = 1.0
    if not rate:
        return A, B, Cy, Dy
    _, Br = _state_space(M, C, K, rate_input(P, geom))
    Dyr = _output_rows(Br[:, 7:, :], Om)
    return A, B, Cy, Dy, Br, Dyr


def decomposed_mck(P, geom: Geometry, rate: bool = False):
    """``M, C, K, Bf`` (and with ``rate`` also ``Bd``) in the symmetric/antisymmetric coordinates.

    Exact congruence ``T^T M T`` etc.; the off-diagonal blocks vanish
    because left and right share parameters (tested). The anti-roll bars
    enter only the antisymmetric block.
    """
    M, C, K, Bf = mck(P, geom)
    T = _T
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
      ``[z, theta, zf_s, zr_s, rates]``, inputs ``[rf_s, rr_s]`` and their rates;
      ``Aa`` (n, 6, 6), ``Ba`` (n, 6, 2), ``Bra`` (n, 6, 2): states
      ``[phi, zf_a, zr_a, rates]``, inputs ``[rf_a, rr_a]`` and their rates.
      ``x' = A x + B u + Br u'``; ``Br`` is zero without tire damping.
    """
    M, C, K, Bf, Bd = decomposed_mck(P, geom, rate=True)
    s, a = np.arange(4), np.arange(4, 7)
    sel = lambda X, r, c: X[:, r][:, :, c]  # noqa: E731
    As, Bs = _state_space(sel(M, s, s), sel(C, s, s), sel(K, s, s), sel(Bf, s, np.arange(2)))
    Aa, Ba = _state_space(sel(M, a, a), sel(C, a, a), sel(K, a, a), sel(Bf, a, np.arange(2, 4)))
    _, Brs = _state_space(sel(M, s, s), sel(C, s, s), sel(K, s, s), sel(Bd, s, np.arange(2)))
    _, Bra = _state_space(sel(M, a, a), sel(C, a, a), sel(K, a, a), sel(Bd, a, np.arange(2, 4)))
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
    """Natural frequency (Hz) and damping ratio of the seven modes of one car.

    Parameters
    ----------
    params : array_like, shape (12,) or (16,), or dict (absent extensions 0)
    geom : Geometry

    Returns
    -------
    dict
        mode name (:data:`MODES`) -> ``{"frequency_hz", "damping_ratio",
        "undamped_frequency_hz"}``. ``frequency_hz`` is the natural frequency
        ``|lambda|/2pi`` of the damped eigenvalue pair, ``damping_ratio``
        ``-Re(lambda)/|lambda|``; for an overdamped mode the undamped
        frequency and the modal damping estimate are given.
    """
    if isinstance(params, dict):
        params = [params.get(n, 0.0) if n not in NAMES else params[n] for n in ALL_NAMES]
    P = full_rows(np.asarray(params, dtype=float).reshape(1, -1))
    M, C, K, _ = decomposed_mck(P, geom)
    s, a = np.arange(4), np.arange(4, 7)

    sym_modes = MODES[:2] + MODES[3:5]  # bounce, pitch, front/rear hop in phase
    anti_modes = (MODES[2],) + MODES[5:]  # roll, front/rear hop anti-phase
    sym_pref = {0: (0, 1), 1: (1, 0), 2: (2, 3), 3: (3, 2)}  # dominant coordinate -> preferred names
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
    return {m: res[m] for m in MODES}


def format_modal_summary(summary) -> str:
    lines = [f"{'mode':<24} {'f_n (Hz)':>9} {'zeta':>7}"]
    for m, v in summary.items():
        lines.append(f"{m:<24} {v['frequency_hz']:9.3f} {v['damping_ratio']:7.3f}")
    return "\n".join(lines)


__all__ = ["CHANNELS", "mck", "output_map", "rate_input", "state_space", "blocks", "modal_summary",
           "static_corner_loads", "static_state", "INDEX"]
