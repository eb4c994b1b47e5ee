"""What a process pays at its start: a log writer imports the file layout and the codec,
not the reader, export, replay or the link; the console script's entry point imports no
command group; checking a name against the analysis imports no scipy; a session whose
simulator is a child process imports no engine.  Each is checked in a fresh interpreter
(the modules a process has loaded, not a timing)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def _loaded_after(statement: str) -> set[str]:
    code = f"import sys, json\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout
    return set(json.loads(out.splitlines()[-1]))


def test_a_log_writer_imports_only_what_it_writes_with():
    loaded = _loaded_after("import groundstation.logs.writer")
    assert {"groundstation.logs.h5file", "groundstation.codec", "h5py"} <= loaded
    for heavy in ("groundstation.logs.reader", "groundstation.logs.export",
                  "groundstation.logs.replay", "groundstation.link", "scipy"):
        assert heavy not in loaded, heavy


def test_the_console_entry_point_imports_no_command_group():
    loaded = _loaded_after("from groundstation.cli.entry import main")
    assert not {m for m in loaded if m.startswith("groundstation.cli.") and m != "groundstation.cli.entry"}
    assert "numpy" not in loaded


def test_the_analysis_names_come_without_the_numerics():
    loaded = _loaded_after("from groundstation.analysis.names import SENSORS")
    assert "scipy" not in loaded and "h5py" not in loaded


@pytest.mark.parametrize("package, name, module", [
    ("groundstation.logs", "LogReader", "groundstation.logs.reader"),
    ("groundstation.logs", "Recorder", "groundstation.logs.recorder"),
    ("groundstation.analysis", "los_jitter", "groundstation.analysis.jitter"),
    ("groundstation.analysis", "SENSORS", "groundstation.analysis.names"),
])
def test_a_package_name_is_the_defining_modules_own(package, name, module):
    import importlib
    assert getattr(importlib.import_module(package), name) is getattr(importlib.import_module(module), name)


def test_an_unknown_name_is_an_attribute_error():
    import groundstation.logs
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        groundstation.logs.Nope


@pytest.mark.parametrize("package, name", [("groundstation.logs", "LogReader"),
                                           ("groundstation.analysis", "analyze_log")])
def test_dir_lists_a_name_before_its_first_use(package, name):
    code = (f"import sys, json, {package} as p\n"
            f"print(json.dumps([{name!r} in dir(p), {name!r} in vars(p)]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout
    assert json.loads(out.splitlines()[-1]) == [True, False]    # listed, not yet imported


def test_a_session_with_the_simulator_in_a_child_imports_no_engine():
    """`campaign run --fast`: the engine (numba, the plant's model) is the child's; the
    ground station's process imports the child's handle and the session only."""
    loaded = _loaded_after("from groundstation.sim.launch_ahead import launch_ahead\n"
                           "from groundstation.sim.stepped_process import SteppedSimulatorProcess\n"
                           "import groundstation.station.station, groundstation.campaign.runner")
    assert "groundstation.sim.stepped_process" in loaded
    for heavy in ("numba", "groundstation.sim.device", "groundstation.sim.engine"):
        assert heavy not in loaded, heavy


def test_the_simulators_names_still_come_from_the_package():
    loaded = _loaded_after("from groundstation.sim import SimulatedDevice, Firmware")
    assert {"groundstation.sim.device", "groundstation.sim.firmware", "numba"} <= loaded


def test_checking_a_campaign_imports_neither_scipy_signal_nor_scipy_linalg():
    """`campaign show` and the check before `campaign run`: a design is read and its
    factors checked, discretised only when uploaded; a base motion's held stage comes
    from the numerics cache once computed (the first check of inertial_bm fills it)."""
    _loaded_after("from groundstation.campaign import load_campaign\n"
                  "load_campaign('profiles/campaigns/inertial_bm.toml')")
    loaded = _loaded_after("from groundstation.campaign import load_campaign\n"
                           "load_campaign('profiles/campaigns/relative_steps.toml')\n"
                           "load_campaign('profiles/campaigns/inertial_bm.toml')")
    assert {"groundstation.params.design_file", "groundstation.basemotion.synthesis"} <= loaded
    for heavy in ("scipy.signal", "scipy.linalg"):
        assert heavy not in loaded, heavy


def test_a_fast_campaign_launches_its_simulator_before_importing_numpy():
    """`campaign run --fast`: the child's start (its imports and numba's cache, the longest
    thing before the first run) begins before the command imports numpy."""
    loaded = _loaded_after(
        "import groundstation.sim.launch_ahead as la, sys\n"
        "seen = []\n"
        "la.launch_ahead = lambda **kw: seen.append('numpy' in sys.modules)\n"
        "from groundstation.cli.campaign import _simulator_ahead\n"
        "import argparse\n"
        "_simulator_ahead(argparse.Namespace(resume=None, file='profiles/campaigns/relative_steps.toml',"
        " generator='auto'), {'fast': True})\n"
        "assert seen == [False], seen")
    assert "groundstation.sim.stepped_process" in loaded
