"""The campaign's actions: one registered class per action, holding everything the
campaign knows about it - its keys, how its values are checked before anything runs,
and what it does on the Testbed.  Adding an action is one new class here (and a row in
docs/campaigns.md); reading, checking and running a campaign all look it up in
`ACTIONS`, so an action cannot be checked but not run, or the other way round.

    @register
    class Dwell(Action):
        name = "dwell"
        required = {"seconds"}
        durations = {"seconds"}

        def check(self, c: StepCheck) -> None:
            c.number("seconds", positive=True)

        def run(self, r: StepRun) -> None:
            r.tb.dwell(r.capped("seconds", r.args["seconds"]), progress=r.progress)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

from ..core.kinds import LinkState
from ..core.errors import GroundStationError
from ..instruments import spec4050
from .checks import StepCheck
from .model import Step


class Action:
    """The base of every action.  A subclass sets `name` and its keys and defines
    `run`; `check` is needed only when the action has values to check."""

    name: ClassVar[str]
    #: keys a step must give / may give; any other key is refused
    required: ClassVar[frozenset[str]] = frozenset()
    optional: ClassVar[frozenset[str]] = frozenset()
    #: keys naming a file, resolved relative to the campaign file when it is read
    paths: ClassVar[frozenset[str]] = frozenset()
    #: keys that are a time the run waits through: a trial run (max_step_seconds) caps them
    durations: ClassVar[frozenset[str]] = frozenset()
    #: the step drives the function generator (the GUI finds one before such a campaign runs)
    needs_generator: ClassVar[bool] = False

    def check(self, c: StepCheck) -> None:
        """Check the step's values (problems go to `c`); nothing is sent anywhere."""

    def run(self, r: "StepRun") -> None:
        raise NotImplementedError

    @property
    def keys(self) -> frozenset[str]:
        return self.required | self.optional


#: action name -> its handler, in the order registered
ACTIONS: dict[str, Action] = {}


def register(cls: type[Action]) -> type[Action]:
    """Class decorator: make `cls` the handler of the action `cls.name`."""
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        raise TypeError(f"{cls.__name__}: an action needs a name")
    if name in ACTIONS:
        raise ValueError(f"action {name!r} is registered twice ({type(ACTIONS[name]).__name__}, "
                         f"{cls.__name__})")
    if cls.run is Action.run:
        raise TypeError(f"{cls.__name__}: action {name!r} does not say how it runs")
    for attr in ("required", "optional", "paths", "durations"):
        setattr(cls, attr, frozenset(getattr(cls, attr)))      # a set literal is fine to write
    if not (cls.paths | cls.durations) <= cls.required | cls.optional:
        raise ValueError(f"{cls.__name__}: paths and durations must be keys of {name!r}")
    ACTIONS[name] = cls()
    return cls


def known_actions() -> str:
    """The registered actions, as a refusal lists them."""
    return ", ".join(sorted(ACTIONS))


@dataclass
class StepRun:
    """What an action's `run` gets: the Testbed, the step, and the runner's settings."""

    tb: Any
    step: Step
    max_step_seconds: float | None
    report: Callable[[Step, float], None]

    @property
    def args(self) -> dict[str, Any]:
        return self.step.args

    def capped(self, key: str, value: float) -> float:
        """`value` of `key`, shortened to max_step_seconds when `key` is a duration."""
        if self.max_step_seconds is not None and key in ACTIONS[self.step.action].durations:
            return min(float(value), self.max_step_seconds)
        return float(value)

    def progress(self, fraction: float) -> None:
        self.report(self.step, fraction)


# ------------------------------------------------------------------------- the link, modes
@register
class Connect(Action):
    name = "connect"

    def run(self, r: StepRun) -> None:
        # the Testbed connected when it opened: this step checks the link is still there
        if r.tb.client is None or r.tb.client.link_state != LinkState.UP:
            raise GroundStationError("the link is not up")


@register
class SetMode(Action):
    name = "set_mode"
    required = {"mode"}

    def check(self, c: StepCheck) -> None:
        c.mode("mode")

    def run(self, r: StepRun) -> None:
        r.tb.set_mode(r.args["mode"])


