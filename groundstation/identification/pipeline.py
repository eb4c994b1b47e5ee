"""From identification logs to the identified parameters: which logs serve, their
frequency responses, the plant fit, and what of it goes into the testbed file.

A log serves the plant fit when it is an open-loop random excitation of one motor
(reference §7: `open_loop_sysid`) large enough for the bearing to slide: at the small
level (0.02 A) the bearing sticks and its presliding friction is a stiff spring the
linear plant leaves out, so such a log is listed and not used.  From each log that
serves, the responses from the excited motor's current to both encoders (and the gyro
on the inertial rig) are estimated (analysis.log_frf) and fitted together
(analysis.plant_fit).

The bearing's viscous coefficient b_f is fitted, but not written from the frequency
responses: under random excitation the Coulomb friction acts as an extra damping of about
the same kind, so the fitted b_f is an effective damping at that excitation level (on the
twin, about 10 % above the true b_f at 1 A), not the b_f of the friction model.  It is
reported as that; the steady-state friction sweep is what measures b_f.

Which log serves what is read off the log: a log whose profile drives a motor current
(PROFILE_BEGIN's target, in the log's command journal) serves the plant fit; a log whose
profile drives the position reference serves the friction (friction.py: the velocity
sweep, the hysteresis loops), which is identified after the plant, with the identified
plant.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..analysis.log_frf import frf_from_log
from ..analysis.log_window import LogIdentificationError
from ..analysis.plant_fit import (FRICTION_STIFFNESS, MeasuredResponse, ParameterEstimate,
                                  PlantFit, fit_plant)
from ..core.errors import GroundStationError
from ..logs.reader import LogReader
from ..plant.testbed import Testbed, load_testbed
from .friction import FrictionFit, identify_friction_logs
from .twin_bias import corrected_fit
from .testbed_file import Provenance

#: below this RMS current (A) the bearing sticks: the log does not serve the plant fit
MIN_CURRENT_RMS_A = 0.1
#: the band fitted by default: above the low band where friction shapes the response
#: most, below the band edge of the shipped excitation (5-300 Hz)
DEFAULT_BAND_HZ = (15.0, 300.0)
#: fitted, reported, not written (see the module docstring)
EFFECTIVE_ONLY = ("mechanics.bearing_viscous", FRICTION_STIFFNESS.name)
INPUTS = ("current_coarse", "current_fine")
#: PROFILE_BEGIN's targets (protocol/commands.toml): what a log's profile drives
CURRENT_TARGETS = {2, 3}
POSITION_TARGETS = {0, 1}


class IdentificationError(GroundStationError):
    """The logs cannot identify the rig (the message says which log and why)."""


@dataclass(frozen=True)
class LogUse:
    """What one log was used for."""
    path: Path
    used: bool
    input_channel: str               # the excited motor's current ('' if none)
    current_rms_a: float
    note: str = ""
    purpose: str = "plant"           # 'plant' (open-loop current) or 'friction' (position)


@dataclass(frozen=True, eq=False)
class Identification:
    base: Testbed
    fit: PlantFit
    logs: tuple[LogUse, ...]
    responses: tuple             # analysis.log_frf.LogFrf of every response fitted
    written: dict[str, float]    # what goes into the testbed file
    provenance: tuple[Provenance, ...]
    notes: tuple[str, ...]
    friction: FrictionFit | None = None    # None: no log served the friction

    @property
    def slope_table(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The identified slope table (x, f) to write beside the file (None: keep the base's)."""
        t = self.friction.slope_table if self.friction is not None else None
        return None if t is None else (t[0], t[1])


def _testbed_kind(text: str) -> tuple[str, str]:
    try:
        t = tomllib.loads(text).get("testbed", {})
    except tomllib.TOMLDecodeError:
        return "", ""
    return str(t.get("configuration", "")), str(t.get("setup", ""))


