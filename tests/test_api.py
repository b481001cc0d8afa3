"""The public namespace (SPEC §5) and its documentation."""

import inspect

import pytest

import rideid

DOCUMENTED = [rideid.identify, rideid.jade, rideid.load_dataset, rideid.CostFunction, rideid.JadeSolver,
              rideid.modal_summary, rideid.iso8608_profile, rideid.iso8608_class]


def test_spec_entry_points_exist():
    for name in ("load_dataset", "identify", "CostFunction", "jade"):
        assert callable(getattr(rideid, name))
    assert issubclass(rideid.DataError, ValueError)
    assert issubclass(rideid.ScaleError, rideid.DataError)


@pytest.mark.parametrize("obj", DOCUMENTED, ids=lambda o: o.__name__)
def test_every_parameter_is_documented(obj):
    doc = inspect.getdoc(obj) or ""
    assert "Parameters" in doc, f"{obj.__name__} has no Parameters section"
    target = obj.__init__ if inspect.isclass(obj) else obj
    for name, p in inspect.signature(target).parameters.items():
        if name in ("self",) or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        assert name in doc, f"{obj.__name__}: parameter '{name}' is not documented"


def test_dataset_repr_is_short(sim_dataset):
    ds = rideid.load_dataset(sim_dataset)
    text = repr(ds)
    assert len(text) < 1000, len(text)
    assert f"name={ds.name!r}" in text and str(ds.path) in text
    assert f"runs={len(ds.runs)} [{ds.runs[0].id}, {ds.runs[1].id}" in text
    assert "tracks=[" in text and "'total_mass': 1093.3" in text and "model=none" in text


def test_identify_is_its_own_function():
    """rideid.identify documents and checks its own signature (not the single-model fit's borrowed one)."""
    from rideid.estimate.fit import identify as single

    assert rideid.identify is not single.identify and not hasattr(rideid.identify, "__wrapped__")
    params = inspect.signature(rideid.identify).parameters
    assert "model" in params and "simulator" in params
    assert list(params)[0] == "ds" and all(p.kind == p.KEYWORD_ONLY for n, p in params.items() if n != "ds")
    assert "rideid identify" in inspect.getdoc(rideid.identify)
