"""Controller design files -> continuous transfer functions -> the device's filter sections.

A design file (`profiles/controllers/*.toml`) holds a SITO controller the way the
reference (testbed.md §6) writes it: continuous transfer functions in factored form,
c0 and Q (so c1' = Q, c2' = 1) or c1' and c2' explicitly, for one mode ("relative":
e is the angle error in rad; "inertial": e is the rate error in rad/s) and one testbed.

    [design]
    name = "Relative Design #2"
    mode = "relative"                            # or "inertial"
    testbed = "../testbeds/relative_2dof.toml"   # relative to this file
    prewarp_hz = 46.70                           # optional
    outer_loop_gain_per_s = 25.0                 # K_p; required in inertial mode

    [saturation]
    coarse_in_oz = 81.3
    fine_in_oz = 16.1
    anti_windup = "none"     # optional: "none" (default) or "conditional_integration"

    [friction_compensation]
    enabled = false          # model, sigma_in_oz_per_rad, coulomb_torque_in_oz, alpha,
                             # slope_table (CSV, relative to this file) are optional

    # 30801(s+36.28)(s^2+25.92s+8.61e4) / [(s+108.8)(s^2+410.8s+8.61e4)]
    [c0]
    gain = 30801.0
    numerator = [[36.28], [25.92, 8.61e4]]
    denominator = [[108.8], [410.8, 8.61e4]]

Each factor is written as in the reference: [a] is (s + a), [b, c] is (s^2 + b s + c),
[0] is s (an integrator in a denominator); a repeated factor is written twice.  `gain`
multiplies the monic factors.  Instead of its factors, c0 may be *output-equivalent* to
another design's: `[c0] equivalent_to = "other.toml"` makes this design's loop gain
c0 (c1' g1 + c2' g2) the other's, with g1, g2 the plant of this design's testbed.

A file may start from another with a top-level `base = "other.toml"`: its tables are
merged key by key over the base's, except that a transfer function (c0, Q, c1, c2) is
replaced whole, and giving Q or c1/c2 drops all three of the base's.

The file is turned into continuous transfer functions here (groundstation.params.tf_algebra)
and discretised by groundstation.params.discretise; table_values gives the parameter table.
One of the three modules of the design path (tf_algebra, design_file, discretise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..core.kinds import Setup
from ..core.dictionary import Dictionary, load_dictionary
from ..core.errors import GroundStationError
from ..core.tomlfile import read_toml
from .discretise import _singular_text, discretise_design, pad_sections, singular_factors
from .table import default_values
from .tf_algebra import (CANCEL_TOLERANCE, CONTROL_RATE_HZ, DesignError, TransferFunction,
                         _snap_integrators, output_equivalent_c0)

MODES = ("relative", "inertial")
FRICTION_MODEL_CODES = {"SFM": 0, "DHM": 1, "DB-SFM": 2, "DB-DHM": 3}   # friction_comp_model
TRANSFER_FUNCTIONS = ("c0", "Q", "c1", "c2")


# ======================================================================================
# the design record
# ======================================================================================
@dataclass(frozen=True)
class FrictionCompensation:
    """Feedback friction compensation; None fields keep the table's current value."""

    enabled: bool
    model: str | None = None                 # SFM, DHM, DB-SFM, DB-DHM
    sigma_in_oz_per_rad: float | None = None
    coulomb_torque_in_oz: float | None = None
    alpha: float | None = None
    slope_table: Path | None = None
    slope_x: tuple[float, ...] | None = None      # the table's points, read from slope_table
    slope_ratio: tuple[float, ...] | None = None


