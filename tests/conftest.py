import os

# Two test workers share two cores, and rideid fits with BLAS on one thread (rideid.model.batch.single_threaded_blas
# around identify, a study's tasks, the model choice): tests that call its parts directly get the same, and so do
# the command lines they start (OpenBLAS's threads spin on small matrices: a road fit's Cholesky factor took 9 ms
# on two threads, 0.2 ms on one).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

threadpool_limits(limits=1, user_api="blas")

if os.environ.get("PYTEST_XDIST_WORKER"):
    # Two workers fill both cores: each one's rideid on one thread, the work rideid spreads over the kernel's
    # threads (rideid.model.batch.thread_map, the kernels' chunks) one after the other in the worker's own thread
    # (Numba's thread count is the calling thread's, so nothing is started). Side by side, the threads took turns
    # with the other worker: the suite took 5:43 on two idle cores, 4:49 on one thread each (docs/performance.md).
    # The tests of the threads themselves take both cores back (the ``both_cores`` fixture).
    import numba

    numba.set_num_threads(1)


@pytest.fixture
def both_cores():
    """The kernel's thread count in this thread as on a user's two cores (the test workers run on one: above)."""
    import numba

    from rideid.model.backend import kernel_threads
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: nothing runs side by side")
    with kernel_threads(2):
        yield numba.get_num_threads()


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run slow studies")


_WARMING = []


def pytest_configure(config):
    # with workers (pytest -n): compile the Numba kernels once into their caches while the workers collect, rather
    # than in every worker (tests/warm_kernels.py; on a fresh clone 17 s of compiling per worker otherwise)
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    import subprocess
    import sys
    from pathlib import Path
    script = str(Path(__file__).with_name("warm_kernels.py"))
    for names in (["nonlinear"], ["linear", "contact", "simulator"]):
        _WARMING.append(subprocess.Popen([sys.executable, script, *names], stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL))


def pytest_unconfigure(config):
    while _WARMING:
        proc = _WARMING.pop()
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def pytest_collection_modifyitems(config, items):
    # the longest tests of the default run first (marked heavy, each the only user of its module's fixtures): the
    # workers take the tests in this order, and one begun last kept its worker busy while the other had finished
    # (the two workers' sums of test time were 377 and 352 s)
    items.sort(key=lambda item: "heavy" not in item.keywords)
    if config.getoption("--runslow") or os.environ.get("RIDEID_SLOW"):
        return
    skip = pytest.mark.skip(reason="slow study: make test-slow (or RIDEID_SLOW=1) runs it")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def default_scenario():
    import rideid
    return rideid.default_scenario()


@pytest.fixture(scope="session")
def sim_dataset(tmp_path_factory, default_scenario):
    """The built-in scenario simulated noise-free, written as a dataset."""
    import warnings

    from rideid.synth.scenario import simulate_manifest, write_dataset
    out = tmp_path_factory.mktemp("ds") / "clean"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the built-in runs must not lift a wheel
        data, lifts = simulate_manifest(default_scenario, noise=0.0, seed=1)
    assert lifts == []
    write_dataset(default_scenario, data, out)
    return out


#: a 2.45 t van: other geometry, rates and tire radius than the built-in car
VAN_VEHICLE = {"wheelbase": 3.3, "track_front": 1.70, "track_rear": 1.68, "tire_radius": 0.35}
VAN_TRUTH = {"m_s": 2200.0, "I_xx": 900.0, "I_yy": 4500.0, "a": 1.6, "m_uf": 55.0, "m_ur": 70.0,
             "k_sf": 45000.0, "k_sr": 60000.0, "c_sf": 3500.0, "c_sr": 4000.0, "k_tf": 280000.0, "k_tr": 300000.0}


def van_scenario(folder):
    """The built-in tracks and runs with the van as truth, written to ``folder/van.toml`` and loaded."""
    import tomllib

    import tomli_w

    import rideid
    doc = tomllib.loads(rideid.default_scenario_path().read_text())
    doc["name"] = "van"
    doc["vehicle"] = dict(VAN_VEHICLE)
    doc["known"] = {"total_mass": 2450.0}
    doc["truth"] = dict(VAN_TRUTH)
    (folder / "van.toml").write_text(tomli_w.dumps(doc))
    return rideid.load_scenario(folder / "van.toml")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
