"""The HTML report: structure, figures, rebuild, and (slow) a real browser."""

import re
import shutil
import subprocess

import numpy as np
import pytest

from rideid.cli import main
from rideid.report.html import SECTIONS


@pytest.fixture(scope="module")
def fit_dir(sim_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("fit") / "fit"
    assert main(["identify", str(sim_dataset), "--out", str(out), "--seed", "1", "--quiet",
                 "--generations", "30"]) == 0
    return out


def _images(html):
    return re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)


def test_report_has_every_section_and_nonempty_figures(fit_dir):
    html = (fit_dir / "report.html").read_text()
    for s in SECTIONS:
        assert f'id="{s}"' in html, s
    assert 'id="dampers"' not in html and "<h2>Damper curves</h2>" not in html  # linear dampers: no curve section
    imgs = _images(html)
    # convergence, spread, weights, 10 fits, 3 maps, the uncertainty budget, the frequency responses
    assert len(imgs) == 18
    import base64
    import io

    import matplotlib.image as mpimg
    for b in imgs:
        arr = mpimg.imread(io.BytesIO(base64.b64decode(b)), format="png")
        assert arr.shape[0] > 150 and arr.shape[1] > 300
        assert arr[..., :3].std() > 0.05  # not a blank image
    for f in ("convergence", "spread", "weights", "fit_W_H", "param_track"):
        assert (fit_dir / "figures" / f"{f}.png").stat().st_size > 5000
    # the estimates table lists all twelve parameters, the anchor is stated
    for n in ("m_s", "I_xx", "k_tr"):
        assert f"<td>{n}</td>" in html
    assert "total_mass = 1093.3" in html
    assert "http://" not in html and "https://" not in html  # opens offline


def test_report_rebuild(fit_dir, capsys):
    """`rideid report` rebuilds from result.json + the dataset the same page identify wrote."""
    before = (fit_dir / "report.html").read_text()
    (fit_dir / "report.html").unlink()
    assert main(["report", str(fit_dir)]) == 0
    after = (fit_dir / "report.html").read_text()
    assert len(after) > 100_000
    assert "report written" in capsys.readouterr().out
    strip = lambda h: re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "IMG", h)  # noqa: E731
    assert strip(after) == strip(before)
    assert len(_images(after)) == len(_images(before)) == 18  # with the frequency responses


def test_report_relative_error_column_reads_plainly(fit_dir, tmp_path):
    """The estimates table's ± % column (of std_total, the first error column): three decimals below 100 %,
    whole percent above (an estimate near zero, such as tire damping of 0.6 N s/m with ±6 N s/m, reads 1000,
    not 1000.004)."""
    import json
    d = tmp_path / "fit"
    shutil.copytree(fit_dir, d)
    doc = json.loads((d / "result.json").read_text())
    doc["parameters"]["c_sf"]["std_total"] = 10.00004 * doc["parameters"]["c_sf"]["value"]
    doc["parameters"]["k_sf"]["std_total"] = 0.00123 * doc["parameters"]["k_sf"]["value"]
    (d / "result.json").write_text(json.dumps(doc))
    assert main(["report", str(d)]) == 0
    html = (d / "report.html").read_text()
    cells = {n: re.search(rf"<td>{n}</td>.*?</td>\s*<td>[^<]*</td><td>([^<]*)</td>", html, re.S).group(1)
             for n in ("c_sf", "k_sf")}
    assert cells == {"c_sf": "1000", "k_sf": "0.123"}


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_report_compares_adaptive_and_fixed(fit_dir, sim_dataset, tmp_path, capsys):
    fixed = tmp_path / "fixed"
    assert main(["identify", str(sim_dataset), "--out", str(fixed), "--seed", "1", "--quiet", "--generations", "20",
                 "--weights", "fixed", "--no-report"]) == 0
    assert not (fixed / "report.html").exists()
    assert main(["report", str(fit_dir), "--compare", str(fixed)]) == 0
    html = (fit_dir / "report.html").read_text()
    assert 'id="compare"' in html and "adaptive (this) vs fixed (fixed)" in html
    assert len(_images(html)) == 19  # the default report's 18 (frequency responses included) and the comparison
    assert (fit_dir / "figures" / "compare.png").stat().st_size > 5000
    # comparing with a folder that is not an identification is bad input
    assert main(["report", str(fit_dir), "--compare", str(tmp_path)]) == 2
    assert "result.json: not found" in capsys.readouterr().err


def test_report_bad_folder(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "result.json: not found" in capsys.readouterr().err


@pytest.mark.slow
def test_report_renders_in_headless_chromium(fit_dir, tmp_path):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("chromium not installed (make chromium)")
    shot = tmp_path / "shot.png"
    cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1300,2000", f"--screenshot={shot}",
           (fit_dir / "report.html").as_uri()]
    subprocess.run(cmd, capture_output=True, timeout=120)
    import matplotlib.image as mpimg
    img = mpimg.imread(shot)
    assert img.shape[0] >= 1000
    gray = img[..., :3].mean(axis=2)
    assert gray.std() > 0.05                    # not blank
    assert (gray < 0.5).mean() > 0.01           # text and plots drawn
    dark_rows = np.nonzero((gray < 0.5).mean(axis=1) > 0.002)[0]
    assert dark_rows.max() - dark_rows.min() > 800  # content down the page, not just the header