@dataclass(frozen=True, eq=False)
class ControllerDesign:
    path: Path
    name: str
    description: str
    mode: str                       # "relative" | "inertial"
    testbed: Any                    # groundstation.plant.testbed.Testbed
    c0: TransferFunction            # in-oz/rad (relative) or in-oz/(rad/s) (inertial)
    c1: TransferFunction            # coarse path c1' (dimensionless)
    c2: TransferFunction            # fine path c2'
    q: TransferFunction | None      # the controller ratio, when the file gives Q
    saturation_coarse_in_oz: float
    saturation_fine_in_oz: float
    friction: FrictionCompensation
    #: the table's anti_windup entry: "none" runs the designed filters on through a
    #: saturation, as the reference's controller does (testbed.md §6 names the limits and
    #: nothing else); "conditional_integration" freezes all cascade states while either
    #: motor saturates (SPEC.md §10, step 7).  docs/fidelity.md has why "none" is the default.
    anti_windup: str = "none"
    outer_loop_gain_per_s: float | None = None
    prewarp_hz: float | None = None
    c0_equivalent_to: Path | None = None
    c0_order: int = 0
    notes: tuple[str, ...] = ()
    text: str = ""                  # the file as read

    @property
    def cascades(self) -> dict[str, TransferFunction]:
        return {"c0": self.c0, "c1": self.c1, "c2": self.c2}


# ======================================================================================
# loading
# ======================================================================================
_DESIGN_KEYS = {"name", "description", "mode", "testbed", "prewarp_hz", "outer_loop_gain_per_s"}
_SATURATION_KEYS = {"coarse_in_oz", "fine_in_oz", "anti_windup"}
#: design-file word -> the table's anti_windup value
ANTI_WINDUP = {"none": 0, "conditional_integration": 1}
_FRICTION_KEYS = {"enabled", "model", "sigma_in_oz_per_rad", "coulomb_torque_in_oz", "alpha",
                  "slope_table"}
_TF_KEYS = {"gain", "numerator", "denominator"}
_EQUIVALENT_KEYS = {"equivalent_to", "cancel_tolerance"}
_TOP_KEYS = {"base", "design", "saturation", "friction_compensation", *TRANSFER_FUNCTIONS}
# values that name files: resolved against the file that wrote them, before merging
_PATH_FIELDS = (("design", "testbed"), ("c0", "equivalent_to"), ("friction_compensation", "slope_table"))


def load_design(path: str | Path) -> ControllerDesign:
    """Read and check a design file; DesignError names the file and the field."""
    return _load(Path(path), ())


def _load(path: Path, chain: tuple[Path, ...]) -> ControllerDesign:
    doc, text = _merged_document(path, chain)
    where = str(path)
    d = _table(doc, "design", where)
    _no_unknown(d, _DESIGN_KEYS, where, "[design]")
    name = _text(d, "name", where, "design")
    description = _text(d, "description", where, "design", required=False) or ""
    mode = _text(d, "mode", where, "design")
    if mode not in MODES:
        raise DesignError(f"{where}: design.mode = {mode!r}; allowed: \"relative\", \"inertial\"")
    testbed = _testbed(d, where)
    if mode == Setup.INERTIAL and not testbed.inertial:
        raise DesignError(f"{where}: design.mode = \"inertial\" needs a testbed with a gyro "
                          f"(setup = \"inertial\"); {testbed.path.name} has setup = "
                          f"\"{testbed.setup}\"")
    prewarp = _number(d, "prewarp_hz", where, "design", required=False,
                      lo=0.0, hi=CONTROL_RATE_HZ / 2, open_lo=True, open_hi=True,
                      allowed=f"a frequency in Hz between 0 and {CONTROL_RATE_HZ / 2:g} (Nyquist)")
    kp = _number(d, "outer_loop_gain_per_s", where, "design", required=(mode == Setup.INERTIAL),
                 lo=0.0, allowed="a gain >= 0 in 1/s (K_p of the outer position loop)")
    sat_coarse, sat_fine, anti_windup = _saturation(doc, where)
    friction = _friction(doc, where)
    q, c1, c2 = _controller_ratio(doc, where)
    notes: list[str] = []
    c0, equivalent_to = _c0(doc, path, chain, mode, c1, c2, testbed, where, notes)
    _check_runnable(where, c0, c1, c2, q, equivalent_to, prewarp)
    return ControllerDesign(
        path=path.resolve(), name=name, description=description, mode=mode, testbed=testbed,
        c0=c0, c1=c1, c2=c2, q=q, saturation_coarse_in_oz=sat_coarse,
        saturation_fine_in_oz=sat_fine, anti_windup=anti_windup, friction=friction,
        outer_loop_gain_per_s=kp,
        prewarp_hz=prewarp, c0_equivalent_to=equivalent_to, c0_order=c0.order,
        notes=tuple(notes), text=text)


