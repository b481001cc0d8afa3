"""rideid study (SPEC §7): study files, the Dask engine, resuming, failures, an external scheduler.

One small Monte Carlo study (a three-run scenario at 50 Hz, tiny JADE) is
run once uninterrupted on a local cluster; the resumed, worker-killed and
external-scheduler runs must end with the same table, bit for bit (wall
times aside).
"""

import contextlib
import inspect
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.studies import load_study, local_cluster, parse_study
from rideid.studies.spec import dataset_content_hash, identify_accepts
from rideid.studies.task import TIMING_COLUMNS, run_task

pq = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("distributed")

RIDEID = [sys.executable, "-m", "rideid"]


def small_scenario(path: Path, runs=("T_HH", "H_HH", "W_H")):
    """The built-in car on three of its runs, sampled at 50 Hz (a task takes about a second)."""
    doc = tomllib.loads(rideid.default_scenario_path().read_text())
    doc["runs"] = [dict(r, fs=50.0) for r in doc["runs"] if r["id"] in runs]
    used = {r["track"] for r in doc["runs"]}
    doc["tracks"] = [t for t in doc["tracks"] if t["id"] in used]
    path.write_text(tomli_w.dumps(doc))
    return path


MC = """
name = "small Monte Carlo"
[data]
scenario = "small.toml"
noise = 0.01
noise_seeds = {{ first = 1, count = {n} }}
[identify]
population = 8
generations = 10
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("study")
    small_scenario(d / "small.toml")
    (d / "mc.toml").write_text(MC.format(n=4))
    return d


@pytest.fixture(scope="module")
def reference(folder):
    """The study run once, uninterrupted, on its own default 2-worker local cluster."""
    res = rideid.study(folder / "mc.toml", folder / "ref", n_workers=2)
    return res


@pytest.fixture(scope="module")
def cluster():
    """One more local cluster (2 workers) the other runs share, by its address (as --scheduler)."""
    c = local_cluster(2)
    yield c
    c.close()


def table(path):
    rows = pq.read_table(path).to_pylist()
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


# -- study files -----------------------------------------------------------

BAD = [
    ("colour = 1\n[data]\nscenario = 'builtin'\nnoise = 0.01\n", "unknown key 'colour' in the study file"),
    ("[data]\nscenario = 'builtin'\nnoise = 0.01\n[identify]\npopulaton = 8\n",
     "unknown key 'populaton' in [identify]"),
    ("[data]\nscenario = 'builtin'\nnoise = 0.01\ndatasets = ['x']\n", "either 'datasets'"),
    ("[data]\nscenario = 'builtin'\n", "[data] missing key 'noise'"),
    ("[data]\nscenario = 'builtin'\nnoise = 0.01\n[identify]\nweights = 'adaptiv'\n",
     "[identify] weights: expected \"adaptive\" or \"fixed\", got 'adaptiv'"),
    ("[data]\nscenario = 'builtin'\nnoise = 0.01\n[identify]\npopulation = [16, 2]\n",
     "[identify] population: must be at least 4, got 2"),
    ("[data]\nscenario = 'builtin'\nnoise = 0.01\nnoise_seeds = {first = 1}\n", "missing key 'count'"),
    ("[data]\nscenario = 'builtin'\nnoise = 0.01\n[subsets]\ntwist = ['T_HH', 'T_XX']\n",
     "[subsets] twist: unknown run 'T_XX'"),
    ("[data]\ndatasets = ['cars/*']\n", "'cars/*' matches no dataset folder"),
    ("[data]\ndatasets = ['car1']\nnoise = 0.01\n", "[data] noise: belongs to a scenario study"),
    ("[data]\nscenario = 'nowhere.toml'\nnoise = 0.01\n", "[data] scenario: scenario file not found"),
    ("[data\n", "invalid TOML"),
]


@pytest.mark.parametrize("text,msg", BAD, ids=[m for _, m in BAD])
def test_bad_study_file_is_named(tmp_path, text, msg):
    f = tmp_path / "s.toml"
    f.write_text(text)
    with pytest.raises(rideid.DataError) as e:
        load_study(f)
    assert str(e.value).startswith(str(f)) and msg in str(e.value)


def test_model_option_needs_an_identify_that_has_it(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("[data]\nscenario = 'builtin'\nnoise = 0.01\n[identify]\nmodel = 'base'\n")
    if identify_accepts("model"):
        assert load_study(f).tasks[0].options["identify"]["model"] == "base"
    else:
        with pytest.raises(rideid.DataError, match=r"\[identify\] model: this version of rideid.identify has no "
                                                   "model choice"):
            load_study(f)


def test_cli_bad_study_file_exits_2_and_writes_nothing(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("[data]\nscenario = 'builtin'\nnoise = 0.01\n[identify]\ngenerations = 0\n")
    p = subprocess.run(RIDEID + ["study", str(f), "--out", str(tmp_path / "out"), "--quiet"], capture_output=True,
                       text=True)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [f"rideid: error: {f} [identify] generations: must be at least 1, got 0"]
    assert not (tmp_path / "out").exists()


def test_cli_help_lists_study(capsys):
    from rideid.cli import main
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0 and "study" in capsys.readouterr().out


def test_unreachable_scheduler_is_bad_input_and_writes_nothing(folder, tmp_path, monkeypatch):
    from rideid.studies import engine
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", "1s")
    addr = f"tcp://127.0.0.1:{_free_port()}"
    with pytest.raises(rideid.ArgumentError, match=f"--scheduler {addr}: no Dask scheduler reachable there"):
        rideid.study(folder / "mc.toml", tmp_path / "out", scheduler=addr)
    assert not (tmp_path / "out").exists()


def test_tasks_are_the_product_of_the_axes_and_keyed_by_content(folder, tmp_path):
    doc = {"data": {"scenario": "small.toml", "noise": [0.0, 0.01], "noise_seeds": [1, 2, 3]},
           "identify": {"weights": ["fixed", "adaptive"], "seed": [1, 2]},
           "subsets": {"all": "all", "twist": ["T_HH"]}}
    st = parse_study(doc, base=folder)
    assert len(st.tasks) == 2 * 3 * 2 * 2 * 2
    assert len({t.key for t in st.tasks}) == len(st.tasks)
    first, last = st.tasks[0].options, st.tasks[-1].options
    assert first == {"data": {"scenario": "small.toml", "noise": 0.0, "noise_seed": 1}, "subset": "all",
                     "runs": None, "identify": {"weights": "fixed", "population": 32, "generations": 400,
                                                "polish": True, "seed": 1}}
    assert last["runs"] == ["T_HH"] and last["identify"]["seed"] == 2 and last["data"]["noise_seed"] == 3
    # the same study again: the same keys; the scenario file changed: new keys
    assert [t.key for t in parse_study(doc, base=folder).tasks] == [t.key for t in st.tasks]
    shutil.copytree(folder, tmp_path / "f", ignore=shutil.ignore_patterns("ref", "out*"))
    sc = tmp_path / "f" / "small.toml"
    sc.write_text(sc.read_text().replace("c_sf = 1786.0", "c_sf = 1790.0"))
    assert not {t.key for t in parse_study(doc, base=tmp_path / "f").tasks} & {t.key for t in st.tasks}


def test_dataset_hash_follows_the_run_files(tmp_path, folder):
    sc = rideid.load_scenario(folder / "small.toml")
    data, _ = rideid.simulate_manifest(sc, noise=0.0)
    rideid.write_dataset(sc, data, tmp_path / "ds")
    h = dataset_content_hash(tmp_path / "ds")
    (tmp_path / "ds" / "notes.txt").write_text("not part of the dataset")
    assert dataset_content_hash(tmp_path / "ds") == h
    f = tmp_path / "ds" / "runs" / "W_H.csv"
    f.write_text(f.read_text().replace(",0,", ",0.0,", 1) + "\n")
    assert dataset_content_hash(tmp_path / "ds") != h


def test_api_docstrings():
    for obj in (rideid.study, rideid.load_study):
        doc = inspect.getdoc(obj)
        for name in inspect.signature(obj).parameters:
            assert name in doc, f"{obj.__name__}: parameter '{name}' is not documented"


# -- running ---------------------------------------------------------------

@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_monte_carlo_on_a_local_cluster(folder, reference):
    assert (reference.tasks, reference.done, reference.failed, reference.computed) == (4, 4, 0, 4)
    rows = table(reference.results)
    assert [r["noise_seed"] for r in rows] == [1, 2, 3, 4]
    names = rideid.NAMES
    # a task gives the bits of the same identification done by hand, in this process
    sc = rideid.load_scenario(folder / "small.toml")
    rec = run_task(rideid.load_study(folder / "mc.toml").tasks[2].options, scenario=sc)
    assert all(rows[2][n] == rec["row"][n] for n in names)
    data, _ = rideid.simulate_manifest(sc, noise=0.01, seed=3)
    rideid.write_dataset(sc, data, folder / "by-hand")
    res = rideid.identify(rideid.load_dataset(folder / "by-hand"), seed=1, population=8, generations=10)
    assert all(rows[2][n] == res.parameters[n] for n in names)
    # 1 % noise on three runs: every estimate within 1 % of the truth, different seeds differ
    for n in names:
        assert max(abs(r[f"{n}_error"]) for r in rows) < 0.01
        assert rows[0][f"{n}_truth"] == sc.truth[n]
    assert len({r["k_sf"] for r in rows}) == 4
    assert all(r["k_sf_std"] > 0 for r in rows)
    out = folder / "ref"
    for f in ("summary.md", "summary.csv", "summary.html", "study.json", "figures/errors.png",
              "figures/spread.png", "figures/intervals.png"):
        assert (out / f).is_file(), f
    # the summary's spread is the sample std of the four k_sf estimates
    csv = (out / "summary.csv").read_text().splitlines()
    head = csv[0].split(",")
    ksf = next(ln.split(",") for ln in csv if ",k_sf," in ln)
    spread = float(ksf[head.index("spread")])
    assert spread == pytest.approx(np.std([r["k_sf"] for r in rows], ddof=1), rel=1e-3)
    # run again: nothing to compute, the same table
    again = rideid.study(folder / "mc.toml", out)
    assert again.computed == 0 and table(again.results) == rows


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_summary_takes_the_crlb_from_rideid_plan(folder, reference, monkeypatch):
    """The CRLB columns come from rideid.plan's plan.json layout (SPEC §7)."""
    from rideid.studies import summary

    calls = []

    def fake_plan(sc, noise):
        calls.append(([r.id for r in sc.runs], noise))
        return {"all_runs": {"crlb": {"k_sf": {"std": 5.0, "relative": 5.0 / 24445}},
                             "identify_std": {"k_sf": {"std": 6.0}},
                             "derived": {"m_s": {"std": 0.1, "std_identify": 0.2}}}}

    monkeypatch.setattr(summary, "plan", fake_plan)
    monkeypatch.setattr(summary, "_PLANS", {})
    spec = load_study(folder / "mc.toml")
    stats, notes = summary.group_stats(spec, pq.read_table(reference.results).to_pylist())
    by = {s["parameter"]: s for s in stats}
    assert calls == [(["T_HH", "H_HH", "W_H"], 0.01)]
    assert (by["k_sf"]["crlb_std"], by["k_sf"]["plan_identify_std"]) == (5.0, 6.0)
    assert (by["m_s"]["crlb_std"], by["m_s"]["plan_identify_std"]) == (0.1, 0.2)
    assert by["I_xx"]["crlb_std"] is None and "from rideid.plan" in notes[0]


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_resume_after_sigkill_recomputes_only_unfinished_tasks(folder, reference, cluster):
    out = folder / "out-killed"
    addr = cluster.scheduler_address
    p = subprocess.Popen(RIDEID + ["study", str(folder / "mc.toml"), "--out", str(out), "--quiet", "--scheduler", addr],
                         start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(list((out / "tasks").glob("*.json"))) < 1:
            assert p.poll() is None, "the study ended before it could be killed"
            time.sleep(0.02)
    finally:
        os.killpg(p.pid, signal.SIGKILL)  # the client (the slow test kills one with its local cluster)
        p.wait()
    finished = {f.stem for f in (out / "tasks").glob("*.json")}
    assert 1 <= len(finished) < 4
    assert not (out / "results.parquet").exists()
    mtimes = {f: f.stat().st_mtime_ns for f in (out / "tasks").glob("*.json")}
    res = rideid.study(folder / "mc.toml", out, scheduler=addr)
    assert res.computed == 4 - len(finished)
    assert all(f.stat().st_mtime_ns == m for f, m in mtimes.items())  # finished records untouched
    assert table(res.results) == table(reference.results)


@pytest.mark.slow  # 25-40 s: CI's slow pass runs it (make test stays under 10 minutes on 2 cores)
def test_worker_killed_mid_task(folder, reference, cluster):
    from distributed import Client

    spy = Client(cluster)
    killed = {}

    def progress(info):
        if info["done"] == 1 and not killed:
            busy = [w for w, ts in spy.processing().items() if ts]
            pids = spy.run(os.getpid)
            assert busy, "no task in flight to interrupt"
            for w in busy:
                os.kill(pids[w], signal.SIGKILL)
            killed.update({w: pids[w] for w in busy})

    try:
        res = rideid.study(folder / "mc.toml", folder / "out-worker", scheduler=cluster.scheduler_address,
                           progress=progress)
        assert killed
        assert (res.done, res.failed) == (4, 0)
        assert table(res.results) == table(reference.results)
    finally:
        spy.close()


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow  # 25-40 s: CI's slow pass runs it (make test stays under 10 minutes on 2 cores)
def test_external_scheduler_and_worker(folder, reference):
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    dask = [sys.executable, "-m", "dask"]
    procs = [subprocess.Popen(dask + ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    try:
        procs.append(subprocess.Popen(dask + ["worker", addr, "--nworkers", "2", "--nthreads", "1", "--no-dashboard",
                                              "--host", "127.0.0.1"], env=env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        out = folder / "out-remote"
        p = subprocess.run(RIDEID + ["study", str(folder / "mc.toml"), "--out", str(out), "--scheduler", addr],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        assert "4 tasks: 4 done, 0 failed (4 computed now" in p.stdout
        assert table(out / "results.parquet") == table(reference.results)
    finally:
        for q in reversed(procs):
            os.killpg(q.pid, signal.SIGTERM)
        for q in reversed(procs):
            try:
                q.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(q.pid, signal.SIGKILL)
                q.wait()


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_failing_task_is_recorded_and_the_others_finish(tmp_path, folder, cluster):
    sc = rideid.load_scenario(folder / "small.toml")
    data, _ = rideid.simulate_manifest(sc, noise=0.01, seed=7)
    for car in ("car1", "car2"):
        rideid.write_dataset(sc, data, tmp_path / "fleet" / car)
    bad = tmp_path / "fleet" / "car2" / "runs" / "H_HH.csv"
    lines = bad.read_text().splitlines()
    cells = lines[5].split(",")
    cells[1] = "nan"  # the first channel after time, line 6 of the file
    lines[5] = ",".join(cells)
    bad.write_text("\n".join(lines) + "\n")
    (tmp_path / "fleet.toml").write_text(
        "[data]\ndatasets = ['fleet/car*']\n[identify]\npopulation = 8\ngenerations = 10\n"
        "[subsets]\nall = 'all'\ntwist_washboard = ['T_HH', 'W_H']\n")
    addr = cluster.scheduler_address
    res = rideid.study(tmp_path / "fleet.toml", tmp_path / "out", scheduler=addr)
    rows = table(res.results)
    assert [(r["dataset"], r["subset"], r["status"]) for r in rows] == [
        ("fleet/car1", "all", "done"), ("fleet/car1", "twist_washboard", "done"),
        ("fleet/car2", "all", "failed"), ("fleet/car2", "twist_washboard", "failed")]
    assert rows[2]["error"] == f"{bad}: column 'body_az_fl' has a NaN or infinite value (line 6)"
    assert rows[1]["runs"] == "T_HH,W_H" and rows[1]["k_sf"] != rows[0]["k_sf"]
    # dataset folders carry their truth.toml: errors vs truth, here within 1 %
    assert max(abs(rows[0][f"{n}_error"]) for n in rideid.NAMES) < 0.01
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "## Failed tasks" in md and "has a NaN or infinite value" in md
    # a bad dataset's failure is final: resuming does not recompute it; fixing the file does
    assert rideid.study(tmp_path / "fleet.toml", tmp_path / "out", scheduler=addr).computed == 0
    rideid.write_dataset(sc, data, tmp_path / "fleet" / "car2")
    again = rideid.study(tmp_path / "fleet.toml", tmp_path / "out", scheduler=addr)
    assert again.computed == 2 and again.done == 4
    fixed = table(again.results)
    assert fixed[2]["k_sf"] == fixed[0]["k_sf"]  # the same data and options: the same bits


EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "studies"


@pytest.mark.parametrize("name", ["monte_carlo.toml", "track_subsets.toml", "weights.toml", "fleet.toml"])
def test_example_study_files_are_valid(name, tmp_path):
    f = tmp_path / name
    shutil.copy(EXAMPLES / name, f)
    if name == "fleet.toml":
        sc = rideid.default_scenario()
        for car in ("car-01", "car-02"):
            (tmp_path / "fleet" / car).mkdir(parents=True)
            rideid.write_dataset(sc, {r.id: (np.arange(3) / 200, np.zeros((3, 10))) for r in sc.runs},
                                 tmp_path / "fleet" / car)
    st = load_study(f)
    assert len(st.tasks) >= 2


@pytest.mark.slow
def test_forty_task_monte_carlo_killed_twice_and_resumed(tmp_path):
    """The issue's acceptance study: 40 tasks on the default local cluster, killed twice, resumed."""
    small_scenario(tmp_path / "small.toml")
    (tmp_path / "mc.toml").write_text(MC.format(n=40))
    out = tmp_path / "killed"
    for kill_at, how in ((8, "SIGINT"), (20, "SIGKILL")):
        p = subprocess.Popen(RIDEID + ["study", str(tmp_path / "mc.toml"), "--out", str(out), "--quiet"],
                             start_new_session=True, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 600
            while time.monotonic() < deadline and len(list((out / "tasks").glob("*.json"))) < kill_at:
                assert p.poll() is None
                time.sleep(0.05)
            if how == "SIGINT":  # Ctrl-C on a terminal (the whole process group): the client says how to resume
                os.killpg(p.pid, signal.SIGINT)
                assert p.wait(timeout=120) == 130
                assert "run the same command again to resume" in p.stderr.read()
        finally:
            with contextlib.suppress(ProcessLookupError):  # SIGKILL: the client and its local cluster's workers
                os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    before = len(list((out / "tasks").glob("*.json")))
    assert 20 <= before < 40
    p = subprocess.run(RIDEID + ["study", str(tmp_path / "mc.toml"), "--out", str(out)], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stderr
    assert f"40 tasks: 40 done, 0 failed ({40 - before} computed now, {before} from an earlier run)" in p.stdout
    ref = rideid.study(tmp_path / "mc.toml", tmp_path / "ref")
    assert ref.computed == 40
    assert table(out / "results.parquet") == table(ref.results)


def test_ctrl_c_while_waiting_is_a_flag_the_loop_turns_into_keyboard_interrupt():
    """SIGINT during the wait sets the flag (no exception where the main thread happens to be, e.g. inside a
    finaliser that would drop it); the loop over completions then raises KeyboardInterrupt before the next
    task, and the previous handler is back afterwards."""
    from rideid.studies import engine

    class Ready:  # a stand-in for distributed.as_completed: three finished futures
        def __init__(self):
            self.q = [1, 2, 3]

        def has_ready(self):
            return bool(self.q)

        def is_empty(self):
            return not self.q

        def __next__(self):
            return self.q.pop(0)

    before = signal.getsignal(signal.SIGINT)
    seen = []
    with pytest.raises(KeyboardInterrupt):
        with engine._interrupt_flag() as stop:
            for fut in engine._completions(Ready(), stop):
                seen.append(fut)
                if fut == 1:
                    os.kill(os.getpid(), signal.SIGINT)
                    assert stop.wait(5.0)
    assert seen == [1]
    assert signal.getsignal(signal.SIGINT) is before
    with engine._interrupt_flag() as stop:  # nothing pending: the loop ends
        assert list(engine._completions(Ready(), stop)) == [1, 2, 3]


def test_a_tasks_subset_keeps_its_runs_in_manifest_order_with_their_findings(sim_dataset):
    """A study task's subset (``Dataset.with_runs``): the runs named, in the manifest's order, their data and the
    load findings of those runs and of the dataset; an id the dataset lacks is one line naming the subset."""
    from dataclasses import replace

    from rideid.data.checks import Finding
    from rideid.errors import DataError

    ds = rideid.load_dataset(sim_dataset)
    ids = [r.id for r in ds.runs]
    found = (Finding("warning", "speed", "a", run=ids[0]), Finding("warning", "numbers", "b"),
             Finding("warning", "speed", "c", run=ids[2]))
    sub = replace(ds, findings=found).with_runs([ids[2], ids[0]], "subset 'two'")
    assert [r.id for r in sub.runs] == [ids[0], ids[2]] and set(sub.data) == {ids[0], ids[2]}
    assert [f.message for f in sub.findings] == ["a", "b", "c"]
    assert [f.message for f in replace(ds, findings=found).with_runs([ids[1]], "s").findings] == ["b"]
    with pytest.raises(DataError, match=rf"subset 'two': run 'X_X' is not in dataset .* \(its runs: {ids[0]}, "):
        ds.with_runs([ids[0], "X_X"], "subset 'two'")
