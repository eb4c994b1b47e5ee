"""params/upload_path.py: the one path from a design to a verified table on the device -
the table built over the device's, cleared at the gate, uploaded and verified - and its
device-free first half (`prepare`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.link import open_client
from groundstation.params import table as ptable
from groundstation.params.clearance import ValidationRefused
from groundstation.params.design_file import load_design, table_values
from groundstation.params.upload import MemoryHistory, ParameterLoader
from groundstation.params.upload_path import (PreparedTable, UploadOutcome, prepare, source_of,
                                              upload_design, upload_table)
from groundstation.sim import SimulatedDevice

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = ROOT / "profiles" / "controllers"
DESIGN2 = CONTROLLERS / "relative_design2.toml"


@pytest.fixture
def device(dictionary):
    """A real-time simulated device, its link, and the names of the commands sent."""
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=3, speed=4.0).start()
    client = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}", heartbeat=True)
    client.connect()
    sent: list[str] = []
    client.add_command_listener(lambda result: sent.append(result.name))
    yield dev, client, sent
    client.close()
    dev.stop()


def with_c0_gain(tmp_path, gain: str) -> Path:
    """Relative Design #2 with c0's gain replaced (its testbed path made absolute)."""
    text = DESIGN2.read_text()
    path = tmp_path / f"design2_gain_{gain}.toml"
    path.write_text(text.replace('"../testbeds/', f'"{ROOT / "profiles" / "testbeds"}/')
                    .replace("gain = 30801", f"gain = {gain}"))
    return path


def test_prepare_builds_and_validates_without_a_device(dictionary):
    prepared = prepare(DESIGN2, dictionary)
    assert isinstance(prepared, PreparedTable) and prepared.report.ok
    assert prepared.values == table_values(load_design(DESIGN2), dictionary=dictionary)
    base = {**ptable.default_values(dictionary), "saturation_fine": 3.0}
    over = prepare(prepared.design, dictionary, base=base)   # a loaded design is used as it is
    assert over.design is prepared.design
    assert source_of(prepared.design) == str(DESIGN2) == source_of(DESIGN2)


def test_a_design_goes_over_the_devices_table_validated_and_verified(dictionary, device):
    dev, client, _sent = device
    loader = ParameterLoader(client, dictionary, MemoryHistory())
    reports, warnings = [], []
    outcome = upload_design(loader, DESIGN2, on_report=reports.append, warn=warnings.append)
    assert isinstance(outcome, UploadOutcome)
    assert outcome.record.validated and outcome.record.source == str(DESIGN2) == outcome.source
    assert outcome.report is reports[0] and outcome.report.ok and not outcome.clearance.overridden
    assert warnings == []                                    # nothing to warn about
    assert loader.read_active().crc == outcome.record.crc == ptable.table_crc(
        ptable.pack(dictionary, outcome.values))
    assert loader.history.records()[-1].crc == outcome.record.crc


def test_a_refused_design_is_not_sent_and_its_report_is_given(dictionary, device, tmp_path):
    _dev, client, sent = device
    loader = ParameterLoader(client, dictionary, MemoryHistory())
    reports = []
    with pytest.raises(ValidationRefused, match="refused by validation, nothing sent") as info:
        upload_design(loader, with_c0_gain(tmp_path, "30801000"), on_report=reports.append)
    assert reports == [info.value.report] and not reports[0].ok
    values = ptable.default_values(dictionary)
    with pytest.raises(ValidationRefused, match="needs a reason"):
        upload_table(loader, values, "no design")            # no design and no reason
    assert not {"PARAM_BEGIN", "PARAM_WRITE", "PARAM_COMMIT"} & set(sent)
    assert loader.history.records() == []


def test_an_override_is_warned_before_sending_and_written_into_the_source(dictionary, device, tmp_path):
    _dev, client, sent = device
    loader = ParameterLoader(client, dictionary, MemoryHistory())
    said: list[tuple[str, int]] = []
    warn = lambda text: said.append((text, len(sent)))       # noqa: E731 - how many commands went before
    outcome = upload_design(loader, with_c0_gain(tmp_path, "6000"), warn=warn,
                            accept_risk="slow loop for a bearing run-in")
    assert outcome.clearance.risk == "marginal" and outcome.record.accepted_risk == "marginal"
    assert outcome.source.endswith("(margins accepted: slow loop for a bearing run-in)")
    (text, commands_before), = said
    assert text.startswith("WARNING: uploading ") and "with its margins accepted" in text
    assert "PARAM_BEGIN" not in sent[:commands_before]       # said before the table went
    values = {**outcome.values, "saturation_fine": 12.5}
    edited = upload_table(loader, values, "edited by hand", accept_risk="bench check")
    assert edited.report is None and not edited.record.validated
    assert edited.source == "edited by hand (not validated; accepted: bench check)"


def test_a_design_is_judged_on_the_session_testbed_of_its_kind():
    """judged_on: the design's own testbed when the session chose none or the same file;
    another file of the same kind replaces it (and the operator is told); a design for
    another kind of rig is refused."""
    from dataclasses import replace as _replace

    from groundstation.params.clearance import ValidationRefused
    from groundstation.params.design_file import load_design
    from groundstation.params.upload_path import judged_on
    from groundstation.plant.testbed import load_testbed

    root = Path(__file__).resolve().parents[2]
    design = load_design(root / "profiles/controllers/relative_design2.toml")
    said = []
    assert judged_on(design, None, said.append) is design
    assert judged_on(design, design.testbed, said.append) is design and said == []
    softer = _replace(design.testbed, text=design.testbed.text + "\n# another rig\n",
                      mechanics={**design.testbed.mechanics, "flexure_stiffness": 20000.0})
    judged = judged_on(design, softer, said.append)
    assert judged.testbed is softer and judged.c0 is design.c0
    assert said == [f"relative_design2.toml: validated on this session's testbed "
                    f"{softer.path.name} (the design names relative_2dof.toml)"]
    with pytest.raises(ValidationRefused, match="relative_design2.toml is a design for a 2dof "
                                                "relative testbed; this session runs "
                                                "inertial_2dof.toml"):
        judged_on(design, load_testbed(root / "profiles/testbeds/inertial_2dof.toml"))
