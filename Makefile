# rideid: `make demo` runs the whole job on the built-in car, `make test` the test suite.
# Both create ./.venv and install the package with its dependencies first.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-slow bench verify venv clean chromium

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/rideid demo --out demo-out

# lint (ruff, configured in pyproject.toml), then the default suite on every core (pytest-xdist). Measured on a
# fresh clone of two otherwise idle cores: 10.9 minutes in all, 9.9 of them the tests (19.4 minutes of CPU time,
# user + sys), the rest making .venv; then 10.6 minutes (9.2 the tests) with three 33-57 s tests moved to CI's
# slow pass, and two of the three logger round trips (33-42 s each) after them; with the next wave's new default
# tests 12.8 minutes (11 the tests), then 8.7 minutes (7.1 the tests) with fifteen 17-48 s tests moved to CI's
# slow pass; 8.0 minutes (6.7 the tests, 751 of them, the powertrain on the compiled kernel); 9.9 minutes (8.2 the
# tests, 769) with the road fits' sensor tests, then 8.7 minutes (7.1 the tests, 763) with six 12-25 s tests moved
# to CI's slow pass; 9.5 minutes (7.8 the tests, 769) with the road fits' new coupling and roll-rate tests, then
# one 20 s test moved to CI's slow pass; 5.5 minutes (4.6 the tests, 1005 of them: the rig, frequency responses,
# both FMI interfaces, the settings registry, the priors and every group pair included) on a fresh clone of two
# idle cores; 5.2 minutes (4.3 the tests, 1029 of them: the problem's blocks, the model choice's screen, the road
# runs' verdict and the both-cores tests included) on a fresh clone, the cores otherwise idle; it takes longer when
# other jobs share the cores, and in the machine's slow hours (1107 tests: 6.9 minutes of them on 2026-12-01,
# 6.2 with the longest tests started first, docs/performance.md); 1113 tests on a fresh clone of two idle cores:
# 5:59, then 5:07 with each worker's rideid on one thread (tests/conftest.py) and the kernels compiled once
test: $(STAMP)
	$(PY) -m ruff check src tests benchmarks
	env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest -q -n auto

# the slow studies as well (JADE benchmark tables at full length, seeds sweeps)
test-slow: $(STAMP)
	RIDEID_SLOW=1 $(PY) -m pytest -q

# Debian's Chromium, for the slow test that renders report.html headless
chromium:
	command -v chromium >/dev/null 2>&1 || (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium)

bench: $(STAMP)
	$(PY) -m pip install --quiet -e '.[bench]'
	$(PY) benchmarks/run_all.py

# verification on the independent MuJoCo car (docs/verification.md): about 15 minutes (10 cars x 3 models), tables in bench-out/verify/
verify: $(STAMP)
	$(PY) benchmarks/verify_mujoco.py --out bench-out/verify

clean:
	rm -rf $(VENV) demo-out bench-out .pytest_cache
