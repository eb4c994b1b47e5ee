# Set-up and the everyday jobs.  Each target does the whole set-up on a fresh machine:
# system libraries for Qt (apt-get, when root), the virtualenv, the package with extras.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: run test test-stressed bench setup clean

setup: $(STAMP)

$(STAMP): pyproject.toml tools/system-deps.sh
	sh tools/system-deps.sh
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/groundstation run

test: $(STAMP)
	QT_QPA_PLATFORM=offscreen $(PY) -m pytest -q

# the suite three times in a row beside a CPU-burning load (docs/testing.md)
test-stressed: $(STAMP)
	MAKE=$(MAKE) sh tools/stressed-test.sh

bench: $(STAMP)
	QT_QPA_PLATFORM=offscreen $(PY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis build *.egg-info
