"""What the embedded controller does, apart from physics: session, command checks and
execution, modes and arming, watchdog, parameter table, profiles, telemetry values.

No sockets and no wall clock here: time is the device tick, advanced by `step()`, so a
test can drive it deterministically.  `handle_command()` returns the RESPONSE stages to
send; the network endpoint (device.py) does the I/O.
"""

from __future__ import annotations

import logging
import math
import secrets
import zlib
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..codec.frames import decode_items, encode_items
from ..core.dictionary import CommandDef, Dictionary
from ..core.errors import GroundStationError
from ..params import table as ptable
from . import core
from . import friction as fr
from .engine import Engine
from .deviations import NONE as NO_DEVIATIONS
from ..plant.testbed import Testbed, load_testbed

log = logging.getLogger(__name__)

FIRMWARE_VERSION = (0 << 16) | (1 << 8) | 0
DEDUP_WINDOW = 64

ACCEPTED, REJECTED, COMPLETED, FAILED = 1, 2, 3, 4


@dataclass
class Stage:
    stage: int
    reason: int = 0
    data: bytes = b""


@dataclass
class _Staging:
    kind: str
    buffer: bytearray
    meta: dict[str, Any] = field(default_factory=dict)


class Firmware:
    """Device-side state machine of the testbed controller."""

    #: deliberate SPEC deviations for the conformance suite's tests (sim/deviations.py)
    deviations = NO_DEVIATIONS

    def __init__(self, dictionary: Dictionary, *, seed: int = 0, description: str = "",
                 testbed: Testbed | None = None):
        self.d = dictionary
        self.rate = dictionary.control_rate_hz
        self.modes = dictionary.command("SET_MODE").args[0].states
        self.targets = dictionary.command("PROFILE_BEGIN").args[1].states
        self.err = dictionary.error_codes
        self.faults = dictionary.packet("HOUSEKEEPING").item_by_name["fault_code"].states
        self.ev = dictionary.event_codes
        self.testbed = testbed or load_testbed()
        self.description = description or f"simulated testbed: {self.testbed.name} ({self.testbed.path.name})"
        #: connection id -> how that host is named in messages ("ip:port"), set by the
        #: protocol endpoint that owns the connections
        self.peer_names: dict[Any, str] = {}
        self.session_since_tick = 0
        self.params = ptable.default_values(dictionary)
        self.param_blob = ptable.pack(dictionary, self.params)
        self.param_crc = ptable.table_crc(self.param_blob)
        self.param_version = 0
        self.engine = Engine(self.testbed, self.params, seed=seed, control_rate_hz=self.rate)
        self.fw = self.engine.fw
        self.fw[core.FW_COMP_ON] = float(self.params["friction_comp_enabled"])
        self.session_token: int | None = None
        self.session_peer: Any = None
        self.telemetry_port = 0
        self.watchdog_expired = False
        self._staging: dict[str, _Staging] = {}
        self.profile: dict[str, Any] | None = None
        self.accepted = 0
        self.rejected = 0
        self.overruns = 0
        self.events: deque[tuple[int, int, str]] = deque(maxlen=256)
        self._done: OrderedDict[tuple[Any, int, int], list[Stage]] = OrderedDict()
        self._emit("INFO", "BOOT", f"firmware {self.version_string} booted: {self.testbed.name}")

    # ------------------------------------------------------------------ state views
    # the firmware state lives in the engine's array, shared with the compiled loop
    @property
    def tick(self) -> int:
        return int(self.fw[core.FW_TICK])

    @property
    def mode(self) -> int:
        return int(self.fw[core.FW_MODE])

    @mode.setter
    def mode(self, value: int) -> None:
        self.fw[core.FW_MODE] = value

    @property
    def armed(self) -> bool:
        return self.fw[core.FW_ARMED] > 0.5

    @property
    def fault(self) -> int:
        return int(self.fw[core.FW_FAULT])

    @fault.setter
    def fault(self, value: int) -> None:
        self.fw[core.FW_FAULT] = value

    @property
    def friction_comp(self) -> bool:
        return self.fw[core.FW_COMP_ON] > 0.5

    @property
    def profile_active(self) -> bool:
        return self.fw[core.FW_PROF_ACTIVE] > 0.5

    # ------------------------------------------------------------------ helpers
    @property
    def version_string(self) -> str:
        v = FIRMWARE_VERSION
        return f"{v >> 16}.{(v >> 8) & 0xFF}.{v & 0xFF}"

    def _emit(self, level: str, code: str, text: str, tick: int | None = None) -> None:
        """Queue an EVENT; `tick` is when it happened (default: now)."""
        levels = self.d.packet("EVENT").item_by_name["level"].states
        self.events.append((levels[level], self.ev[code], text, self.tick if tick is None else tick))

    def _mode_changed(self, tick: int | None = None) -> None:
        name = {val: k for k, val in self.modes.items()}[self.mode]
        self._emit("INFO", "MODE_CHANGED", f"mode {name}", tick)

    def _reason(self, name: str) -> int:
        return self.err[name]

    def _connect_reply(self, token: int) -> bytes:
        return encode_items(self.d.command("CONNECT").reply, {
            "session_token": token, "protocol_major": self.d.version_major,
            "protocol_minor": self.d.version_minor, "dictionary_hash": self.d.hash,
            "tick": self.tick & 0xFFFFFFFF}, "CONNECT reply")

    # ------------------------------------------------------------------ commands
    def handle_command(self, sequence: int, token: int, opcode: int, args: bytes,
                       peer: Any = None) -> list[Stage]:
        """Check and execute one COMMAND; returns the RESPONSE stages to send."""
        # per connection (SPEC §6.4): another host's identical frame is its own command,
        # never a replay of the owner's answer (which would hand it the session token)
        key = (peer if self.deviations.history_per_connection else None, sequence, opcode)
        if key in self._done and not self.deviations.replays_execute:   # a retry: answer again, never execute twice
            return self._done[key]
        try:
            stages = self._execute(sequence, token, opcode, args, peer)
        except Exception:  # a firmware bug must answer, not kill the device
            log.exception("command %04x failed inside the simulated firmware", opcode)
            stages = [Stage(ACCEPTED), Stage(FAILED, self._reason("INTERNAL_ERROR"))]
        if stages[0].stage == ACCEPTED:
            self.accepted += 1
        else:
            self.rejected += 1
        self._done[key] = stages
        while len(self._done) > DEDUP_WINDOW:
            self._done.popitem(last=False)
        return stages

    def _execute(self, sequence, token, opcode, args, peer) -> list[Stage]:
        try:
            cmd = self.d.command(opcode)
        except GroundStationError:
            return [Stage(REJECTED, self._reason("UNKNOWN_COMMAND"))]
        try:
            values = decode_items(cmd.args, args, cmd.name)
        except GroundStationError:
            return [Stage(REJECTED, self._reason("BAD_LENGTH"))]
        if cmd.name == "PROFILE_WRITE" and len(values["samples"]) % 4:
            return [Stage(REJECTED, self._reason("BAD_LENGTH"))]    # whole f32 samples only
        if cmd.needs_session and (self.session_token is None or token != self.session_token):
            self._emit("WARNING", "COMMAND_REJECTED", f"{cmd.name} without the session token")
            return [Stage(REJECTED, self._reason("NOT_SESSION_OWNER"), self._owner_text())]
        bad = self._range_problem(cmd, values)
        if bad:
            return [Stage(REJECTED, self._reason("OUT_OF_RANGE"))]
        if cmd.needs_session:
            self.fw[core.FW_LAST_HEARD] = self.tick
        handler = getattr(self, f"_cmd_{cmd.name.lower()}")
        return handler(values, peer)

    @staticmethod
    def _range_problem(cmd: CommandDef, values: dict[str, Any]) -> str | None:
        for item in cmd.args:
            v = values.get(item.name)
            if isinstance(v, (bytes, str)):
                continue
            if isinstance(v, float) and not math.isfinite(v):
                return item.name
            if not item.in_range(v):
                return item.name
            if item.states and v not in item.states.values():
                return item.name
        return None

    def _ok(self, data: bytes = b"") -> list[Stage]:
        return [Stage(ACCEPTED), Stage(COMPLETED, 0, data)]

    def _reject(self, reason: str) -> list[Stage]:
        return [Stage(REJECTED, self._reason(reason))]

    def _cmd_connect(self, v, peer):
        if v["protocol_major"] != self.d.version_major or v["dictionary_hash"] != self.d.hash:
            return [Stage(REJECTED, self._reason("DICTIONARY_MISMATCH"), self._connect_reply(0))]
        if self.session_token is not None and not v["take_over"] and peer != self.session_peer \
                and not self.deviations.connect_ignores_owner:
            return self._reject("SESSION_BUSY")
        if self.session_token is not None:
            self._emit("WARNING", "SESSION_TAKEN_OVER",
                       f"session taken over by {self.peer_names.get(peer, 'another host')}")
            self._safe_state()
        # unguessable whatever the seed: a token is the only proof of owning the session
        self.session_token = secrets.randbelow((1 << 32) - 1) + 1
        self.session_peer = peer
        self.session_since_tick = self.tick & 0xFFFFFFFF
        self.fw[core.FW_SESSION] = 1.0
        self.telemetry_port = v["telemetry_port"]
        self.fw[core.FW_LAST_HEARD] = self.tick
        self.watchdog_expired = False
        self._emit("INFO", "SESSION_OPENED", f"session opened by {self.peer_names.get(peer, peer)}")
        return self._ok(self._connect_reply(self.session_token))

    def _owner_text(self) -> bytes:
        """REJECTED NOT_SESSION_OWNER's data (SPEC §7): who owns the session and since
        which tick, so a host that lost it can say who took it and when."""
        if self.session_token is None:
            return b"no session open"
        who = self.peer_names.get(self.session_peer, "another host")
        return f"owner {who} since tick {self.session_since_tick}".encode()

    def end_session(self, why: str) -> None:
        """The session owner disconnected or its connection closed."""
        if self.session_token is None:
            return
        if self.armed:
            self._safe_state()
        self.session_token = None
        self.session_peer = None
        self.fw[core.FW_SESSION] = 0.0
        self._emit("INFO", "SESSION_CLOSED", why)

    def _cmd_disconnect(self, v, peer):
        self.end_session("session closed by the host")
        return self._ok()

    def _cmd_heartbeat(self, v, peer):
        return self._ok(encode_items(self.d.command("HEARTBEAT").reply,
                                     {"tick": self.tick & 0xFFFFFFFF}, "HEARTBEAT reply"))

    def _cmd_get_info(self, v, peer):
        return self._ok(encode_items(self.d.command("GET_INFO").reply, {
            "firmware_version": FIRMWARE_VERSION, "protocol_major": self.d.version_major,
            "protocol_minor": self.d.version_minor, "dictionary_hash": self.d.hash,
            "tick": self.tick & 0xFFFFFFFF, "description": self.description}, "GET_INFO reply"))

    def _cmd_set_mode(self, v, peer):
        target = v["mode"]
        if target == self.modes["IDLE"]:
            self._safe_state()                 # emits MODE_CHANGED if it was not idle
        elif self.armed:
            return self._reject("INVALID_STATE")
        if target != self.mode:
            self.mode = target
            self._mode_changed()
        return self._ok()

    def _cmd_arm(self, v, peer):
        if self.fault:
            return self._reject("FAULT_LATCHED")
        if self.mode == self.modes["IDLE"]:
            return self._reject("INVALID_STATE")
        if not self.armed:
            fw = self.fw
            fw[core.FW_ARMED] = 1.0
            fw[core.FW_I1] = fw[core.FW_I2] = fw[core.FW_RATE_REF] = 0.0
            # hold where the axis is, in the quantity the mode controls
            fw[core.FW_REF] = fw[core.FW_ENC_INNER] if self.mode == self.modes["RELATIVE"] \
                else fw[core.FW_LOS_EST]
            self.engine.reset_controllers()
            self._emit("INFO", "ARMED", "drives enabled")
        return self._ok()

    def _cmd_disarm(self, v, peer):
        self._safe_state(keep_mode=True)
        self.fault = 0                       # DISARM acknowledges a latched fault
        self.watchdog_expired = False
        return self._ok()

    def _cmd_abort(self, v, peer):
        self._safe_state()
        self._emit("WARNING", "ABORTED", f"abort from {peer}")
        return self._ok()

    def _cmd_friction_comp(self, v, peer):
        self.fw[core.FW_COMP_ON] = float(v["enable"])
        return self._ok()

    def _cmd_set_currents(self, v, peer):
        if self.mode != self.modes["OPEN_LOOP"]:
            return self._reject("INVALID_STATE")
        if not self.armed:
            return self._reject("NOT_ARMED")
        self.fw[core.FW_I1], self.fw[core.FW_I2] = v["current_coarse"], v["current_fine"]
        return self._ok()

    def _cmd_set_reference(self, v, peer):
        if self.mode not in (self.modes["RELATIVE"], self.modes["INERTIAL"]):
            return self._reject("INVALID_STATE")
        self.fw[core.FW_REF] = v["reference"]
        return self._ok()

    def _cmd_param_begin(self, v, peer):
        if v["table_length"] != ptable.table_size(self.d):
            return self._reject("OUT_OF_RANGE")
        self._staging["param"] = _Staging("param", bytearray(v["table_length"]),
                                          {"version": v["table_version"]})
        return self._ok()

    def _cmd_param_write(self, v, peer):
        return self._write_block("param", v["offset"], v["data"])

    def _write_block(self, kind: str, offset: int, data: bytes) -> list[Stage]:
        st = self._staging.get(kind)
        if st is None:
            return self._reject("NOTHING_STAGED")
        if offset + len(data) > len(st.buffer):
            return self._reject("OUT_OF_RANGE")
        st.buffer[offset:offset + len(data)] = data
        return self._ok()

    def _cmd_param_commit(self, v, peer):
        st = self._staging.get("param")
        if st is None:
            return self._reject("NOTHING_STAGED")
        if self.armed:
            return self._reject("INVALID_STATE")
        blob = bytes(st.buffer)
        if zlib.crc32(blob) != v["table_crc"] and self.deviations.commit_checks_crc:
            return [Stage(ACCEPTED), Stage(FAILED, self._reason("CRC_MISMATCH"))]
        values = ptable.unpack(self.d, blob)
        if ptable.problems(self.d, values):
            return [Stage(ACCEPTED), Stage(FAILED, self._reason("VALIDATION_FAILED"))]
        # activation happens here, between two step() calls: a control-cycle boundary
        self.params, self.param_blob = values, blob
        self.engine.apply_parameters(values)
        self.fw[core.FW_WD_TICKS] *= self.deviations.watchdog_factor
        self.fw[core.FW_COMP_ON] = float(values["friction_comp_enabled"])
        self.param_crc, self.param_version = zlib.crc32(blob), st.meta["version"]
        del self._staging["param"]
        self._emit("INFO", "PARAMETERS_ACTIVATED",
                   f"parameter table v{self.param_version} crc {self.param_crc:08x} active")
        return self._ok(encode_items(self.d.command("PARAM_COMMIT").reply, {
            "table_crc": self.param_crc, "tick": self.tick & 0xFFFFFFFF}, "PARAM_COMMIT reply"))

    def _cmd_param_read(self, v, peer):
        off, count = v["offset"], v["count"]
        if off + count > len(self.param_blob):
            return self._reject("OUT_OF_RANGE")
        return self._ok(encode_items(self.d.command("PARAM_READ").reply, {
            "offset": off, "data": self.param_blob[off:off + count]}, "PARAM_READ reply"))

    def _cmd_profile_begin(self, v, peer):
        if self.profile_active:
            return self._reject("INVALID_STATE")
        self._staging["profile"] = _Staging("profile", bytearray(4 * v["sample_count"]), dict(v))
        return self._ok()

    def _cmd_profile_write(self, v, peer):
        return self._write_block("profile", 4 * v["offset"], v["samples"])

    def _cmd_profile_commit(self, v, peer):
        st = self._staging.get("profile")
        if st is None:
            return self._reject("NOTHING_STAGED")
        if self.profile_active:
            return self._reject("INVALID_STATE")     # never swap samples under playback
        if zlib.crc32(bytes(st.buffer)) != v["profile_crc"]:
            return [Stage(ACCEPTED), Stage(FAILED, self._reason("CRC_MISMATCH"))]
        samples = np.frombuffer(bytes(st.buffer), ">f4").astype(np.float64)
        if not np.all(np.isfinite(samples)) or not self._profile_in_range(samples, st.meta["target"]):
            return [Stage(ACCEPTED), Stage(FAILED, self._reason("VALIDATION_FAILED"))]
        self.profile = {"samples": samples, **st.meta}
        del self._staging["profile"]
        return self._ok()

    def _profile_in_range(self, samples: np.ndarray, target: int) -> bool:
        """Samples must respect the same ranges as the commands they stand in for."""
        t = self.targets
        if target == t["REFERENCE"]:
            item = self.d.command("SET_REFERENCE").args[0]
        elif target in (t["CURRENT_COARSE"], t["CURRENT_FINE"]):
            item = self.d.command("SET_CURRENTS").args[0 if target == t["CURRENT_COARSE"] else 1]
        else:
            return bool(np.all(np.abs(samples) <= self.testbed.sensors["gyro_range"]))
        return item.in_range(float(samples.min())) and item.in_range(float(samples.max()))

    def _cmd_profile_start(self, v, peer):
        if self.profile is None:
            return self._reject("NOTHING_STAGED")
        if not self.armed:
            return self._reject("NOT_ARMED")
        t, m = self.targets, self.modes
        allowed = {t["REFERENCE"]: (m["RELATIVE"], m["INERTIAL"]), t["RATE_REFERENCE"]: (m["INERTIAL"],),
                   t["CURRENT_COARSE"]: (m["OPEN_LOOP"],), t["CURRENT_FINE"]: (m["OPEN_LOOP"],)}
        if self.mode not in allowed[self.profile["target"]]:
            return self._reject("INVALID_STATE")
        self.engine.load_profile(self.profile["samples"], self.profile["target"])
        self.fw[core.FW_PROF_POS] = self.deviations.profile_start_position
        self.fw[core.FW_PROF_ACTIVE] = 1.0
        self._emit("INFO", "PROFILE_STARTED", f"profile {self.profile['profile_id']} started")
        return self._ok()

    def _cmd_profile_stop(self, v, peer):
        if self.profile_active:
            self.fw[core.FW_PROF_ACTIVE] = 0.0
            self._emit("INFO", "PROFILE_STOPPED", "profile stopped by the host")
        return self._ok()

    # ------------------------------------------------------------------ control cycle
    def _safe_state(self, keep_mode: bool = False) -> None:
        """Both motors to zero now (this control period), drives off, profile stopped."""
        was_armed = self.armed
        fw = self.fw
        fw[core.FW_ARMED] = 0.0
        fw[core.FW_I1] = fw[core.FW_I2] = 0.0
        fw[core.FW_PROF_ACTIVE] = 0.0
        if was_armed:
            self._emit("INFO", "DISARMED", "drives disabled, motors at zero")
        if not keep_mode and self.mode != self.modes["IDLE"]:
            fw[core.FW_MODE] = self.modes["IDLE"]
            self._mode_changed()

    _EVENT_TEXT = {
        core.EV_WATCHDOG: ("CRITICAL", "WATCHDOG_EXPIRED", "no heartbeat for {wd} s: motors off, disarmed, idle"),
        core.EV_OVER_TRAVEL: ("ERROR", "FAULT", "outer axis beyond the travel limit: motors off"),
        core.EV_FLEXURE: ("ERROR", "FAULT", "flexure deflection beyond its safe range: motors off"),
        core.EV_PROFILE_DONE: ("INFO", "PROFILE_FINISHED", "profile finished"),
    }

    def run(self, n: int, v_fg: np.ndarray | None = None,
            out: np.ndarray | None = None) -> tuple[dict[str, Any], np.ndarray]:
        """n control periods -> HIGH_RATE columns (engineering units) and the truth array
        (`out`: where to write the outputs, see Engine.run; the columns are then None)."""
        plant_overflows = self.engine.fstate[fr.S_OVERFLOW]
        comp_overflows = self.engine.cstate[fr.S_OVERFLOW]
        cols, truth, events = self.engine.run(n, v_fg, out)
        if self.engine.fstate[fr.S_OVERFLOW] > plant_overflows:
            self._emit("WARNING", "SIMULATOR", "bearing friction model: reversal stack overflowed "
                       "and was reset (more nested reversals than its capacity)")
        if self.engine.cstate[fr.S_OVERFLOW] > comp_overflows:
            self._emit("WARNING", "FRICTION_COMP_RESET", "friction compensation: reversal stack "
                       "overflowed and was reset")
        for tick, code in events:
            level, name, text = self._EVENT_TEXT[code]
            if code == core.EV_WATCHDOG:
                self.watchdog_expired = True
            self._emit(level, name, text.format(wd=self.params["watchdog_timeout"]), tick)
            if code in (core.EV_WATCHDOG, core.EV_OVER_TRAVEL, core.EV_FLEXURE):
                self._emit("INFO", "DISARMED", "drives disabled, motors at zero", tick)
                self._emit("INFO", "MODE_CHANGED", "mode IDLE", tick)
        return cols, truth

    def housekeeping(self) -> dict[str, Any]:
        age_ms = (self.tick - self.fw[core.FW_LAST_HEARD]) * 1000.0 / self.rate
        current = abs(self.fw[core.FW_I1])
        return {
            "temp_motor_coarse": 25.0 + 0.5 * current,
            "temp_motor_fine": 25.0, "temp_flexure": 27.0, "temp_electronics": 35.0,
            "supply_motor": 28.0, "supply_logic": 5.0,
            "firmware_version": FIRMWARE_VERSION, "uptime": int(self.tick / self.rate),
            "param_table_crc": self.param_crc, "param_table_version": self.param_version,
            "active_profile": self.profile["profile_id"] if self.profile else 0,
            "watchdog": 2 if self.watchdog_expired else (0 if self.session_token else 1),
            "heartbeat_age": min(65535, int(age_ms)) if self.session_token else 65535,
            "commands_accepted": self.accepted, "commands_rejected": self.rejected,
            "fault_code": self.fault, "telemetry_overruns": self.overruns,
        }