@register
class Arm(Action):
    name = "arm"

    def run(self, r: StepRun) -> None:
        r.tb.arm()


@register
class Disarm(Action):
    name = "disarm"

    def run(self, r: StepRun) -> None:
        r.tb.disarm()


# ------------------------------------------------------------------------- the controller
@register
class UploadDesign(Action):
    name = "upload_design"
    required = {"design"}
    optional = {"accept_risk"}
    paths = {"design"}

    def check(self, c: StepCheck) -> None:
        from ..params.design_file import load_design     # imported when a step is checked, not at start-up

        c.loads("design", "design", lambda: load_design(c.args["design"]))
        c.text("accept_risk")

    def run(self, r: StepRun) -> None:
        r.tb.upload_design(r.args["design"], accept_risk=r.args.get("accept_risk"))


@register
class FrictionComp(Action):
    name = "friction_comp"
    required = {"enabled"}

    def check(self, c: StepCheck) -> None:
        c.flag("enabled")

    def run(self, r: StepRun) -> None:
        r.tb.friction_comp(bool(r.args["enabled"]))


@register
class SetReference(Action):
    name = "set_reference"
    required = {"angle_rad"}

    def check(self, c: StepCheck) -> None:
        item = c.checker.command_arg("SET_REFERENCE", "reference")
        lo, hi = item.value_range or (-math.inf, math.inf)
        v = c.number("angle_rad", lo=lo, hi=hi, what="SET_REFERENCE range in protocol/commands.toml")
        tb = c.testbed
        if v is not None and tb is not None and abs(v) > tb.mechanics["travel"]:
            c.bad("angle_rad", f"beyond the testbed's travel of +-{tb.mechanics['travel']:g} rad "
                               f"({tb.path.name} [mechanics] travel)")

    def run(self, r: StepRun) -> None:
        r.tb.set_reference(float(r.args["angle_rad"]))


@register
class SetCurrents(Action):
    name = "set_currents"
    optional = {"coarse_a", "fine_a"}

    def check(self, c: StepCheck) -> None:
        tb = c.testbed
        for key, arg, motor in (("coarse_a", "current_coarse", "motor_coarse"),
                                ("fine_a", "current_fine", "motor_fine")):
            lo, hi = c.checker.command_arg("SET_CURRENTS", arg).value_range or (-math.inf, math.inf)
            v = c.number(key, lo=lo, hi=hi, what=f"SET_CURRENTS {arg} range in protocol/commands.toml")
            if v is not None and tb is not None:
                m = getattr(tb, motor)
                peak = m["peak_torque"] / m["torque_constant"]
                if abs(v) > peak * (1 + 1e-6):
                    c.bad(key, f"beyond the motor's peak current {peak:.3g} A ({tb.path.name} "
                               f"[{motor}] peak_torque / torque_constant)")

    def run(self, r: StepRun) -> None:
        r.tb.set_currents(float(r.args.get("coarse_a", 0.0)), float(r.args.get("fine_a", 0.0)))


# ------------------------------------------------------------------------- the generator
_MODEL = f"{spec4050.MODEL} limit, groundstation/instruments/spec4050.py"
_LOAD = "HZ"                      # the base stage's amplifier input: high impedance
#: the table's quantity -> the campaign step's key for it
_WAVE_ARGS = {"frequency": "frequency_hz", "phase": "phase_deg", "amplitude": "amplitude_vpp",
              "offset": "offset_v"}


