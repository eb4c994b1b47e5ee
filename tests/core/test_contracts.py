"""The contracts (groundstation/core/contracts.py) hold for their implementations: the live
link and the log replay are both telemetry sources, the link is a command channel, the
4050 driver is the base-motion instrument - by member and by call signature."""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest

from groundstation.core.contracts import (BaseMotionInstrument, CommandChannel, DeviceLink,
                                          TelemetrySource)
from groundstation.fanout.viewer import WatchClient
from groundstation.instruments.fg4050 import FunctionGenerator4050
from groundstation.link.client import DeviceClient
from groundstation.logs.replay import ReplaySource
from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]
INERTIAL = ROOT / "profiles" / "testbeds" / "inertial_2dof.toml"


def protocol_methods(protocol) -> list[str]:
    """The contract's methods, its own and those of the contracts it is made of."""
    names = []
    for part in protocol.__mro__:
        if part.__module__ != protocol.__module__:
            continue                       # Protocol, Generic, object
        names += [name for name, value in vars(part).items()
                  if callable(value) and not name.startswith("_") and name not in names]
    return names


def signature_problems(protocol, cls) -> list[str]:
    """Each contract method exists on `cls` and accepts every call the contract allows:
    the same parameters by name and kind, anything extra with a default."""
    out = []
    for name in protocol_methods(protocol):
        impl = getattr(cls, name, None)
        if impl is None or not callable(impl):
            out.append(f"{cls.__name__}.{name} missing")
            continue
        want = inspect.signature(getattr(protocol, name)).parameters
        have = inspect.signature(impl).parameters
        for pname, p in want.items():
            if p.kind is p.VAR_KEYWORD:
                if not any(q.kind is q.VAR_KEYWORD for q in have.values()):
                    out.append(f"{cls.__name__}.{name} takes no **{pname}")
                continue
            q = have.get(pname)
            if q is None or q.kind is not p.kind:
                out.append(f"{cls.__name__}.{name}: parameter {pname} "
                           f"{'missing' if q is None else f'is {q.kind}, contract says {p.kind}'}")
            elif p.default is not p.empty and q.default is q.empty:
                out.append(f"{cls.__name__}.{name}: {pname} must be optional")
        for qname, q in have.items():
            if qname not in want and q.default is q.empty and q.kind not in (q.VAR_POSITIONAL,
                                                                                q.VAR_KEYWORD):
                out.append(f"{cls.__name__}.{name}: extra required parameter {qname}")
    return out


@pytest.mark.parametrize("protocol, cls", [(TelemetrySource, DeviceClient),
                                           (TelemetrySource, ReplaySource),
                                           (TelemetrySource, WatchClient),
                                           (CommandChannel, DeviceClient),
                                           (DeviceLink, DeviceClient),
                                           (BaseMotionInstrument, FunctionGenerator4050)])
def test_signatures_match(protocol, cls):
    assert protocol_methods(protocol)
    assert signature_problems(protocol, cls) == []


def test_the_checker_catches_a_mismatch():
    class Narrow:
        def subscribe(self):                       # no callback parameter
            pass

        def unsubscribe(self, callback, extra):    # an extra required parameter
            pass

    problems = signature_problems(TelemetrySource, Narrow)
    assert "Narrow.subscribe: parameter callback missing" in problems
    assert "Narrow.subscribe: parameter after_others missing" in problems
    assert "Narrow.unsubscribe: extra required parameter extra" in problems
    assert "Narrow.add_link_listener missing" in problems and "Narrow.close missing" in problems


def test_live_objects_are_instances_of_their_contracts(tmp_path):
    """A running session's link and generator, and a replay of what it recorded."""
    with Testbed("sim", testbed=INERTIAL, fast=True, generator="sim",
                 log_folder=tmp_path) as tb:
        assert isinstance(tb.client, TelemetrySource) and isinstance(tb.client, CommandChannel)
        assert isinstance(tb.client, DeviceLink)
        assert isinstance(tb.generator, BaseMotionInstrument)
        tb.start_recording("contract")
        tb.dwell(0.2)
        files = tb.stop_recording()["files"]
    replay = ReplaySource(files[0], speed=None)
    try:
        assert isinstance(replay, TelemetrySource)
        assert not isinstance(replay, CommandChannel)          # a replay cannot command
        assert not isinstance(replay, DeviceLink)
        seen = []
        replay.subscribe(seen.append)
        replay.unsubscribe(seen.append)
        replay.unsubscribe(seen.append)                       # twice: no error
    finally:
        replay.close()