def _examine(path: Path, base: Testbed) -> LogUse:
    """Which motor the log excites, and whether it serves; IdentificationError for a log
    of another kind of testbed."""
    try:
        with LogReader(path) as r:
            _, _, text = r.testbed()
            data = r.read("HIGH_RATE", list(INPUTS))
            targets = _profile_targets(r)
    except GroundStationError as exc:
        raise IdentificationError(f"{path.name}: cannot be read ({exc})") from None
    kind = _testbed_kind(text) if text else ("", "")
    if text and kind != (base.configuration, str(base.setup)):
        raise IdentificationError(
            f"{path.name} was recorded on a {kind[0]} {kind[1]} testbed, the base file "
            f"{base.path.name} is {base.configuration} {base.setup}: identify each rig from "
            f"its own logs, starting from a base file of its kind")
    rms = {c: float(np.sqrt(np.nanmean(np.square(np.asarray(data[c], dtype=float)))))
           if len(data[c]) else 0.0 for c in INPUTS}
    channel = max(INPUTS, key=lambda c: rms[c])
    if targets & POSITION_TARGETS and not targets & CURRENT_TARGETS:
        return LogUse(path, True, channel, rms[channel], "", "friction")
    if targets and not targets & CURRENT_TARGETS:
        return LogUse(path, False, "", rms[channel], "plays no current or position profile")
    if not rms[channel] > 0.0:
        return LogUse(path, False, "", 0.0, "no motor current: not an identification log")
    if rms[channel] < MIN_CURRENT_RMS_A:
        return LogUse(path, False, channel, rms[channel],
                      f"{rms[channel]:.3g} A RMS: the bearing sticks at this level (presliding "
                      f"friction), which the linear plant leaves out; not used")
    return LogUse(path, True, channel, rms[channel])


def _profile_targets(r: LogReader) -> set[int]:
    """The targets of the profiles the log's session began (its command journal)."""
    out = set()
    for rec in r.journal("command"):
        if rec.data.get("name") == "PROFILE_BEGIN":
            target = (rec.data.get("arguments") or {}).get("target")
            if isinstance(target, int):
                out.add(target)
    return out


def _responses(use: LogUse, base: Testbed) -> list:
    outputs = ["encoder_outer", "encoder_inner"] + (["gyro_rate"] if base.inertial else [])
    out = []
    for output in outputs:
        try:
            out.append(frf_from_log(use.path, use.input_channel, output, testbed=base))
        except LogIdentificationError as exc:
            raise IdentificationError(f"{use.path.name}: {use.input_channel} -> {output}: "
                                      f"{exc}") from None
    return out


def _provenance(p: ParameterEstimate) -> Provenance:
    return Provenance(p.name, p.units, p.base, p.value, p.ci95, p.status, p.reason, p.sources)


def _written(fit: PlantFit) -> tuple[dict[str, float], list[Provenance], list[str]]:
    written, provenance, notes = {}, [], []
    for p in fit.parameters:
        if p.name in EFFECTIVE_ONLY and p.status == "identified":
            what = ("the bearing's damping seen by the frequency responses (with the twin "
                    "correction, b_f itself if the twin's friction is the rig's; without, b_f "
                    "plus the Coulomb friction's equivalent)" if p.name == "mechanics.bearing_viscous"
                    else "the bearing friction's linearised stiffness at this excitation")
            notes.append(f"{p.name}: {p.value:.4g} {p.units} fitted as {what}; not written "
                         f"(the base value stays)")
            provenance.append(Provenance(p.name, p.units, p.base, p.base, None,
                                         "held (friction)", f"fitted {p.value:.4g} {p.units}: "
                                         f"{what}", p.sources))
            continue
        if p.name == FRICTION_STIFFNESS.name:
            continue                                  # not a parameter of the file
        if p.status == "identified":
            written[p.name] = p.value
        provenance.append(_provenance(p))
    return written, provenance, notes