@register
class GeneratorSet(Action):
    name = "generator_set"
    needs_generator = True
    required = {"waveform"}
    optional = {"channel", "frequency_hz", "amplitude_vpp", "offset_v", "phase_deg", "output"}

    def check(self, c: StepCheck) -> None:
        c.channel()
        c.flag("output")
        wave = c.args.get("waveform")
        if not isinstance(wave, str) or wave.upper() not in spec4050.WAVEFORMS:
            c.bad("waveform", f"not a waveform the generator driver sets ({', '.join(spec4050.WAVEFORMS)})")
            return
        wave = wave.upper()
        # the instrument's own limits come from its one table (spec4050.LIMITS), the
        # same rows the driver and the simulated instrument check; the stage's amplifier
        # input is high impedance, the load the driver expects
        values: dict[str, float | None] = {}
        for key, arg in _WAVE_ARGS.items():
            row = spec4050.limit_for(key, wave)
            if row is None:                       # the setting does not apply to this wave
                continue
            low, high = row.bounds(_LOAD)
            where = f", {wave}" if spec4050.varies_by_waveform(key) else ""
            where += ", high-impedance load" if row.depends_on_load else ""
            values[key] = c.number(arg, lo=low, hi=high, what=f"{_MODEL}{where}")
        amp, ofst = values.get("amplitude"), values.get("offset")
        envelope = spec4050.limit_for("envelope", wave)
        if envelope is not None and amp is not None and ofst is not None \
                and abs(ofst) + amp / 2 > envelope.bounds(_LOAD)[1]:
            c.bad("amplitude_vpp", f"|offset| + amplitude/2 = {abs(ofst) + amp / 2:g} V is beyond "
                                   f"{envelope.bounds(_LOAD)[1]:g} V ({_MODEL})")
        tb = c.testbed
        if tb is None:
            return
        lim_amp, lim_ofst = tb.limits.get("fg_max_amplitude"), tb.limits.get("fg_max_offset")
        if amp is not None and lim_amp is not None and amp > lim_amp:
            c.bad("amplitude_vpp", f"above the testbed's limit of {lim_amp:g} Vpp "
                                   f"({tb.path.name} [limits] fg_max_amplitude)")
        if ofst is not None and lim_ofst is not None and abs(ofst) > lim_ofst:
            c.bad("offset_v", f"beyond the testbed's limit of +-{lim_ofst:g} V "
                              f"({tb.path.name} [limits] fg_max_offset)")

    def run(self, r: StepRun) -> None:
        a = r.args
        r.tb.generator_set(int(a.get("channel", 1)), waveform=a["waveform"],
                           frequency_hz=a.get("frequency_hz"), amplitude_vpp=a.get("amplitude_vpp"),
                           offset_v=float(a.get("offset_v", 0.0)), phase_deg=float(a.get("phase_deg", 0.0)),
                           output=bool(a.get("output", True)))


@register
class GeneratorOff(Action):
    name = "generator_off"
    needs_generator = True

    def run(self, r: StepRun) -> None:
        r.tb.generator_off()


@register
class PlayBaseMotion(Action):
    name = "play_base_motion"
    needs_generator = True
    required = {"psd"}
    optional = {"duration_s", "seed", "rms_mrad", "channel"}
    paths = {"psd"}
    # duration_s is not a duration to cap: a base-motion profile keeps its period, and a
    # capped dwell after it plays only its beginning

    def check(self, c: StepCheck) -> None:
        from ..basemotion import load_profile, load_psd

        a = c.args
        c.channel()
        duration = c.number("duration_s", positive=True)
        rms = c.number("rms_mrad", positive=True)
        seed = a.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            c.bad("seed", "must be an integer >= 0")
            return
        if not c.loads("psd", "psd", lambda: load_psd(a["psd"])):
            return
        if ("duration_s" in a and duration is None) or ("rms_mrad" in a and rms is None):
            return
        tb = c.testbed
        if tb is None:
            return
        # synthesised as it will be played: its amplitude is what the generator is asked for
        cache = c.checker.base_motion
        key = (a["psd"], duration, seed, rms)
        if key not in cache:
            try:
                kwargs = {"seed": seed, "target_rms_rad": None if rms is None else rms * 1e-3}
                if duration is not None:
                    kwargs["duration_s"] = duration
                cache[key] = load_profile(a["psd"], tb, **kwargs)
            except GroundStationError as exc:
                cache[key] = str(exc)
        profile = cache[key]
        if isinstance(profile, str):
            c.problem(f"psd: {profile}")
            return
        vpp = profile.amplitude_vpp
        if vpp > spec4050.AMPLITUDE_MAX_VPP[_LOAD]:
            c.problem(f"psd: the profile needs {vpp:.3g} Vpp, above the generator's "
                      f"{spec4050.AMPLITUDE_MAX_VPP[_LOAD]:g} Vpp ({_MODEL})")
        lim = tb.limits.get("fg_max_amplitude")
        if lim is not None and vpp > lim:
            c.problem(f"psd: the profile needs {vpp:.3g} Vpp, above the testbed's limit "
                      f"of {lim:g} Vpp ({tb.path.name} [limits] fg_max_amplitude); lower rms_mrad")

    def run(self, r: StepRun) -> None:
        a = r.args
        rms = a.get("rms_mrad")
        r.tb.play_base_motion(a["psd"], duration_s=r.capped("duration_s", a.get("duration_s", 60.0)),
                              seed=int(a.get("seed", 0)), rms_rad=None if rms is None else float(rms) * 1e-3,
                              channel=int(a.get("channel", 1)))


