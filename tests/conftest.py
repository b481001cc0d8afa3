import os

import numpy as np
import pytest


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run slow studies")


def pytest_collection_modifyitems(config, items):
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

    from rideid.scenario import simulate_manifest, write_dataset
    out = tmp_path_factory.mktemp("ds") / "clean"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the built-in runs must not lift a wheel
        data, lifts = simulate_manifest(default_scenario, noise=0.0, seed=1)
    assert lifts == []
    write_dataset(default_scenario, data, out)
    return out


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