def _saturation(doc: dict, where: str) -> tuple[float, float, str]:
    """(coarse limit, fine limit, anti-windup) of the [saturation] table."""
    sat = _table(doc, "saturation", where)
    _no_unknown(sat, _SATURATION_KEYS, where, "[saturation]")
    sat_coarse = _number(sat, "coarse_in_oz", where, "saturation", lo=0.0,
                         allowed="a torque >= 0 in in-oz")
    sat_fine = _number(sat, "fine_in_oz", where, "saturation", lo=0.0,
                       allowed="a torque >= 0 in in-oz")
    anti_windup = sat.get("anti_windup", "none")
    if anti_windup not in ANTI_WINDUP:
        raise DesignError(f"{where}: saturation.anti_windup must be one of "
                          f"{', '.join(repr(k) for k in ANTI_WINDUP)}, got {anti_windup!r}")
    return sat_coarse, sat_fine, anti_windup


def _controller_ratio(doc: dict, where: str
                      ) -> tuple[TransferFunction | None, TransferFunction, TransferFunction]:
    """(Q or None, c1, c2): from [Q] (c1 = Q, c2 = 1) or from [c1] and [c2]."""
    if "Q" in doc and ("c1" in doc or "c2" in doc):
        raise DesignError(f"{where}: give either [Q] (c1' = Q, c2' = 1) or both [c1] and [c2], "
                          f"not both")
    if "Q" in doc:
        q = _transfer_function(doc, "Q", where)
        return q, q, TransferFunction.constant(1.0)
    if "c1" in doc and "c2" in doc:
        return None, _transfer_function(doc, "c1", where), _transfer_function(doc, "c2", where)
    raise DesignError(f"{where}: missing [Q] (the controller ratio; c1' = Q, c2' = 1) "
                      f"or both [c1] and [c2]")


def _c0(doc: dict, path: Path, chain: tuple[Path, ...], mode: str, c1: TransferFunction,
        c2: TransferFunction, testbed, where: str,
        notes: list[str]) -> tuple[TransferFunction, Path | None]:
    """(c0, the design it is output-equivalent to or None): [c0] as written, or made
    equivalent to another design's controller (what that did goes to `notes`)."""
    raw_c0 = _table(doc, "c0", where)
    if "equivalent_to" not in raw_c0:
        return _transfer_function(doc, "c0", where), None
    _no_unknown(raw_c0, _EQUIVALENT_KEYS, where, "[c0] with equivalent_to")
    equivalent_to = raw_c0["equivalent_to"]
    if not isinstance(equivalent_to, Path):
        raise DesignError(f"{where}: c0.equivalent_to must be the path of a design file "
                          f"(text), got {equivalent_to!r}")
    tol = _number(raw_c0, "cancel_tolerance", where, "c0", required=False, lo=0.0, hi=0.1,
                  allowed="a relative tolerance between 0 and 0.1")
    tol = CANCEL_TOLERANCE if tol is None else tol
    partner = _partner(equivalent_to, path, chain, mode)
    c0, cancelled = output_equivalent_c0(partner, c1, c2, testbed, tol, where)
    notes.append(f"c0 is output-equivalent to {equivalent_to.name} on {testbed.name}: order "
                 f"{c0.order} ({len(c0.zeros)} zeros, {len(c0.poles)} poles) after "
                 f"cancelling {cancelled} pole/zero pair(s) within {tol:g}")
    if partner.testbed.path != testbed.path:
        notes.append(f"{equivalent_to.name} was designed for {partner.testbed.path.name}; the "
                     f"equivalence uses this design's testbed {testbed.path.name}")
    return c0, equivalent_to


