"""A run's metrics carry validity (analysis/validity.py) and a campaign comparison never
ranks an invalid run (campaign/metrics.py): it names it and says why, and gives no ratio
against an invalid baseline.  Rows are built here as campaign_metrics builds them; no
log is needed to test the comparison's rules."""

from __future__ import annotations

import math

import pytest

from groundstation.analysis.validity import MAX_EXCLUDED_FRACTION, pct_text, window_validity
from groundstation.campaign.comparison import compare
from groundstation.campaign.metrics import CampaignMetrics
from groundstation.campaign.model import AnalysisSpec
from groundstation.campaign.report import CampaignReport
from groundstation.campaign.report_figures import html_page

DESIGNS = ["open_loop", "d1.toml", "d2.toml"]
MOTIONS = ["BM1.csv", "BM2.csv"]
SPEC = AnalysisSpec(group_by="base_motion", compare="design", baseline="d1.toml", given=True)


# ---------------------------------------------------------------------- the verdict
def test_the_excluded_fraction_and_the_verdict():
    # 52 % of a 60 s window at 1200 Hz off the autocollimator's range: not valid, said so
    frames = 72_000
    v = window_validity(frames, 0, int(0.52 * frames), sensor="autocollimator")
    assert not v.valid and v.excluded_fraction == pytest.approx(0.52)
    assert v.reason == "52 % of the window off the autocollimator's range or at its A/D rail (limit 1 % excluded)"
    # missing frames count against the window too (in control periods: received + missing)
    v = window_validity(990, 10, 0, sensor="autocollimator")
    assert v.valid and v.missing_fraction == pytest.approx(0.01)
    v = window_validity(980, 20, 5, sensor="encoder_inner")
    assert not v.valid and "2 % of its frames missing" in v.reason
    assert "0.5 % of the window not measured by the encoder_inner" in v.reason
    # the limit is stated and may be moved
    assert MAX_EXCLUDED_FRACTION == 0.01
    assert window_validity(100, 0, 5, max_excluded_fraction=0.05).valid
    assert not window_validity(100, 0, 6, max_excluded_fraction=0.05).valid
    with pytest.raises(ValueError, match="from 0 to 1"):
        window_validity(100, 0, 0, max_excluded_fraction=1.5)
    # a sensor that gave no figure at all: not valid, whatever the fractions
    assert not window_validity(100, 0, 0, unscored="no jitter: all excluded").valid
    assert pct_text(0.0042) == "0.42 %" and pct_text(0.517) == "52 %"


# ---------------------------------------------------------------------- the comparison
def _row(run: int, design: str, motion: str, std: float, energy: float, excluded: float = 0.0,
         error: str = "") -> dict:
    v = window_validity(72_000, 0, int(round(excluded * 72_000)), sensor="autocollimator")
    metrics = {} if error else {
        "from_s": 0.0, "to_s": 60.0, "std_urad": std, "highpass_rms_urad": 0.9 * std,
        "energy_total_j": energy, "excluded_fraction": v.excluded_fraction, "valid": v.valid,
        "invalid_reason": v.reason}
    return {"run": run, "run_status": "completed", "recording": f"r{run}", "file": f"/logs/r{run}.h5",
            "part": None, "variables": {"design": design, "base_motion": motion},
            "window": {"start": "mark", "mark": "", "start_s": 0.0, "stop_s": 60.0},
            "metrics": metrics, "notes": "", "error": error, "reference": {}, "reference_error": ""}


def _metrics(rows: list[dict]) -> CampaignMetrics:
    matrix = {"design": DESIGNS, "base_motion": MOTIONS}
    cells, notes = compare(rows, SPEC, matrix)
    return CampaignMetrics("c", "report.json", SPEC, matrix, rows, comparison=cells, notes=notes)


def test_an_invalid_run_is_named_not_ranked():
    rows = [_row(1, "open_loop", "BM1.csv", 2678.0, 0.0, excluded=0.06),
            _row(2, "open_loop", "BM2.csv", 3000.0, 0.0, excluded=0.52),
            _row(3, "d1.toml", "BM1.csv", 267.0, 327.0), _row(4, "d1.toml", "BM2.csv", 846.0, 234.0),
            _row(5, "d2.toml", "BM1.csv", 54.0, 14.0), _row(6, "d2.toml", "BM2.csv", 120.0, 30.0)]
    m = _metrics(rows)
    ol = m.cell("BM2", "open_loop")
    assert ol["valid"] is False and ol["excluded_fraction"] == pytest.approx(0.52)
    for key in ("std_urad", "highpass_rms_urad", "energy_total_j"):
        assert ol[f"{key}_ratio"] is None and ol[f"{key}_change_pct"] is None
    assert "not valid: 52 % of the window off the autocollimator's range" in ol["note"]
    # the valid ones are compared as before
    d2 = m.cell("BM1", "d2")
    assert d2["valid"] and d2["std_urad_ratio"] == pytest.approx(54.0 / 267.0)
    text = m.text()
    assert ("=> open_loop under base_motion BM2: not valid, 52 % of the window off the "
            "autocollimator's range or at its A/D rail (limit 1 % excluded) - not ranked") in text
    assert "open_loop cuts" not in text and "open_loop raises" not in text
    assert "=> d2 cuts jitter by 80 % and energy by 96 % vs d1 under base_motion BM1" in text
    assert "NOT VALID: 6 % of the window off" in text          # the row itself says so
    page = html_page(m, CampaignReport("c", "c.toml", 0.0), {})
    assert 'class="invalid"' in page and "not ranked" in page


def test_no_ratio_against_an_invalid_baseline():
    rows = [_row(1, "d1.toml", "BM1.csv", 267.0, 327.0, excluded=0.2),
            _row(2, "d2.toml", "BM1.csv", 54.0, 14.0),
            _row(3, "open_loop", "BM1.csv", 2678.0, 0.0)]
    m = _metrics(rows)
    d2 = m.cell("BM1", "d2")
    assert d2["valid"] and d2["baseline_valid"] is False
    assert d2["std_urad"] == 54.0 and d2["std_urad_ratio"] is None
    assert "the baseline's run is not valid (20 % of the window off" in d2["note"]
    base = m.cell("BM1", "d1")
    assert base["std_urad_ratio"] is None and "not valid" in base["note"]
    text = m.text()
    assert ("=> d2 under base_motion BM1: no comparison, the baseline d1 is not valid (20 % of "
            "the window off the autocollimator's range") in text
    assert "vs d1" not in text


def test_a_valid_repeat_is_compared_before_an_invalid_one():
    rows = [_row(1, "d1.toml", "BM1.csv", 267.0, 327.0),
            _row(2, "d2.toml", "BM1.csv", 900.0, 14.0, excluded=0.3),
            _row(3, "d2.toml", "BM1.csv", 54.0, 14.0)]
    cell = _metrics(rows).cell("BM1", "d2")
    assert cell["run"] == 3 and cell["valid"]
    assert math.isclose(cell["std_urad_ratio"], 54.0 / 267.0)