# ------------------------------------------------------------------------- recording, playing
@register
class StartRecording(Action):
    name = "start_recording"
    required = {"name"}
    optional = {"notes"}

    def check(self, c: StepCheck) -> None:
        c.text("name")
        c.text("notes", empty_ok=True)

    def run(self, r: StepRun) -> None:
        r.tb.start_recording(r.args["name"], r.args.get("notes", ""))


@register
class StopRecording(Action):
    name = "stop_recording"

    def run(self, r: StepRun) -> None:
        r.tb.stop_recording()


@register
class Play(Action):
    name = "play"
    required = {"profile"}
    optional = {"mode"}
    paths = {"profile"}

    def check(self, c: StepCheck) -> None:
        from ..profiles.profile import load_profile

        c.mode("mode")
        c.loads("profile", "profile", lambda: load_profile(c.args["profile"], c.checker.d))

    def run(self, r: StepRun) -> None:
        # the profile's own length is capped by the Testbed (it stops playback cleanly)
        r.tb.play(r.args["profile"], mode=r.args.get("mode"), max_seconds=r.max_step_seconds,
                  progress=r.progress)


@register
class Dwell(Action):
    name = "dwell"
    required = {"seconds"}
    durations = {"seconds"}

    def check(self, c: StepCheck) -> None:
        c.number("seconds", positive=True)

    def run(self, r: StepRun) -> None:
        r.tb.dwell(r.capped("seconds", r.args["seconds"]), progress=r.progress)


@register
class Settle(Action):
    """Wait until the rig is at rest, in range and unfaulted before a run's clock starts
    (Station.settle; the criteria in station/start_state.py).  The run fails - with
    every unmet criterion and its measured value - if that does not happen in
    max_seconds."""

    name = "settle"
    optional = {"max_seconds", "hold_s", "max_motion_urad", "max_rate_mrad_s", "recentre",
                "recentre_seconds"}
    paths = {"recentre"}

    def check(self, c: StepCheck) -> None:
        for key in ("max_seconds", "hold_s", "max_motion_urad", "max_rate_mrad_s", "recentre_seconds"):
            c.number(key, positive=True)

    def run(self, r: StepRun) -> None:
        from ..station.start_state import StartCriteria
        a = r.args
        criteria = StartCriteria(hold_s=float(a.get("hold_s", 1.0)),
                                 max_motion_rad=float(a.get("max_motion_urad", 50.0)) * 1e-6,
                                 max_rate_rad_s=float(a.get("max_rate_mrad_s", 1.0)) * 1e-3)
        r.tb.settle(float(a.get("max_seconds", 30.0)), criteria, progress=r.progress,
                    recentre=a.get("recentre"), recentre_seconds=float(a.get("recentre_seconds", 20.0)))


@register
class Mark(Action):
    name = "mark"
    required = {"text"}

    def check(self, c: StepCheck) -> None:
        c.text("text")

    def run(self, r: StepRun) -> None:
        r.tb.mark(r.args["text"])


@register
class Pause(Action):
    name = "pause"
    required = {"prompt"}

    def check(self, c: StepCheck) -> None:
        c.text("prompt")

    def run(self, r: StepRun) -> None:
        r.tb.pause(r.args["prompt"])


#: every key that names a file, whatever the action (the CLI shows these by file name)
PATH_KEYS = frozenset().union(*(a.paths for a in ACTIONS.values()))
#: (action, key) pairs a trial run caps
DURATION_KEYS = frozenset((a.name, k) for a in ACTIONS.values() for k in a.durations)