def _check_runnable(where: str, c0: TransferFunction, c1: TransferFunction,
                    c2: TransferFunction, q: TransferFunction | None,
                    equivalent_to: Path | None, prewarp: float | None) -> None:
    """Raise DesignError unless each filter discretises and is proper."""
    labels = {"c0": "[c0]" + (f" (output-equivalent to {equivalent_to.name})" if equivalent_to else ""),
              "c1": "[Q] (c1' = Q)" if q is not None else "[c1]", "c2": "[c2]"}
    problems = [_singular_text(labels[label], kind, r, CONTROL_RATE_HZ, prewarp)
                for label, tf in (("c0", c0), ("c1", c1), ("c2", c2))
                for kind, r in singular_factors(tf, CONTROL_RATE_HZ, prewarp)]
    if problems:
        raise DesignError(f"{where}: cannot be discretised: " + "; ".join(problems))
    for label, tf in (("c0", c0), ("c1", c1), ("c2", c2)):
        if len(tf.zeros) > len(tf.poles):
            raise DesignError(f"{where}: {label} has {len(tf.zeros)} zeros and {len(tf.poles)} "
                              f"poles: it must be proper (no more zeros than poles) to run as "
                              f"a filter; add roll-off poles")


def _merged_document(path: Path, chain: tuple[Path, ...]) -> tuple[dict, str]:
    """The file's tables over its `base` file's (recursively); file paths made absolute."""
    resolved = path.resolve()
    if resolved in chain:
        loop = " -> ".join(p.name for p in (*chain[chain.index(resolved):], resolved))
        raise DesignError(f"{path}: design files refer to each other in a cycle ({loop})")
    doc, text = read_toml(path, DesignError, "design file not found")
    unknown = set(doc) - _TOP_KEYS
    if unknown:
        raise DesignError(f"{path}: unknown key(s) or table(s) {sorted(unknown)}; allowed: "
                          f"{', '.join(sorted(_TOP_KEYS))}")
    for table, key in _PATH_FIELDS:
        if isinstance(doc.get(table), dict) and key in doc[table]:
            value = doc[table][key]
            if not isinstance(value, str):
                raise DesignError(f"{path}: {table}.{key} must be a file path (text), got {value!r}")
            doc[table][key] = (path.parent / value).resolve()
    if "base" not in doc:
        return doc, text
    base_name = doc.pop("base")
    if not isinstance(base_name, str):
        raise DesignError(f"{path}: base must be the path of a design file (text), got {base_name!r}")
    try:
        base, _ = _merged_document(path.parent / base_name, (*chain, resolved))
    except DesignError as exc:
        raise DesignError(f"{path}: base '{base_name}': {exc}") from None
    if any(k in doc for k in ("Q", "c1", "c2")):
        for k in ("Q", "c1", "c2"):
            base.pop(k, None)
    for key, value in doc.items():
        if key in TRANSFER_FUNCTIONS or not (isinstance(value, dict) and isinstance(base.get(key), dict)):
            base[key] = value
        else:
            base[key] = {**base[key], **value}
    return base, text


def _partner(partner_path: Path, path: Path, chain: tuple[Path, ...], mode: str) -> ControllerDesign:
    try:
        partner = _load(partner_path, (*chain, path.resolve()))
    except DesignError as exc:
        raise DesignError(f"{path}: c0.equivalent_to '{partner_path.name}': {exc}") from None
    if partner.mode != mode:
        raise DesignError(f"{path}: c0.equivalent_to names a design for {partner.mode} mode "
                          f"({partner_path.name}); it must be for {mode} mode like this one")
    return partner


