"""One BLAS thread in the ground station's processes unless the user chose otherwise:
BLAS threads spinning between the small matrix calls took a core from the simulator
and the receiver (core/blas_threads.py).  Checked in fresh processes: the variables
only count before numpy loads."""

from __future__ import annotations

import os
import subprocess
import sys

from groundstation.core.blas_threads import BLAS_THREAD_VARIABLES, one_blas_thread


def _env_without_blas_settings(**extra) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    return {**env, **extra}


def test_a_value_the_user_set_stands():
    env = {"OMP_NUM_THREADS": "4"}
    one_blas_thread(env)
    assert env == {"OMP_NUM_THREADS": "4", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def test_the_command_line_sets_one_thread_before_numpy_loads():
    code = ("import os, sys\n"
            "from groundstation.cli.entry import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(os.environ.get('OPENBLAS_NUM_THREADS'), os.environ.get('OMP_NUM_THREADS'),\n"
            "      file=sys.stderr)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env=_env_without_blas_settings(OMP_NUM_THREADS="3"), check=True)
    assert out.stderr.split()[-2:] == ["1", "3"]


def test_the_simulators_child_gets_one_thread_from_a_script_that_set_none(monkeypatch):
    from groundstation.sim.stepped_process import _child_environment

    for name in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    env = _child_environment()
    assert all(env[name] == "1" for name in BLAS_THREAD_VARIABLES)
    assert all(name not in os.environ for name in BLAS_THREAD_VARIABLES)   # ours untouched