def _with_friction(written: dict[str, float], provenance: list[Provenance], notes: list[str],
                   friction: FrictionFit | None) -> None:
    """Put the friction's identified values and provenance in (the velocity sweep's b_f
    replaces the frequency-response fit's effective one)."""
    if friction is None:
        return
    ours = {e.name for e in friction.estimates}
    provenance[:] = [p for p in provenance if p.name not in ours]
    provenance += [_provenance(e) for e in friction.estimates]
    written.update(friction.written)
    if "mechanics.bearing_viscous" in friction.written:
        notes[:] = [n.replace("not written (the base value stays)",
                              "the velocity sweep's b_f is written instead")
                    if n.startswith("mechanics.bearing_viscous:") else n for n in notes]
    notes += friction.notes


def _twin_corrected(fit: PlantFit, base: Testbed, responses, serving: Sequence[LogUse],
                    friction: FrictionFit | None) -> tuple[PlantFit, list[str]]:
    """The fit corrected on a twin with the rig's friction: the identified one, else the
    base file's (said in a note).  The twin's b_f is the friction's, never the fit's
    effective damping, which stands for b_f and the Coulomb friction together."""
    values = {"mechanics.bearing_viscous": float(base.mechanics["bearing_viscous"]),
              "friction.coulomb_torque": float(base.friction["coulomb_torque"])}
    notes = []
    if friction is not None:
        values.update(friction.written)
    else:
        notes.append("the twin that measured the fit's bias has the base file's friction (no "
                     "friction log given): the correction is as good as that friction")
    try:
        fit, more = corrected_fit(fit, responses, [(u.path, u.input_channel) for u in serving],
                                  values, None if friction is None or friction.slope_table is None
                                  else friction.slope_table[:2])
    except GroundStationError as exc:
        return fit, [f"the fit's bias could not be measured on the twin ({exc}): not corrected"]
    return fit, notes + more


def identify(paths: Sequence[str | Path], base_path: str | Path, *,
             band_hz: tuple[float, float] = DEFAULT_BAND_HZ,
             min_coherence: float = 0.9, twin_correction: bool = True) -> Identification:
    """Identify the rig that recorded `paths`, starting from `base_path`: the plant from
    its open-loop current logs, then its friction from its position-profile logs, then
    (`twin_correction`) the plant fit's bias measured on a twin of the result and taken
    out (twin_bias.py)."""
    base = load_testbed(base_path)
    if not paths:
        raise IdentificationError("no logs given: record the open_loop_sysid campaign on "
                                  "the rig and give its logs (or its report.json)")
    uses = [_examine(Path(p), base) for p in paths]
    serving = [u for u in uses if u.used and u.purpose == "plant"]
    if not serving:
        raise IdentificationError(
            "none of the logs is an open-loop random excitation of at least "
            f"{MIN_CURRENT_RMS_A:g} A RMS (the plant is fitted first, the friction with it): "
            + "; ".join(f"{u.path.name}: {u.note or 'a position profile (friction)'}"
                        for u in uses))
    responses = [lf for u in serving for lf in _responses(u, base)]
    measured = [MeasuredResponse(lf.model_path, lf.measured.freq_hz, lf.measured.response,
                                 lf.measured.coherence, lf.measured.segments, lf.path.name)
                for lf in responses]
    rates = {round(lf.measured.rate_hz, 6) for lf in responses}
    if len(rates) != 1:
        raise IdentificationError(f"the logs were sampled at different rates {sorted(rates)}")
    try:
        fit = fit_plant(base, measured, sample_rate_hz=rates.pop(), band_hz=band_hz,
                        min_coherence=min_coherence)
    except GroundStationError as exc:
        raise IdentificationError(f"the plant fit failed: {exc}") from None
    friction = identify_friction_logs([u.path for u in uses if u.used and u.purpose == "friction"],
                                      base, fit.testbed)
    twin_notes: list[str] = []
    if twin_correction:
        fit, twin_notes = _twin_corrected(fit, base, responses, serving, friction)
    written, provenance, notes = _written(fit)
    _with_friction(written, provenance, notes, friction)
    notes += fit.messages + tuple(twin_notes)
    return Identification(base, fit, tuple(uses), tuple(responses), written,
                          tuple(provenance), tuple(notes), friction)