def _testbed(d: dict, where: str):
    from ..plant.testbed import load_testbed

    if "testbed" not in d:
        raise DesignError(f"{where}: design.testbed is missing; give the testbed file the design "
                          f"is for, relative to this file (e.g. \"../testbeds/relative_2dof.toml\")")
    try:
        return load_testbed(d["testbed"])
    except GroundStationError as exc:
        raise DesignError(f"{where}: design.testbed: {exc}") from None


def _friction(doc: dict, where: str) -> FrictionCompensation:
    f = _table(doc, "friction_compensation", where)
    _no_unknown(f, _FRICTION_KEYS, where, "[friction_compensation]")
    if "enabled" not in f:
        raise DesignError(f"{where}: friction_compensation.enabled is missing; allowed: true, false")
    enabled = f["enabled"]
    if not isinstance(enabled, bool):
        raise DesignError(f"{where}: friction_compensation.enabled = {enabled!r}; allowed: true, false")
    model = _text(f, "model", where, "friction_compensation", required=False)
    if model is not None and model not in FRICTION_MODEL_CODES:
        raise DesignError(f"{where}: friction_compensation.model = {model!r}; allowed: "
                          f"{', '.join(FRICTION_MODEL_CODES)}")
    positive = dict(required=False, lo=0.0, open_lo=True)
    sigma = _number(f, "sigma_in_oz_per_rad", where, "friction_compensation",
                    allowed="a rest stiffness > 0 in in-oz/rad", **positive)
    coulomb = _number(f, "coulomb_torque_in_oz", where, "friction_compensation",
                      allowed="a torque > 0 in in-oz", **positive)
    alpha = _number(f, "alpha", where, "friction_compensation", allowed="a shape factor > 0",
                    **positive)
    table = f.get("slope_table")
    xs = ys = None
    if table is not None:
        from ..plant.slope_table import load_slope_table

        try:
            x, y = load_slope_table(table)
        except GroundStationError as exc:
            raise DesignError(f"{where}: friction_compensation.slope_table: {exc}") from None
        xs, ys = tuple(float(v) for v in x), tuple(float(v) for v in y)
    return FrictionCompensation(enabled, model, sigma, coulomb, alpha, table, xs, ys)


def _transfer_function(doc: dict, key: str, where: str) -> TransferFunction:
    raw = _table(doc, key, where)
    _no_unknown(raw, _TF_KEYS, where, f"[{key}]" + (" (or equivalent_to)" if key == "c0" else ""))
    gain = _number(raw, "gain", where, key, allowed="a finite number (the factors are monic)")
    factors = {}
    for side in ("numerator", "denominator"):
        items = raw.get(side, [])
        if not isinstance(items, list):
            raise DesignError(f"{where}: {key}.{side} must be a list of factors [a] = (s+a) or "
                              f"[b, c] = (s^2+b*s+c), got {items!r}")
        for i, f in enumerate(items):
            if (not isinstance(f, list) or len(f) not in (1, 2)
                    or not all(_is_number(v) and math.isfinite(v) for v in f)):
                raise DesignError(f"{where}: {key}.{side}[{i}] = {f!r}; allowed: [a] for (s+a) "
                                  f"or [b, c] for (s^2+b*s+c), finite numbers")
        factors[side] = [[float(v) for v in f] for f in items]
    tf = TransferFunction.from_factors(gain, factors["numerator"], factors["denominator"])
    return _snap_integrators(tf)


# --- small field readers ----------------------------------------------------------------
def _table(doc: dict, key: str, where: str) -> dict:
    if key not in doc:
        raise DesignError(f"{where}: missing table [{key}]")
    if not isinstance(doc[key], dict):
        raise DesignError(f"{where}: {key} must be a table [{key}], got {doc[key]!r}")
    return doc[key]


def _no_unknown(table: dict, known: set[str], where: str, label: str) -> None:
    unknown = set(table) - known
    if unknown:
        raise DesignError(f"{where}: {label} has unknown key(s) {sorted(unknown)}; allowed: "
                          f"{', '.join(sorted(known))}")