def test_figure_pool_returns_the_jobs_order(monkeypatch):
    """The pool draws the costliest figures first (heat maps, the spread) but hands every figure back in the
    order of its jobs, with the worker's own result (fork: the workers see these stand-ins)."""
    import os

    from rideid.report import html
    for name in ("fig_fit", "fig_heatmap", "fig_spread", "fig_weights"):
        monkeypatch.setattr(html, name, lambda k, name=name: (name, k, os.getpid()))
    jobs = [("fig_weights", (0,)), ("fig_fit", (1,)), ("fig_fit", (2,)), ("fig_heatmap", (3,)),
            ("fig_spread", (4,)), ("fig_heatmap", (5,))]
    out = html._map_figures(jobs)
    assert [(n, k) for n, k, _ in out] == [(n, a[0]) for n, a in jobs]
    if (os.cpu_count() or 1) > 1:
        assert all(pid != os.getpid() for _, _, pid in out)  # drawn in the workers


def test_report_opens_on_a_summary_and_its_correlation_table_fits_the_page(fit_dir, tmp_path):
    """A person reads the summary first (verdict, car, error bars, fit, data, each with a link) and jumps to
    the sections from it and from the bar; with damper curves (twenty knot forces more: a 36 x 36 matrix
    overflowed the page) the matrix holds the other parameters and the strongest pairs are listed, knots too;
    every wide table scrolls in its own box."""
    import json
    d = tmp_path / "fit"
    shutil.copytree(fit_dir, d)
    doc = json.loads((d / "result.json").read_text())
    names = [n for n in doc["correlation"]["names"]]
    names += [f"F_{a}{k}" for a in "fr" for k in range(1, 11)] + ["bs_clear_f", "bs_clear_r", "bs_rate_f", "bs_rate_r"]
    M = np.eye(len(names))
    pairs = {("F_f3", "F_f4"): 0.97, ("k_sf", "c_sf"): -0.85, ("F_r1", "bs_rate_r"): 0.5}
    for (a, b), r in pairs.items():
        M[names.index(a), names.index(b)] = M[names.index(b), names.index(a)] = r
    doc["correlation"] = {"names": names, "matrix": M.tolist(), "basis": "robust"}
    (d / "result.json").write_text(json.dumps(doc))
    assert main(["report", str(d)]) == 0
    html = (d / "report.html").read_text()
    matrix = re.search(r'<table class="small" id="correlation">(.*?)</table>', html, re.S).group(1)
    header = re.findall(r"<th>([^<]*)</th>", matrix.split("</tr>")[0])
    assert header == [""] + [n for n in names if not n.startswith("F_")] and len(header) - 1 <= 16
    listed = re.findall(r"<tr><td>([^<]*)</td><td[^>]*>([^<]*)</td><td[^>]*>([^<]*)</td></tr>",
                        re.search(r'id="correlation-pairs">(.*?)</table>', html, re.S).group(1))
    assert listed == [("F_f3", "F_f4", "+0.97"), ("k_sf", "c_sf", "-0.85")]  # strongest first; not |r| < 0.8
    assert "knot forces (20) are not\n in the matrix" in html
    # every table of more than six columns scrolls in its own box
    for m in re.finditer(r"(<div class=\"scroll\">\s*)?<table[^>]*>(.*?)</table>", html, re.S):
        cols = len(re.findall(r"<t[hd][ >]", m.group(2).split("</tr>")[0]))
        assert cols <= 6 or m.group(1), m.group(2)[:200]
    # the summary comes first, and every link of the bar and the summary lands on a section of the page
    assert html.index('<section id="summary">') < html.index('id="verdict"') < html.index('<section id="estimates">')
    ids = set(re.findall(r'id="([^"]+)"', html))
    links = re.findall(r'href="#([^"]+)"', html)
    assert {"estimates", "adequacy", "fits", "data", "maps"} <= set(links) and set(links) <= ids, set(links) - ids
    summary = re.search(r'<section id="summary">(.*?)</section>', html, re.S).group(1)
    rows = dict(re.findall(r"<tr><th>([^<]*)</th><td>([^<]*)<a", summary))
    # the built-in car rolls 2.3 degrees on the 80 mm twist: the small-angle note (SPEC §1) is in the summary
    assert set(rows) == {"Verdict", "Car", "Estimates", "Small angles", "Frequency responses", "Fit", "Data"}
    assert rows["Frequency responses"].startswith("±2 std of ") and "the measured H1 (" in rows["Frequency responses"]
    sa = doc["adequacy"]["small_angle"]
    assert sa["roll_run"] == "T_HL" and 2.0 < sa["largest_roll_deg"] < 2.6 and sa["optimistic"]
    assert f"rolls up to {sa['largest_roll_deg']:.1f} deg (T_HL)" in rows["Small angles"]
    assert rows["Verdict"].startswith("model adequate: ") and "total_mass = 1093.3" in rows["Car"]
    rel = {n: 200 * p["std_total"] / abs(p["value"]) for n, p in doc["parameters"].items()
           if not p.get("fixed") and not p.get("derived") and p.get("std_total")}
    lo, hi = min(rel, key=rel.get), max(rel, key=rel.get)
    # the error bars are ±2 std_total (SPEC §12); the total mass given as a plain number is said to be exact
    assert rows["Estimates"].strip() == (f"{len(rel)} estimated; ±2 std_total from {rel[lo]:.2g} % ({lo}) to "
                                         f"{rel[hi]:.2g} % ({hi}); TOTAL MASS TAKEN AS EXACT")
    assert rows["Fit"].startswith(f"cost {doc['cost']:.3g}; ") and rows["Data"].startswith("10 runs; ")
