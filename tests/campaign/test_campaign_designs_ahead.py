"""A campaign's design uploads discretised before its first run (campaign/designs_ahead.py):
each design the campaign uploads is discretised and its loop's plant sampled once, into
the numerics cache, so the runs import neither scipy.signal nor scipy.linalg for them; a
design that cannot be discretised is left for its upload step to report."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from groundstation.campaign import load_campaign
from groundstation.campaign.designs_ahead import discretise_designs_ahead
from groundstation.core.dictionary import load_dictionary
from groundstation.core.numerics_cache import CACHE_ENV
from groundstation.plant import model as plant_model

ROOT = Path(__file__).resolve().parents[2]
RELATIVE_STEPS = ROOT / "profiles" / "campaigns" / "relative_steps.toml"


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    plant_model._discretised.cache_clear()     # the copy in memory: this folder starts empty
    return tmp_path / "cache"


def _kept(cache: Path, kind: str) -> int:
    return len(list((cache / kind).glob("*.npz"))) if (cache / kind).exists() else 0


def test_every_uploaded_design_is_discretised_once(cache):
    c = load_campaign(RELATIVE_STEPS)
    assert discretise_designs_ahead(c, load_dictionary()) == 2          # design 1 and design 2
    assert _kept(cache, "sections") >= 2 and _kept(cache, "zero_order_hold") == 1
    before = sorted(p.stat().st_mtime_ns for p in (cache / "sections").glob("*.npz"))
    assert discretise_designs_ahead(c, load_dictionary()) == 2
    assert sorted(p.stat().st_mtime_ns for p in (cache / "sections").glob("*.npz")) == before


def test_after_it_an_upload_imports_no_scipy(cache):
    """What the runs then do - the upload's table and its closed-loop check - in a fresh
    interpreter: no scipy.signal, no scipy.linalg."""
    discretise_designs_ahead(load_campaign(RELATIVE_STEPS), load_dictionary())
    design = ROOT / "profiles" / "controllers" / "relative_design2.toml"
    code = ("import sys, json\nfrom groundstation.params.design_file import load_design\n"
            "from groundstation.params.loop_response import loop_model\n"
            f"loop_model(load_design({str(design)!r}))\n"
            "print(json.dumps([m for m in ('scipy.signal', 'scipy.linalg') if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         timeout=120, env={**os.environ, CACHE_ENV: str(cache)}).stdout
    assert json.loads(out.splitlines()[-1]) == []


def test_a_design_that_cannot_be_discretised_is_left_to_its_upload(cache, tmp_path):
    """A design file gone or garbled since the check: nothing raised, the others done."""
    c = load_campaign(RELATIVE_STEPS)
    garbled = tmp_path / "garbled.toml"
    garbled.write_text("not a design any more")
    steps = [dataclasses.replace(s, args={**s.args, "design": str(garbled)})
             if s.action == "upload_design" and s.run == 1 else s for s in c.steps]
    assert discretise_designs_ahead(dataclasses.replace(c, steps=steps), load_dictionary()) == 1
