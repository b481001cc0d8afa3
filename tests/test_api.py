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
