# Set-up and the everyday jobs.  Each target does the whole set-up on a fresh machine:
# system libraries for Qt (apt-get, when root), the virtualenv, the package with extras.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: run test test-stressed bench setup clean firmware screenshots bytecode

setup: $(STAMP)

$(STAMP): pyproject.toml tools/system-deps.sh
	sh tools/system-deps.sh
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# the package's modules compiled once.  Every process of a session imports the package
# afresh - the command, the simulator's child, each log writer, each Dask worker - and
# where the environment sets PYTHONDONTWRITEBYTECODE (containers, CI images) Python
# never keeps what it compiled, so each of them compiled every module from source
# again: 0.13 s of a 1.4 s fast campaign (docs/campaigns.md, "Sixth round").
# compileall writes regardless, and skips what is up to date; a module edited since
# is compiled in memory, as it would be anyway.
bytecode: $(STAMP)
	$(PY) -m compileall -q groundstation

run: $(STAMP) bytecode
	$(VENV)/bin/groundstation run

test: $(STAMP) firmware bytecode
	QT_QPA_PLATFORM=offscreen $(PY) -m pytest -q

# the C reference device (firmware/reference_device/README.md): C99 on the exported kit
FW_DIR := firmware/reference_device
FW_BIN := $(FW_DIR)/build/hfb_reference_device
FW_SRC := $(wildcard $(FW_DIR)/src/*.c) $(FW_DIR)/kit/hfb_protocol.c
FW_HDR := $(wildcard $(FW_DIR)/src/*.h) $(FW_DIR)/kit/hfb_protocol.h
FW_CFLAGS := -std=c99 -Wall -Wextra -Werror -O2

firmware: $(FW_BIN)

$(FW_BIN): $(FW_SRC) $(FW_HDR)
	mkdir -p $(FW_DIR)/build
	gcc $(FW_CFLAGS) -I$(FW_DIR)/kit -o $@ $(FW_SRC) -lm

# the suite three times in a row beside a CPU-burning load (docs/testing.md)
test-stressed: $(STAMP) bytecode
	MAKE=$(MAKE) sh tools/stressed-test.sh

bench: $(STAMP) bytecode
	QT_QPA_PLATFORM=offscreen $(PY) benchmarks/run_all.py

# the window in each source, to docs/screenshots/ (tools/screenshots.py), on a virtual X
# server: xvfb installed when missing and root, as tools/system-deps.sh installs packages
screenshots: $(STAMP)
	@command -v xvfb-run >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" != "0" ]; then \
	    echo "screenshots: xvfb-run missing: run 'sudo apt-get install xvfb xauth'" >&2; exit 1; fi; \
	  echo "screenshots: installing xvfb xauth"; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  apt-get update -qq >/dev/null || echo "screenshots: apt-get update failed, trying the install anyway" >&2; \
	  apt-get install -y -qq --no-install-recommends xvfb xauth >/dev/null; }
	xvfb-run -a -s "-screen 0 1920x1080x24" $(PY) tools/screenshots.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis build *.egg-info
