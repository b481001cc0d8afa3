"""ISO 8608 random roads: the spectra and classes of the standard, the left/right coherency model,
the generator against both (averaged over seeds, within sampling error) and the classifier."""

import math

import numpy as np
import pytest
from scipy import integrate, signal, special

from rideid.errors import ArgumentError
from rideid.model.roads import (ISO_BAND, N0, ROAD_CLASSES, class_gd, class_of, fit_band, iso8608_class, iso8608_fit,
                                iso8608_profile, iso8608_psd, road_coherency)

B = 1.6  # track width, m


def test_class_table_is_the_standards():
    # ISO 8608 Table: geometric means of Gd(n0) at n0 = 0.1 cycles/m, 1e-6 m^3
    assert N0 == 0.1 and ISO_BAND == (0.011, 2.83)
    assert {c: round(g * 1e6) for c, g in ROAD_CLASSES.items() if c in "ABCDE"} == \
        {"A": 16, "B": 64, "C": 256, "D": 1024, "E": 4096}
    assert class_gd("c") == 256e-6 and class_gd(1e-4) == 1e-4
    # boundaries at the geometric means between neighbours: a factor 2 either side
    for c, g in ROAD_CLASSES.items():
        assert class_of(g) == c and class_of(g * 1.999) == c
        if c != "A":
            assert class_of(g / 2) == c and class_of(g / 2.001) == chr(ord(c) - 1)
    assert class_of(0.0) == "A" and class_of(1.0) == "H"
    assert iso8608_psd(0.2, "B") == pytest.approx(64e-6 / 4)  # (n/n0)^-2
    assert iso8608_psd(0.2, "B", waviness=3) == pytest.approx(64e-6 / 8)


def test_coherency_closed_forms_and_limits():
    n = np.linspace(0.0, 3.0, 61)
    z = 2 * np.pi * n[1:] * B
    # w = 2: rho = z K1(z) (Dodds and Robson); w = 1: rho = exp(-z) (K_1/2 in closed form)
    assert np.allclose(road_coherency(n[1:], B), z * special.k1(z), rtol=1e-10, atol=1e-300)
    assert np.allclose(road_coherency(n[1:], B, waviness=1.0), np.exp(-z), rtol=1e-10, atol=1e-300)
    # the stretch a enters only as B / a
    assert np.allclose(road_coherency(n, B, coherence=2.0), road_coherency(n, B / 2.0))
    assert np.all(road_coherency(n, B, coherence=math.inf) == 1.0)
    assert np.all(road_coherency(n[1:], B, coherence=0.0) == 0.0)
    assert road_coherency(0.0, B) == 1.0
    r = road_coherency(n, B)
    assert np.all(np.diff(r) <= 0) and r[-1] < 1e-10


@pytest.mark.parametrize("w", [1.5, 2.0, 2.6])
def test_coherency_is_the_isotropic_surface_integral(w):
    # independent method: integrate the isotropic 2-D spectrum S2(k) ~ k^-(w+1) along the lateral wavenumber m,
    # cross-spectrum of two lines B apart over the spectrum of one (quad with a cosine weight, to infinity)
    for n in (0.02, 0.1, 0.3):
        def s2(m, n=n):
            return (n * n + m * m) ** (-(w + 1) / 2)
        cross = integrate.quad(s2, 0, np.inf, weight="cos", wvar=2 * np.pi * B, limlst=200)[0]
        auto = integrate.quad(s2, 0, np.inf)[0]
        assert road_coherency(n, B, waviness=w) == pytest.approx(cross / auto, rel=1e-6)


def test_same_seed_same_road():
    a = iso8608_profile("B", 200.0, np.random.default_rng(7), track_width=B)
    b = iso8608_profile("B", 200.0, np.random.default_rng(7), track_width=B)
    c = iso8608_profile("B", 200.0, np.random.default_rng(8), track_width=B)
    for u, v in zip(a, b):
        assert np.array_equal(u, v)
    assert not np.array_equal(a[1], c[1])
    x = a[0]
    assert x[0] == 0.0 and x[-1] == pytest.approx(200.0) and np.allclose(np.diff(x), 0.05)
    x2 = iso8608_profile("B", 10.0, np.random.default_rng(7), x0=-3.0, dx=0.1)[0]
    assert x2[0] == -3.0 and x2.size == 101


def _octaves(lo, hi):
    edges = lo * 2.0 ** np.arange(0, int(np.log2(hi / lo)) + 1)
    return list(zip(edges[:-1], edges[1:]))


@pytest.mark.parametrize("road_class, w", [("B", 2.0), ("D", 2.5)])
def test_each_path_has_the_iso_spectrum(road_class, w):
    # Welch estimate of each path over seeds; per octave band the mean of PSD / Gd(n) is 1 within 4 standard
    # errors of the seeds' scatter (plus 3 % for the Hann window's leakage on a steep spectrum)
    dx, seeds = 0.05, range(8)
    ratios = []
    for s in seeds:
        x, zl, zr = iso8608_profile(road_class, 2000.0, np.random.default_rng(s), track_width=B, waviness=w)
        f, P = signal.welch(np.c_[zl, zr], fs=1 / dx, nperseg=2 ** 13, axis=0)
        ratio = P / iso8608_psd(np.maximum(f, 1e-9), road_class, w)[:, None]
        ratios.append([[ratio[(f >= a) & (f < b), j].mean() for a, b in _octaves(0.02, 2.56)] for j in (0, 1)])
    R = np.array(ratios)  # (seed, path, band)
    mean, sem = R.mean(axis=0), R.std(axis=0, ddof=1) / np.sqrt(len(seeds))
    assert np.all(np.abs(mean - 1) <= 4 * sem + 0.03), (mean, sem)
    # and no power outside the band (above 2.83 cycles/m)
    assert np.all(P[f > 3.0] < 1e-6 * iso8608_psd(3.0, road_class, w))


