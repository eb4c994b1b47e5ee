"""A campaign's design uploads discretised before its first run (campaign/designs_ahead.py):
each design the campaign uploads is discretised and its loop's plant sampled once, into
the numerics cache, so the runs import neither scipy.signal nor scipy.linalg for them; a
design that cannot be discretised is left for its upload step to report."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from conftest import in_fresh_interpreter


from groundstation.campaign import load_campaign
from groundstation.campaign.designs_ahead import discretise_designs_ahead
from groundstation.core.dictionary import load_dictionary
from groundstation.core.numerics_cache import CACHE_ENV

ROOT = Path(__file__).resolve().parents[2]
RELATIVE_STEPS = ROOT / "profiles" / "campaigns" / "relative_steps.toml"


def _kept(cache: Path, kind: str) -> int:
    return len(list((cache / kind).glob("*.npz"))) if (cache / kind).exists() else 0


def test_every_uploaded_design_is_discretised_once(numerics_cache):
    c = load_campaign(RELATIVE_STEPS)
    assert discretise_designs_ahead(c, load_dictionary()) == 2          # design 1 and design 2
    assert _kept(numerics_cache, "sections") >= 2 and _kept(numerics_cache, "zero_order_hold") == 1
    before = sorted(p.stat().st_mtime_ns for p in (numerics_cache / "sections").glob("*.npz"))
    assert discretise_designs_ahead(c, load_dictionary()) == 2
    assert sorted(p.stat().st_mtime_ns for p in (numerics_cache / "sections").glob("*.npz")) == before


def test_after_it_an_upload_imports_no_scipy(numerics_cache):
    """What the runs then do - the upload's table and its closed-loop check - in a fresh
    interpreter: no scipy.signal, no scipy.linalg."""
    discretise_designs_ahead(load_campaign(RELATIVE_STEPS), load_dictionary())
    design = ROOT / "profiles" / "controllers" / "relative_design2.toml"
    code = ("import sys, json\nfrom groundstation.params.design_file import load_design\n"
            "from groundstation.params.loop_response import loop_model\n"
            f"loop_model(load_design({str(design)!r}))\n"
            "print(json.dumps([m for m in ('scipy.signal', 'scipy.linalg') if m in sys.modules]))")
    assert in_fresh_interpreter(code, **{CACHE_ENV: str(numerics_cache)}) == []


def test_a_design_that_cannot_be_discretised_is_left_to_its_upload(numerics_cache, tmp_path):
    """A design file gone or garbled since the check: nothing raised, the others done."""
    c = load_campaign(RELATIVE_STEPS)
    garbled = tmp_path / "garbled.toml"
    garbled.write_text("not a design any more")
    steps = [dataclasses.replace(s, args={**s.args, "design": str(garbled)})
             if s.action == "upload_design" and s.run == 1 else s for s in c.steps]
    assert discretise_designs_ahead(dataclasses.replace(c, steps=steps), load_dictionary()) == 1