def _text(table: dict, key: str, where: str, section: str, required: bool = True) -> str | None:
    if key not in table:
        if required:
            raise DesignError(f"{where}: {section}.{key} is missing (text)")
        return None
    if not isinstance(table[key], str):
        raise DesignError(f"{where}: {section}.{key} must be text, got {table[key]!r}")
    return table[key]


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(table: dict, key: str, where: str, section: str, *, required: bool = True,
            lo: float = -math.inf, hi: float = math.inf, open_lo: bool = False,
            open_hi: bool = False, allowed: str = "a number") -> float | None:
    if key not in table:
        if required:
            raise DesignError(f"{where}: {section}.{key} is missing; allowed: {allowed}")
        return None
    v = table[key]
    if not _is_number(v) or not math.isfinite(v):
        raise DesignError(f"{where}: {section}.{key} = {v!r}; allowed: {allowed} (finite)")
    if v < lo or v > hi or (open_lo and v == lo) or (open_hi and v == hi):
        raise DesignError(f"{where}: {section}.{key} = {v!r}; allowed: {allowed}")
    return float(v)


# ======================================================================================
# the parameter table
# ======================================================================================
def table_values(design: ControllerDesign, base: Mapping[str, Any] | None = None,
                 dictionary: Dictionary | None = None) -> dict[str, Any]:
    """A complete parameter table: the design's mode's c0/c1/c2, outer-loop gain,
    saturations and friction-compensation settings over `base` (e.g. the device's
    current table) or, without one, the dictionary's defaults."""
    d = dictionary or load_dictionary()
    values = {k: _copy(v) for k, v in default_values(d).items()}   # never alias the defaults
    if base is not None:
        unknown = set(base) - set(values)
        if unknown:
            raise DesignError(f"base table has parameters this dictionary does not know: "
                              f"{sorted(unknown)}")
        values.update({k: _copy(v) for k, v in base.items()})
    shapes = {p.name: p.shape for p in d.parameters}
    for name, cascade in discretise_design(design, d.control_rate_hz).items():
        key = f"{design.mode}_{name}"
        values[key] = pad_sections(cascade.sos, shapes[key][0], f"{design.path.name}: {name}").tolist()
    if design.outer_loop_gain_per_s is not None:
        values["outer_loop_gain"] = design.outer_loop_gain_per_s
    values["saturation_coarse"] = design.saturation_coarse_in_oz
    values["saturation_fine"] = design.saturation_fine_in_oz
    values["anti_windup"] = ANTI_WINDUP[design.anti_windup]
    values.update(_friction_values(design, shapes["friction_comp_table_x"][0]))
    return values


def _friction_values(design: ControllerDesign, table_rows: int) -> dict[str, Any]:
    fc = design.friction
    out: dict[str, Any] = {"friction_comp_enabled": int(fc.enabled)}
    if fc.model is not None:
        out["friction_comp_model"] = FRICTION_MODEL_CODES[fc.model]
    for key, value in (("friction_comp_sigma", fc.sigma_in_oz_per_rad),
                       ("friction_comp_coulomb", fc.coulomb_torque_in_oz),
                       ("friction_comp_alpha", fc.alpha)):
        if value is not None:
            out[key] = value
    if fc.slope_x is not None:
        n = len(fc.slope_x)
        if n > table_rows:
            raise DesignError(f"{design.path}: friction_compensation.slope_table has {n} points; "
                              f"the parameter table holds {table_rows}")
        # unused points repeat the end of the branch (x = 2, slope 0), like the defaults
        out["friction_comp_table_points"] = n
        out["friction_comp_table_x"] = list(fc.slope_x) + [2.0] * (table_rows - n)
        out["friction_comp_table_slope"] = list(fc.slope_ratio) + [0.0] * (table_rows - n)
    return out


def _copy(v):
    return np.asarray(v).tolist() if isinstance(v, (list, tuple, np.ndarray)) else v
