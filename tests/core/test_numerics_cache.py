"""The numerics cache (core/numerics_cache.py): a design's sections and a plant's
zero-order hold read back from disk are bit for bit what scipy computes; a check of a
design discretised before is discretised again in a fresh interpreter without
scipy.signal; a damaged,
foreign or unwritable cache costs time, never a result or the command."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import expm

from conftest import in_fresh_interpreter

from groundstation.core.numerics_cache import CACHE_ENV, cached_arrays, input_key
from groundstation.params.design_file import load_design
from groundstation.params.discretise import bilinear_rate_hz, discretise_design
from groundstation.plant import model as plant_model
from groundstation.plant.model import continuous_model, discrete_model
from groundstation.plant.testbed import load_testbed

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "profiles" / "controllers" / "relative_design1.toml"
TESTBED = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"


def _files(folder: Path) -> list[Path]:
    return sorted(folder.rglob("*.npz")) if folder.exists() else []


def _sections(design) -> dict[str, np.ndarray]:
    return {name: c.sos for name, c in discretise_design(design).items()}


def _scipy_sections(tf, prewarp_hz) -> np.ndarray:
    zd, pd, kd = signal.bilinear_zpk(tf.zeros, tf.poles, tf.gain, bilinear_rate_hz(1200.0, prewarp_hz))
    return np.atleast_2d(signal.zpk2sos(zd, pd, kd))


def test_sections_read_back_are_bit_for_bit_the_computed_ones(numerics_cache):
    design = load_design(DESIGN)
    cold = _sections(design)
    written = _files(numerics_cache / "sections")
    assert written, "nothing was kept"
    stamps = [p.stat().st_mtime_ns for p in written]
    warm = _sections(design)
    assert [p.stat().st_mtime_ns for p in _files(numerics_cache / "sections")] == stamps   # read, not rewritten
    for name in cold:
        assert cold[name].tobytes() == warm[name].tobytes(), name


def test_a_kept_result_is_what_scipy_gives_for_those_inputs(numerics_cache):
    design = load_design(DESIGN)
    for tf in design.cascades.values():
        inputs = (np.asarray(tf.zeros, complex), np.asarray(tf.poles, complex), float(tf.gain),
                  float(bilinear_rate_hz(1200.0, design.prewarp_hz)))
        ours = cached_arrays("sections", "any", inputs,
                             lambda tf=tf: (_scipy_sections(tf, design.prewarp_hz),),
                             lambda a: len(a) == 1)[0]
        assert ours.tobytes() == _scipy_sections(tf, design.prewarp_hz).tobytes()


def test_the_zero_order_hold_read_back_equals_the_matrix_exponential(numerics_cache):
    tb = load_testbed(TESTBED)
    cold = discrete_model(tb)
    assert _files(numerics_cache / "zero_order_hold")
    plant_model._discretised.cache_clear()          # the copy in memory too: read from disk
    warm = discrete_model(tb)
    assert cold.Ad.tobytes() == warm.Ad.tobytes() and cold.Bd.tobytes() == warm.Bd.tobytes()
    A, B = continuous_model(tb)
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = expm(M * warm.substep)
    assert warm.Ad.tobytes() == E[:n, :n].tobytes() and warm.Bd.tobytes() == E[:n, n:].tobytes()


@pytest.mark.parametrize("damage", ["truncated", "garbage", "wrong shape", "not finite"])
def test_a_damaged_file_is_computed_again_and_replaced(numerics_cache, damage):
    design = load_design(DESIGN)
    good = _sections(design)
    for path in _files(numerics_cache / "sections"):
        if damage == "truncated":
            path.write_bytes(path.read_bytes()[:40])
        elif damage == "garbage":
            path.write_bytes(b"not an archive at all")
        else:
            bad = np.zeros((2, 5)) if damage == "wrong shape" else np.full((1, 6), np.nan)
            np.savez(path, a0=bad)
    again = _sections(design)
    for name in good:
        assert again[name].tobytes() == good[name].tobytes(), name
    after = _sections(design)                        # and the rewritten files read back
    assert all(after[name].tobytes() == good[name].tobytes() for name in good)


def test_a_folder_that_cannot_be_written_is_not_used(tmp_path, monkeypatch):
    blocker = tmp_path / "a file"
    blocker.write_text("the cache folder's path is taken by a file")
    monkeypatch.setenv(CACHE_ENV, str(blocker))
    design = load_design(DESIGN)
    sections = _sections(design)
    for name, tf in design.cascades.items():
        assert sections[name].shape[1] == 6
    assert blocker.read_text().startswith("the cache")


@pytest.mark.parametrize("result, kinds_check", [
    (np.array([np.inf]), lambda a: True),                 # not finite: refused by the cache itself
    (np.array([1.0], dtype=np.float32), lambda a: True),  # not float64: likewise
    (np.array([1.0, 2.0]), lambda a: a[0].size == 1),     # the kind's own check refuses it
])
def test_a_result_refused_as_invalid_is_never_kept(numerics_cache, result, kinds_check):
    calls = []

    def compute():
        calls.append(1)
        return (result,)

    for _ in range(2):
        cached_arrays("demo", "1", (1.0,), compute, kinds_check)
    assert len(calls) == 2 and not _files(numerics_cache)


def test_the_key_is_every_input_bit_and_the_librarys_version():
    base = input_key("sections", "1.16.3", (np.array([1 + 2j]), 3.0))
    assert base == input_key("sections", "1.16.3", (np.array([1 + 2j]), 3.0))
    assert base != input_key("sections", "1.16.4", (np.array([1 + 2j]), 3.0))
    assert base != input_key("sections", "1.16.3", (np.array([1 + 2j]), np.nextafter(3.0, 4.0)))
    assert base != input_key("sections", "1.16.3", (np.array([1 + 2j, 0j]), 3.0))
    assert base != input_key("zero_order_hold", "1.16.3", (np.array([1 + 2j]), 3.0))
    # the same bytes in another shape or type are another input
    assert (input_key("k", "1", (np.zeros((2, 3)),)) != input_key("k", "1", (np.zeros((3, 2)),)))
    assert (input_key("k", "1", (np.zeros(2),)) != input_key("k", "1", (np.zeros(2, np.int64),)))
    with pytest.raises(TypeError, match="cannot be keyed"):
        input_key("k", "1", ({"a": 1},))


def test_results_saved_are_read_as_the_sections_of_another_process(numerics_cache):
    """What one command wrote, the next reads: a fresh interpreter discretises from the file."""
    design = load_design(DESIGN)
    mine = {name: s.tolist() for name, s in _sections(design).items()}
    code = ("import json\nfrom groundstation.params.design_file import load_design\n"
            "from groundstation.params.discretise import discretise_design\n"
            f"d = discretise_design(load_design({str(DESIGN)!r}))\n"
            "import sys\nprint(json.dumps([{n: c.sos.tolist() for n, c in d.items()}, 'scipy.signal' in sys.modules]))")
    theirs, imported = in_fresh_interpreter(code, **{CACHE_ENV: str(numerics_cache)})
    assert theirs == mine and imported is False


def test_the_base_stages_held_response_read_back_equals_scipys(numerics_cache):
    from groundstation.basemotion import BaseStageModel

    stage = BaseStageModel.from_testbed(load_testbed(ROOT / "profiles" / "testbeds" / "inertial_2dof.toml"))
    f = np.linspace(0.1, 200.0, 57)
    cold = stage.held_response(f, 1 / 1200)
    assert _files(numerics_cache / "held_stage")
    warm = stage.held_response(f, 1 / 1200)
    num, den = stage._continuous()
    numd, dend, _ = signal.cont2discrete((num, den), 1 / 1200, method="zoh")
    z = np.exp(2j * np.pi * f / 1200)
    direct = np.polyval(np.ravel(numd), z) / np.polyval(dend, z)
    assert cold.tobytes() == warm.tobytes() == direct.tobytes()


def test_no_cache_folder_to_be_named_is_no_cache(monkeypatch):
    """Without GROUNDSTATION_CACHE_DIR and no user cache folder to be had (platformdirs
    raising, as with no home directory), the sections are computed as always."""
    import platformdirs

    def no_home(*args, **kwargs):
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setattr(platformdirs, "user_cache_dir", no_home)
    design = load_design(DESIGN)
    sections = _sections(design)
    for name, tf in design.cascades.items():
        expected = _scipy_sections(tf, design.prewarp_hz)
        assert sections[name].shape == expected.shape, name
