#!/bin/sh
# Run `make test` RUNS times in a row (default 3) with both cores saturated by a
# CPU-burning load beside it (stress-ng --cpu 4: two busy processes per core), the way a
# shared CI machine or a laptop compiling something else treats the suite.  Installs
# stress-ng when missing and root (Debian/Ubuntu).  Stops at the first failing run;
# prints one line per run with its status and wall time.  See docs/testing.md.
set -eu
RUNS="${RUNS:-3}"
CPU_LOAD="${CPU_LOAD:-4}"
if ! command -v stress-ng >/dev/null 2>&1; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "stressed-test: installing stress-ng"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends stress-ng >/dev/null
  else
    echo "stressed-test: stress-ng is missing: install it ('sudo apt-get install stress-ng')" >&2
    exit 2
  fi
fi
# stress-ng's own process stops its workers on SIGTERM.  (It used to run under setsid and
# be stopped as a process group: when setsid had to fork, $! was setsid's pid, not the
# group's, and a failed run left the load burning after the script had exited.)
stress-ng --cpu "$CPU_LOAD" --quiet &
LOAD_PID=$!
trap 'kill -TERM "$LOAD_PID" 2>/dev/null || true; wait "$LOAD_PID" 2>/dev/null || true' EXIT INT TERM
i=1
while [ "$i" -le "$RUNS" ]; do
  start=$(date +%s)
  if ${MAKE:-make} test; then status=passed; else status=FAILED; fi
  echo "stressed-test: run $i of $RUNS $status in $(( $(date +%s) - start )) s (load $(cut -d' ' -f1 /proc/loadavg))"
  [ "$status" = passed ] || exit 1
  i=$((i + 1))
done
