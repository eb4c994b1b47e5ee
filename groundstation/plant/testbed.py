"""Testbed configuration files (`profiles/testbeds/*.toml`) -> a checked `Testbed` record.

Every number the simulator uses comes from one of these files; the schema below says
which keys exist, their units and the allowed range.  A missing, mistyped or
out-of-range value raises TestbedConfigError naming the file, the field and the range,
before anything starts: the simulator never runs half-configured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.kinds import Setup
from ..core.errors import GroundStationError
from ..core.tomlfile import read_toml

PROFILES_DIR = Path(__file__).resolve().parent.parent.parent / "profiles"
TESTBEDS_DIR = PROFILES_DIR / "testbeds"
DEFAULT_TESTBED = TESTBEDS_DIR / "relative_2dof.toml"


class TestbedConfigError(GroundStationError):
    """A testbed file is missing, malformed, or has a bad value (names file and field)."""

    __test__ = False        # a name starting with "Test" that pytest must not collect


INF = math.inf
# section -> key -> (type, min, max, units); min/max inclusive.  Types: "float", "int",
# "bool", "str".  Keys whose section is optional are checked only if the section exists.
_MECH_2DOF = {
    "J1": ("float", 1e-4, 1e3, "in-oz-s^2"), "J2": ("float", 1e-4, 1e3, "in-oz-s^2"),
    "flexure_stiffness": ("float", 1.0, 1e7, "in-oz/rad"),
    "flexure_damping": ("float", 0.0, 1e4, "in-oz-s/rad"),
    "bearing_viscous": ("float", 0.0, 1e4, "in-oz-s/rad"),
    "flexure_safe_deflection": ("float", 1e-5, 1.0, "rad"),
    "flexure_yield_deflection": ("float", 1e-5, 1.0, "rad"),
    "travel": ("float", 1e-3, math.pi, "rad"),
}
_MECH_1DOF = {
    "J": ("float", 1e-4, 1e3, "in-oz-s^2"),
    "bearing_viscous": ("float", 0.0, 1e4, "in-oz-s/rad"),
    "travel": ("float", 1e-3, math.pi, "rad"),
}
_MOTOR = {
    "torque_constant": ("float", 1e-3, 1e4, "in-oz/A"), "resistance": ("float", 1e-3, 1e4, "ohm"),
    "inductance": ("float", 0.0, 10.0, "H"), "back_emf": ("float", 0.0, 100.0, "V/(rad/s)"),
    "peak_torque": ("float", 1e-3, 1e5, "in-oz"),
}
SCHEMA: dict[str, dict[str, tuple]] = {
    "testbed": {"name": ("str", None, None, ""), "configuration": ("str", None, None, ""),
                "setup": ("str", None, None, ""), "description": ("str", None, None, "")},
    "friction": {"model": ("str", None, None, ""), "sigma": ("float", 1e-3, 1e9, "in-oz/rad"),
                 "coulomb_torque": ("float", 0.0, 1e4, "in-oz"), "alpha": ("float", 0.05, 10.0, ""),
                 "slope_table": ("str", None, None, ""), "stack_capacity": ("int", 4, 4096, "")},
    "motor_coarse": _MOTOR,
    "motor_fine": _MOTOR,
    "sensors": {
        "encoder_bits": ("int", 8, 32, "bits"), "base_encoder_bits": ("int", 8, 32, "bits"),
        "encoder_noise": ("float", 0.0, 1e-3, "rad"),
        "gyro_resolution": ("float", 1e-12, 1.0, "rad/s"), "gyro_range": ("float", 1e-3, 1e3, "rad/s"),
        "gyro_bandwidth": ("float", 1.0, 5000.0, "Hz"), "gyro_damping": ("float", 0.05, 5.0, ""),
        "gyro_delay": ("float", 0.0, 0.1, "s"), "gyro_arw": ("float", 0.0, 100.0, "deg/sqrt(h)"),
        "gyro_bias_stability": ("float", 0.0, 1e4, "deg/h"),
        "autocollimator_bits": ("int", 8, 32, "bits"), "autocollimator_range": ("float", 1e-4, 45.0, "deg"),
        "autocollimator_noise": ("float", 0.0, 1e-3, "rad"),
    },
    "base_stage": {"enabled": ("bool", None, None, ""), "amplifier_gain": ("float", 0.0, 1e3, "V/V"),
                   "actuator_gain": ("float", 0.0, 10.0, "rad/V"),
                   "natural_frequency": ("float", 0.01, 500.0, "Hz"), "damping": ("float", 0.0, 10.0, "")},
    "simulation": {"substeps": ("int", 1, 64, "")},
    # a repeatable torque ripple along the bearing's travel (reference §9a: "due to bearing
    # and/or motor irregularities"), additive to the friction torque, a function of the
    # bearing angle phi1 only; the compensator's model never knows it.  Optional section.
    "bearing_ripple": {"amplitude": ("float", 0.0, 1e3, "in-oz"),
                       "period": ("float", 1e-7, 10.0, "rad"),
                       "phase": ("float", -10.0, 10.0, "rad")},
    "limits": {"fg_max_amplitude": ("float", 0.0, 20.0, "Vpp"), "fg_max_offset": ("float", 0.0, 10.0, "V")},
}
NO_RIPPLE = {"amplitude": 0.0, "period": 1.0, "phase": 0.0}
FRICTION_MODELS = ("SFM", "DHM", "DB-SFM", "DB-DHM", "viscous")


@dataclass(frozen=True)
class Testbed:
    """A checked testbed configuration; sections are plain dicts of SI-or-rig units."""

    __test__ = False

    path: Path
    name: str
    configuration: str            # "1dof" | "2dof"
    setup: str                    # "relative" | "inertial"
    description: str
    mechanics: dict[str, float]
    friction: dict[str, Any]
    motor_coarse: dict[str, float]
    motor_fine: dict[str, float]
    sensors: dict[str, float]
    base_stage: dict[str, Any]
    substeps: int
    limits: dict[str, float]
    assumed: tuple[str, ...]
    text: str                     # the file as read (recorded with every log)
    #: {"amplitude" in-oz, "period" rad, "phase" rad}; amplitude 0 (no section): none
    bearing_ripple: dict[str, float] = field(default_factory=lambda: dict(NO_RIPPLE))

    @property
    def slope_table_path(self) -> Path:
        return (self.path.parent / self.friction["slope_table"]).resolve()

    @property
    def is_2dof(self) -> bool:
        return self.configuration == "2dof"

    @property
    def inertial(self) -> bool:
        return self.setup == Setup.INERTIAL


def _check(value: Any, spec: tuple, where: str) -> Any:
    kind, lo, hi, units = spec
    u = f" {units}" if units else ""
    if kind == "str":
        if not isinstance(value, str):
            raise TestbedConfigError(f"{where} must be text, got {value!r}")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise TestbedConfigError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (
            kind == "int" and not isinstance(value, int)):
        raise TestbedConfigError(f"{where} must be {'an integer' if kind == 'int' else 'a number'}"
                                 f"{u and ' in' + u}, got {value!r}")
    if not math.isfinite(value) or not lo <= value <= hi:
        raise TestbedConfigError(f"{where} = {value!r}{u} is outside the allowed range [{lo}, {hi}]{u}")
    return int(value) if kind == "int" else float(value)


def _section(doc: dict, name: str, schema: dict, path: Path, required: bool = True) -> dict:
    raw = doc.get(name)
    if raw is None:
        if required:
            raise TestbedConfigError(f"{path}: missing section [{name}]")
        return {}
    if not isinstance(raw, dict):
        raise TestbedConfigError(f"{path}: [{name}] must be a table")
    unknown = set(raw) - set(schema)
    if unknown:
        raise TestbedConfigError(f"{path}: [{name}] has unknown key(s) {sorted(unknown)} "
                                 f"(known: {', '.join(schema)})")
    out = {}
    for key, spec in schema.items():
        if key not in raw:
            lo, hi, units = spec[1], spec[2], spec[3]
            rng = f" (allowed range [{lo}, {hi}] {units})" if lo is not None else ""
            raise TestbedConfigError(f"{path}: [{name}] is missing '{key}'{rng}")
        out[key] = _check(raw[key], spec, f"{path}: {name}.{key}")
    return out


def load_testbed(path: str | Path | None = None) -> Testbed:
    """Read and check a testbed file (default: the 2-DOF relative configuration)."""
    path = Path(path) if path is not None else DEFAULT_TESTBED
    doc, text = read_toml(path, TestbedConfigError, f"testbed file not found (see {TESTBEDS_DIR})")

    tb = _section(doc, "testbed", SCHEMA["testbed"], path)
    if tb["configuration"] not in ("1dof", "2dof"):
        raise TestbedConfigError(f"{path}: testbed.configuration must be \"1dof\" or \"2dof\"")
    if tb["setup"] not in set(Setup):
        raise TestbedConfigError(f"{path}: testbed.setup must be \"relative\" or \"inertial\"")
    mech = _section(doc, "mechanics", _MECH_2DOF if tb["configuration"] == "2dof" else _MECH_1DOF, path)
    if tb["configuration"] == "2dof" and mech["flexure_safe_deflection"] >= mech["flexure_yield_deflection"]:
        raise TestbedConfigError(f"{path}: mechanics.flexure_safe_deflection must be below "
                                 f"flexure_yield_deflection")
    fric = _section(doc, "friction", SCHEMA["friction"], path)
    if fric["model"] not in FRICTION_MODELS:
        raise TestbedConfigError(f"{path}: friction.model = {fric['model']!r}; use one of "
                                 f"{', '.join(FRICTION_MODELS)}")
    base_schema = SCHEMA["base_stage"]
    raw_base = doc.get("base_stage", {})
    if isinstance(raw_base, dict) and raw_base.get("enabled") is False:
        base_schema = {"enabled": base_schema["enabled"]}
    base = _section(doc, "base_stage", base_schema, path)
    if tb["setup"] == Setup.RELATIVE and base["enabled"]:
        raise TestbedConfigError(f"{path}: base_stage.enabled must be false in the relative "
                                 f"setup (the base is fixed to the optical table)")
    assumed = doc.get("assumed", {}).get("values", [])
    if not isinstance(assumed, list) or not all(isinstance(a, str) for a in assumed):
        raise TestbedConfigError(f"{path}: [assumed] values must be a list of 'section.key' names")
    testbed = Testbed(
        path=path.resolve(), name=tb["name"], configuration=tb["configuration"], setup=Setup(tb["setup"]),
        description=tb["description"], mechanics=mech, friction=fric,
        motor_coarse=_section(doc, "motor_coarse", SCHEMA["motor_coarse"], path),
        motor_fine=_section(doc, "motor_fine", SCHEMA["motor_fine"], path),
        sensors=_section(doc, "sensors", SCHEMA["sensors"], path), base_stage=base,
        substeps=_section(doc, "simulation", SCHEMA["simulation"], path)["substeps"],
        limits=_section(doc, "limits", SCHEMA["limits"], path),
        assumed=tuple(assumed), text=text,
        bearing_ripple=_section(doc, "bearing_ripple", SCHEMA["bearing_ripple"], path, required=False)
        or dict(NO_RIPPLE))
    if fric["model"] != "viscous" and not testbed.slope_table_path.is_file():
        raise TestbedConfigError(f"{path}: friction.slope_table '{fric['slope_table']}' not found "
                                 f"(looked for {testbed.slope_table_path})")
    return testbed