@pytest.mark.parametrize("a", [1.0, 3.0])
def test_left_right_coherence_is_the_model(a):
    # scipy's (squared) coherence over 150 segments: bias (1 - g^2)^2 / K below 0.007; mean over seeds within
    # 4 standard errors (plus 0.01 for that bias) of rho(n)^2
    dx = 0.05
    C = []
    for s in range(6):
        x, zl, zr = iso8608_profile("C", 4000.0, np.random.default_rng(100 + s), track_width=B, coherence=a)
        f, c = signal.coherence(zl, zr, fs=1 / dx, nperseg=1024)
        C.append(c)
    C = np.array(C)
    sel = (f >= 0.04) & (f <= 1.5)
    model = road_coherency(f[sel], B, coherence=a) ** 2
    mean, sem = C[:, sel].mean(axis=0), C[:, sel].std(axis=0, ddof=1) / np.sqrt(C.shape[0])
    assert np.all(np.abs(mean - model) <= 4 * sem + 0.01), np.c_[f[sel], mean, model][:20]
    assert model.max() > 0.5 and model.min() < 0.01  # the band spans coherent and incoherent wavelengths


def test_identical_and_independent_paths():
    x, zl, zr = iso8608_profile("B", 300.0, np.random.default_rng(1), coherence=math.inf)
    assert np.array_equal(zl, zr)
    x, zl, zr = iso8608_profile("B", 4000.0, np.random.default_rng(1), coherence=0.0)
    f, c = signal.coherence(zl, zr, fs=20.0, nperseg=1024)
    assert c[(f > 0.04) & (f < 2.5)].mean() < 0.02


@pytest.mark.parametrize("road_class", list("ABCDE"))
def test_generated_roads_classify_as_their_class(road_class):
    for s in range(4):
        x, zl, zr = iso8608_profile(road_class, 500.0, np.random.default_rng(s), track_width=B)
        assert iso8608_class(x, zl)[0] == road_class
        c, gd = iso8608_class(x, np.c_[zl, zr])
        assert c == road_class and 0.6 < gd / ROAD_CLASSES[road_class] < 1.6


def test_fit_is_unbiased_over_seeds_and_honours_the_waviness():
    g = [iso8608_fit(*_xz(s, w=2.5), waviness=2.5) for s in range(10)]
    assert np.mean(g) / ROAD_CLASSES["C"] == pytest.approx(1.0, abs=3 * np.std(g) / np.sqrt(10) / ROAD_CLASSES["C"])


def _xz(seed, w):
    x, zl, _ = iso8608_profile("C", 800.0, np.random.default_rng(seed), waviness=w)
    return x, zl


def test_sinusoid_gives_the_closed_form_gd():
    # A cos(2 pi n1 x + p) on a spectral line: Gd(n0) = A^2 n1 / (2 n0^2 S), S = sum over the band's lines of dn/n_k
    dx, L, A = 0.05, 1000.0, 0.01
    x = dx * np.arange(int(L / dx))
    lo, hi = fit_band(x.size * dx, dx)
    assert (lo, hi) == (0.011, 2.83)
    nk = np.fft.rfftfreq(x.size, dx)
    S = np.sum(1.0 / nk[(nk >= lo) & (nk <= hi)]) * (nk[1] - nk[0])
    assert S == pytest.approx(math.log(hi / lo), rel=0.01)
    for n1 in (0.05, 0.5, 2.0):
        z = A * np.cos(2 * np.pi * n1 * x + 0.3)
        expect = A * A * n1 / (2 * N0 ** 2 * S)
        c, gd = iso8608_class(x, z)
        assert gd == pytest.approx(expect, rel=1e-9)
        assert c == class_of(expect)
    # outside the band: nothing
    assert iso8608_fit(x, A * np.cos(2 * np.pi * 4.0 * x)) < 1e-12


def test_short_record_fit_band_and_bad_input():
    assert fit_band(100.0, 0.05) == (0.04, 2.83)
    assert fit_band(1000.0, 0.2) == (0.011, 1.25)
    with pytest.raises(ArgumentError, match="too short or too coarse"):
        fit_band(1.0, 0.05)
    with pytest.raises(ArgumentError, match="unknown ISO 8608 road class 'Z'"):
        iso8608_profile("Z", 10.0, np.random.default_rng(1))
    with pytest.raises(ArgumentError, match="take dx below"):
        iso8608_profile("A", 10.0, np.random.default_rng(1), dx=0.2)
    with pytest.raises(ArgumentError, match="numpy.random.Generator"):
        iso8608_profile("A", 10.0, 1)
    with pytest.raises(ArgumentError, match="coherence must be"):
        road_coherency(0.1, B, coherence=-1.0)
    with pytest.raises(ArgumentError, match="uniform"):
        iso8608_class(np.r_[0.0, np.cumsum(np.random.default_rng(1).uniform(0.04, 0.06, 99))], np.zeros(100))
