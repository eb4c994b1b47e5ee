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

Discretisation: the bilinear (Tustin) map at the control rate, optionally pre-warped,
into second-order sections in the table's row format b0 b1 b2 a0 a1 a2 (a0 = 1),
padded with identity rows.  All angular frequencies are rad/s, all frequencies named
`_hz` are Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from scipy import signal

from ..dictionary import Dictionary, load_dictionary
from ..errors import GroundStationError
from ..tomlfile import read_toml
from .table import default_values

CONTROL_RATE_HZ = 1200.0          # the controller's loop rate (reference §2)
MATCH_BAND_HZ = 100.0             # discrete and continuous responses are compared up to here
CANCEL_TOLERANCE = 1e-6           # relative distance at which a pole and a zero cancel
INTEGRATOR_TOLERANCE = 1e-9       # rad/s: a pole closer to s = 0 than this is an integrator
SINGULAR_TOLERANCE = 1e-6         # relative distance from s = 2 fs' at which a root is refused
GAIN_REFERENCE_HZ = 10.0          # sections share the gain equally at this frequency
MODES = ("relative", "inertial")
FRICTION_MODEL_CODES = {"SFM": 0, "DHM": 1, "DB-SFM": 2, "DB-DHM": 3}   # friction_comp_model
TRANSFER_FUNCTIONS = ("c0", "Q", "c1", "c2")


class DesignError(GroundStationError):
    """A controller design file is missing, malformed or inconsistent (names file and field)."""


# ======================================================================================
# continuous transfer functions
# ======================================================================================
@dataclass(frozen=True, eq=False)
class TransferFunction:
    """A continuous transfer function gain * prod(s - zeros) / prod(s - poles), rad/s."""

    zeros: np.ndarray             # complex, conjugate pairs complete
    poles: np.ndarray
    gain: float

    @staticmethod
    def from_factors(gain: float, numerator=(), denominator=()) -> "TransferFunction":
        return TransferFunction(_roots_of_factors(numerator), _roots_of_factors(denominator),
                                float(gain))

    @staticmethod
    def constant(gain: float) -> "TransferFunction":
        return TransferFunction(np.zeros(0, complex), np.zeros(0, complex), float(gain))

    @property
    def order(self) -> int:
        return max(len(self.zeros), len(self.poles))

    @property
    def integrators(self) -> int:
        """Number of poles at s = 0 (they map to z = 1 and are allowed on the device)."""
        return int(np.sum(self.poles == 0))

    def response(self, s: np.ndarray) -> np.ndarray:
        """Complex value at the points s (rad/s), evaluated factor by factor."""
        s = np.asarray(s, dtype=complex)
        out = np.full(s.shape, self.gain, dtype=complex)
        for z in self.zeros:
            out = out * (s - z)
        for p in self.poles:
            out = out / (s - p)
        return out

    def frequency_response(self, freqs_hz: np.ndarray) -> np.ndarray:
        return self.response(2j * np.pi * np.asarray(freqs_hz, dtype=float))

    def text(self) -> str:
        """Factored form as the reference writes it: 30801(s+36.28)(s^2+25.92s+8.61e+04) / [...]"""
        num, den = _factor_text(self.zeros), _factor_text(self.poles)
        out = f"{self.gain:.6g}{num}"
        if den:
            out += f" / [{den}]" if den.count("(") + den.count("s") > 1 else f" / {den}"
        return out


def _roots_of_factors(factors) -> np.ndarray:
    roots: list[complex] = []
    for f in factors:
        if len(f) == 1:
            roots.append(complex(-f[0]))
        else:
            b, c = f
            disc = b * b - 4.0 * c
            if disc >= 0:            # two real roots; the stable form avoids cancellation
                q = -0.5 * (b + math.copysign(math.sqrt(disc), b if b else 1.0))
                roots += [complex(q), complex(c / q) if q else 0j]
            else:
                re, im = -0.5 * b, 0.5 * math.sqrt(-disc)
                roots += [complex(re, im), complex(re, -im)]
    return np.array(roots, dtype=complex)


def _factor_text(roots: np.ndarray) -> str:
    """(s+a) and (s^2+bs+c) factors in the order of the roots, repeats as powers."""
    factors: list[str] = []
    done = np.zeros(len(roots), bool)
    for i, r in enumerate(roots):
        if done[i]:
            continue
        done[i] = True
        partner = None
        if r.imag != 0:
            partner = next((j for j in range(len(roots)) if not done[j] and roots[j] == np.conj(r)), None)
        if partner is not None:
            done[partner] = True
            factors.append(f"(s^2{_signed(-2 * r.real)}s{_signed(abs(r) ** 2)})")
        else:
            factors.append("s" if r == 0 else f"(s{_signed(-r.real)})")
    out, i = "", 0
    while i < len(factors):
        n = 1
        while i + n < len(factors) and factors[i + n] == factors[i]:
            n += 1
        out += factors[i] + (f"^{n}" if n > 1 else "")
        i += n
    return out


def _signed(x: float) -> str:
    return f"{'+' if x >= 0 else '-'}{abs(x):.6g}"


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
_SATURATION_KEYS = {"coarse_in_oz", "fine_in_oz"}
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
    if mode == "inertial" and not testbed.inertial:
        raise DesignError(f"{where}: design.mode = \"inertial\" needs a testbed with a gyro "
                          f"(setup = \"inertial\"); {testbed.path.name} has setup = "
                          f"\"{testbed.setup}\"")
    prewarp = _number(d, "prewarp_hz", where, "design", required=False,
                      lo=0.0, hi=CONTROL_RATE_HZ / 2, open_lo=True, open_hi=True,
                      allowed=f"a frequency in Hz between 0 and {CONTROL_RATE_HZ / 2:g} (Nyquist)")
    kp = _number(d, "outer_loop_gain_per_s", where, "design", required=(mode == "inertial"),
                 lo=0.0, allowed="a gain >= 0 in 1/s (K_p of the outer position loop)")

    sat = _table(doc, "saturation", where)
    _no_unknown(sat, _SATURATION_KEYS, where, "[saturation]")
    sat_coarse = _number(sat, "coarse_in_oz", where, "saturation", lo=0.0,
                         allowed="a torque >= 0 in in-oz")
    sat_fine = _number(sat, "fine_in_oz", where, "saturation", lo=0.0,
                       allowed="a torque >= 0 in in-oz")
    friction = _friction(doc, where)

    notes: list[str] = []
    if "Q" in doc and ("c1" in doc or "c2" in doc):
        raise DesignError(f"{where}: give either [Q] (c1' = Q, c2' = 1) or both [c1] and [c2], "
                          f"not both")
    if "Q" in doc:
        q = _transfer_function(doc, "Q", where)
        c1, c2 = q, TransferFunction.constant(1.0)
    elif "c1" in doc and "c2" in doc:
        q = None
        c1, c2 = _transfer_function(doc, "c1", where), _transfer_function(doc, "c2", where)
    else:
        raise DesignError(f"{where}: missing [Q] (the controller ratio; c1' = Q, c2' = 1) "
                          f"or both [c1] and [c2]")

    raw_c0 = _table(doc, "c0", where)
    equivalent_to = None
    if "equivalent_to" in raw_c0:
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
    else:
        c0 = _transfer_function(doc, "c0", where)
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
    return ControllerDesign(
        path=path.resolve(), name=name, description=description, mode=mode, testbed=testbed,
        c0=c0, c1=c1, c2=c2, q=q, saturation_coarse_in_oz=sat_coarse,
        saturation_fine_in_oz=sat_fine, friction=friction, outer_loop_gain_per_s=kp,
        prewarp_hz=prewarp, c0_equivalent_to=equivalent_to, c0_order=c0.order,
        notes=tuple(notes), text=text)


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


def _snap_integrators(tf: TransferFunction) -> TransferFunction:
    """Poles within INTEGRATOR_TOLERANCE of s = 0 become exactly 0 (so they map to z = 1)."""
    poles = np.where(np.abs(tf.poles) < INTEGRATOR_TOLERANCE, 0j, tf.poles)
    zeros = np.where(np.abs(tf.zeros) < INTEGRATOR_TOLERANCE, 0j, tf.zeros)
    return TransferFunction(zeros, poles, tf.gain)


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
# output-equivalent c0
# ======================================================================================
def output_equivalent_c0(partner: ControllerDesign, c1: TransferFunction, c2: TransferFunction,
                         testbed, rtol: float = CANCEL_TOLERANCE,
                         where: str = "") -> tuple[TransferFunction, int]:
    """c0_b = c0_a (c1_a g1 + c2_a g2) / (c1_b g1 + c2_b g2): the same loop gain as the partner.

    With c2' = 1 this is the reference's c0_a (Q_a g1 + g2) / (Q_b g1 + g2).  g1, g2 are the
    testbed's angle outputs; for the inertial (rate) loop both carry the same factor s and
    gyro model, which cancel in the ratio.  Returns the new c0 and the number of pole/zero
    pairs cancelled.  The polynomials here are of low degree (<= 8); the roots are checked
    by comparing the two loop gains along the frequency axis."""
    from ..plant.model import plant_transfer_functions

    if not testbed.is_2dof:
        raise DesignError(f"{where}: c0.equivalent_to needs a 2-DOF testbed (two inputs g1, g2); "
                          f"{testbed.path.name} is {testbed.configuration}")
    (n1, d), (n2, _) = plant_transfer_functions(testbed)
    num_a, den_a = _path_sum(partner.c1, partner.c2, n1, n2)
    num_b, den_b = _path_sum(c1, c2, n1, n2)
    if not np.any(num_b):
        raise DesignError(f"{where}: c1' g1 + c2' g2 is identically zero; no c0 can match "
                          f"{partner.path.name}")
    zeros = np.concatenate([partner.c0.zeros, _roots(num_a), den_b])
    poles = np.concatenate([partner.c0.poles, den_a, _roots(num_b)])
    gain = partner.c0.gain * _lead(num_a) / _lead(num_b)
    zeros, poles, cancelled = cancel_common_roots(zeros, poles, rtol)
    c0 = _snap_integrators(TransferFunction(zeros, poles, gain))
    _check_same_loop(partner, c0, c1, c2, n1, n2, d, where)
    return c0, cancelled


def _path_sum(c1: TransferFunction, c2: TransferFunction, n1, n2) -> tuple[np.ndarray, np.ndarray]:
    """(numerator polynomial, denominator roots) of (c1' g1 + c2' g2) D."""
    num = np.polyadd(np.polymul(_poly(c1.zeros, c1.gain), np.polymul(_poly(c2.poles), n1)),
                     np.polymul(_poly(c2.zeros, c2.gain), np.polymul(_poly(c1.poles), n2)))
    return np.trim_zeros(num, "f"), np.concatenate([c1.poles, c2.poles])


def _poly(roots: np.ndarray, gain: float = 1.0) -> np.ndarray:
    return gain * np.real(np.poly(roots)) if len(roots) else np.array([gain])


def _roots(poly: np.ndarray) -> np.ndarray:
    return np.roots(poly).astype(complex)


def _lead(poly: np.ndarray) -> float:
    return float(np.trim_zeros(poly, "f")[0])


def cancel_common_roots(zeros: np.ndarray, poles: np.ndarray,
                        rtol: float = CANCEL_TOLERANCE) -> tuple[np.ndarray, np.ndarray, int]:
    """Drop pole/zero pairs closer than rtol*|root| (both within INTEGRATOR_TOLERANCE of 0
    also cancel).  Conjugate partners go together because they are equally close."""
    zeros, poles = list(zeros), list(poles)
    kept_zeros, cancelled = [], 0
    for z in zeros:
        best = None
        for i, p in enumerate(poles):
            gap = abs(z - p)
            if gap <= rtol * max(abs(z), abs(p)) or max(abs(z), abs(p)) < INTEGRATOR_TOLERANCE:
                if best is None or gap < abs(z - poles[best]):
                    best = i
        if best is None:
            kept_zeros.append(z)
        else:
            poles.pop(best)
            cancelled += 1
    return np.array(kept_zeros, complex), np.array(poles, complex), cancelled


def _check_same_loop(partner, c0, c1, c2, n1, n2, d, where) -> None:
    w = 2j * np.pi * np.logspace(-2, math.log10(CONTROL_RATE_HZ / 2), 200)
    g1, g2 = np.polyval(n1, w) / np.polyval(d, w), np.polyval(n2, w) / np.polyval(d, w)
    la = partner.c0.response(w) * (partner.c1.response(w) * g1 + partner.c2.response(w) * g2)
    lb = c0.response(w) * (c1.response(w) * g1 + c2.response(w) * g2)
    err = float(np.max(np.abs(lb / la - 1)))
    if not err < 1e-6:
        raise DesignError(f"{where}: c0.equivalent_to: the computed c0 reproduces "
                          f"{partner.path.name}'s loop gain only to {err:.2g} (relative); the "
                          f"polynomials are too ill-conditioned, write c0 out instead")


# ======================================================================================
# discretisation
# ======================================================================================
@dataclass(frozen=True, eq=False)
class DiscreteCascade:
    """One controller cascade as the device runs it (unpadded rows b0 b1 b2 a0 a1 a2)."""

    name: str
    sos: np.ndarray
    integrators: int                # poles at z = 1 that are integrators by design

    @property
    def sections(self) -> int:
        return int(self.sos.shape[0])


def bilinear_rate_hz(rate_hz: float, prewarp_hz: float | None) -> float:
    """The rate to give the plain bilinear map so that it is exact at prewarp_hz.

    s = 2 fs' (z - 1)/(z + 1) maps j w_p to e^(j w_p T) exactly when
    fs' = w_p / (2 tan(w_p T / 2))."""
    if not prewarp_hz:
        return rate_hz
    wp = 2 * math.pi * prewarp_hz
    return wp / (2 * math.tan(wp / (2 * rate_hz)))


def bilinear_singular_point(rate_hz: float = CONTROL_RATE_HZ, prewarp_hz: float | None = None) -> float:
    """The s (rad/s) where the bilinear map this tool uses is singular.

    z = (1 + s/(2 fs'))/(1 - s/(2 fs')) divides by zero at s = 2 fs', with fs' the rate
    given to the map: 2 x 1200 = 2400 rad/s for plain Tustin, w_p / tan(w_p T / 2) when
    pre-warped at f_p (2388.03 rad/s at 46.70 Hz)."""
    return 2.0 * bilinear_rate_hz(rate_hz, prewarp_hz)


def singular_factors(tf: TransferFunction, rate_hz: float = CONTROL_RATE_HZ,
                     prewarp_hz: float | None = None) -> list[tuple[str, complex]]:
    """("zero" | "pole", root) for every root of `tf` at the bilinear map's singular point
    (within SINGULAR_TOLERANCE, relative): a pole there maps to z = infinity, a zero (an
    all-pass or non-minimum-phase factor) to a zero at infinity that leaves the discrete
    filter with a gain of zero.  Neither has a discrete equivalent."""
    point = bilinear_singular_point(rate_hz, prewarp_hz)
    out = []
    for kind, roots in (("zero", tf.zeros), ("pole", tf.poles)):
        for r in roots:
            if abs(complex(r) - point) <= SINGULAR_TOLERANCE * point:
                out.append((kind, complex(r)))
    return out


def _singular_text(label: str, kind: str, root: complex, rate_hz: float,
                   prewarp_hz: float | None) -> str:
    point = bilinear_singular_point(rate_hz, prewarp_hz)
    fs = point / 2
    how = (f"pre-warped at {prewarp_hz:g} Hz, the map uses fs' = {fs:.10g} Hz"
           if prewarp_hz else f"plain Tustin at fs = {rate_hz:g} Hz")
    side = "numerator" if kind == "zero" else "denominator"
    effect = ("it would map to a pole at z = infinity (scipy cannot even form the sections)"
              if kind == "pole" else
              "it would map to a zero at z = infinity: the discrete filter loses that factor "
              "and its gain becomes zero")
    return (f"{label}: the {side} factor {_factor_text(np.array([root]))} puts a {kind} at "
            f"s = {root.real:.10g} rad/s, exactly where the bilinear map z = (1 + sT/2)/(1 - sT/2) "
            f"is singular, s = 2/T = 2 fs' = {point:.10g} rad/s ({how}); {effect}.  Move it "
            f"off that point or change prewarp_hz")


def discretise(tf: TransferFunction, rate_hz: float = CONTROL_RATE_HZ,
               prewarp_hz: float | None = None, name: str = "transfer function") -> np.ndarray:
    """Tustin (optionally pre-warped) -> second-order sections, gain shared across them.
    A root at the map's singular point raises DesignError naming it."""
    bad = singular_factors(tf, rate_hz, prewarp_hz)
    if bad:
        raise DesignError("; ".join(_singular_text(name, kind, r, rate_hz, prewarp_hz) for kind, r in bad))
    zd, pd, kd = signal.bilinear_zpk(tf.zeros, tf.poles, tf.gain, bilinear_rate_hz(rate_hz, prewarp_hz))
    # s = 0 maps to (2fs + 0)/(2fs - 0) = 1 exactly, so an integrator stays on z = 1
    sos = np.atleast_2d(signal.zpk2sos(zd, pd, kd))
    return _share_gain(sos, rate_hz)


def _share_gain(sos: np.ndarray, rate_hz: float) -> np.ndarray:
    """Give every section the same magnitude at GAIN_REFERENCE_HZ (zpk2sos puts the whole
    gain into the first section).  In double precision this changes no result, but the
    sections' internal signals stay of comparable size and each row reads as a unit-size
    filter.  Left alone if a section vanishes or blows up at the reference frequency."""
    if sos.shape[0] < 2:
        return sos
    mags = np.abs(section_responses(sos, np.exp(2j * np.pi * GAIN_REFERENCE_HZ / rate_hz)))
    if not np.all(np.isfinite(mags)) or np.any(mags == 0):
        return sos
    share = np.exp(np.mean(np.log(mags)))
    out = sos.copy()
    out[:, :3] *= (share / mags)[:, None]
    return out


def section_responses(sos: np.ndarray, z) -> np.ndarray:
    """(b0 z^2 + b1 z + b2) / (a0 z^2 + a1 z + a2) of every row at the points z: shape (rows, *z)."""
    sos = np.asarray(sos, dtype=float)
    z = np.asarray(z, dtype=complex)
    b0, b1, b2, a0, a1, a2 = (sos[:, j].reshape((-1,) + (1,) * z.ndim) for j in range(6))
    return ((b0 * z + b1) * z + b2) / ((a0 * z + a1) * z + a2)


def sos_response(sos: np.ndarray, z) -> np.ndarray:
    """The cascade's value at the points z (e^(j w T) for a frequency response)."""
    return np.prod(section_responses(sos, z), axis=0)


def pad_sections(sos: np.ndarray, rows: int, name: str = "cascade") -> np.ndarray:
    """Fill up to `rows` with identity sections [1, 0, 0, 1, 0, 0]."""
    if sos.shape[0] > rows:
        raise DesignError(f"{name} needs {sos.shape[0]} second-order sections; the parameter "
                          f"table holds {rows} (reduce the order to at most {2 * rows})")
    out = np.tile([1.0, 0.0, 0.0, 1.0, 0.0, 0.0], (rows, 1))
    out[:sos.shape[0]] = sos
    return out


def discretise_design(design: ControllerDesign, rate_hz: float = CONTROL_RATE_HZ) -> dict[str, DiscreteCascade]:
    """c0, c1, c2 of the design as unpadded discrete cascades."""
    return {name: DiscreteCascade(name, discretise(tf, rate_hz, design.prewarp_hz, name), tf.integrators)
            for name, tf in design.cascades.items()}


# --- how well the discrete cascades follow the continuous ones -------------------------
@dataclass(frozen=True)
class ResponseError:
    """Worst deviation of a discrete response from its continuous design below a band."""

    magnitude_pct: float          # max | |H_d| / |H_c| - 1 | * 100
    phase_deg: float              # max | angle(H_d / H_c) |
    magnitude_at_hz: float
    phase_at_hz: float

    def within(self, magnitude_pct: float = 1.0, phase_deg: float = 1.0) -> bool:
        return self.magnitude_pct <= magnitude_pct and self.phase_deg <= phase_deg

    def text(self) -> str:
        return (f"{self.magnitude_pct:.2f} % (at {self.magnitude_at_hz:.3g} Hz) / "
                f"{self.phase_deg:.2f} deg (at {self.phase_at_hz:.3g} Hz)")


def match_frequencies(band_hz: float = MATCH_BAND_HZ) -> np.ndarray:
    """A grid fine enough for the lightly damped notches (a few Hz wide) of the designs."""
    return np.unique(np.concatenate([np.logspace(-2, math.log10(band_hz), 300),
                                     np.linspace(band_hz / 2000, band_hz, 2000)]))


def response_error(ratio: np.ndarray, freqs_hz: np.ndarray) -> ResponseError:
    """ResponseError of H_d/H_c given on freqs_hz."""
    mag = np.abs(np.abs(ratio) - 1.0) * 100.0
    ph = np.abs(np.angle(ratio, deg=True))
    i, j = int(np.argmax(mag)), int(np.argmax(ph))
    return ResponseError(float(mag[i]), float(ph[j]), float(freqs_hz[i]), float(freqs_hz[j]))


def cascade_match(tf: TransferFunction, sos: np.ndarray, rate_hz: float = CONTROL_RATE_HZ,
                  band_hz: float = MATCH_BAND_HZ) -> ResponseError:
    """Discrete cascade vs its continuous transfer function, 0 < f <= band_hz."""
    f = match_frequencies(band_hz)
    ratio = _ratio(sos_response(sos, np.exp(2j * np.pi * f / rate_hz)), tf.frequency_response(f))
    return response_error(ratio, f)


def _ratio(discrete: np.ndarray, continuous: np.ndarray) -> np.ndarray:
    """discrete / continuous, 1 where both are equal (a zero-gain cascade matches exactly)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(discrete == continuous, 1.0 + 0j, discrete / continuous)


@dataclass(frozen=True)
class DiscretisationMatch:
    """Discrete vs continuous controller below `band_hz`: each cascade, and the two paths
    the device computes from the error, e -> u1 = c0 c1' and e -> u2 = c0 c2'."""

    band_hz: float
    rate_hz: float
    prewarp_hz: float | None
    warp_pct: float                          # frequency warp of the map at band_hz (%)
    cascades: dict[str, ResponseError]
    paths: dict[str, ResponseError]
    closed_loop: ResponseError | None = None  # sensitivity 1/(1+L), filled in by loop.validate

    @property
    def worst(self) -> ResponseError:
        """The worst magnitude and the worst phase error over the two paths."""
        m = max(self.paths.values(), key=lambda r: r.magnitude_pct)
        p = max(self.paths.values(), key=lambda r: r.phase_deg)
        return ResponseError(m.magnitude_pct, p.phase_deg, m.magnitude_at_hz, p.phase_at_hz)


def discretisation_match(design: ControllerDesign, cascades: Mapping[str, np.ndarray] | None = None,
                         rate_hz: float = CONTROL_RATE_HZ,
                         band_hz: float = MATCH_BAND_HZ) -> DiscretisationMatch:
    """How closely the discrete cascades (default: the design's own discretisation; or the
    rows of a table, identity padding included) follow the continuous design."""
    if cascades is None:
        cascades = {k: c.sos for k, c in discretise_design(design, rate_hz).items()}
    f = match_frequencies(band_hz)
    z = np.exp(2j * np.pi * f / rate_hz)
    ratio = {k: _ratio(sos_response(cascades[k], z), tf.frequency_response(f))
             for k, tf in design.cascades.items()}
    return DiscretisationMatch(
        band_hz, rate_hz, design.prewarp_hz, warp_pct(band_hz, rate_hz, design.prewarp_hz),
        cascades={k: response_error(r, f) for k, r in ratio.items()},
        paths={"e->u1": response_error(ratio["c0"] * ratio["c1"], f),
               "e->u2": response_error(ratio["c0"] * ratio["c2"], f)})


def warp_pct(f_hz: float, rate_hz: float = CONTROL_RATE_HZ, prewarp_hz: float | None = None) -> float:
    """How much faster (%) the bilinear map runs the continuous response at f_hz: the
    discrete response at f is the continuous one at f (1 + warp/100)."""
    fs = bilinear_rate_hz(rate_hz, prewarp_hz)
    w = 2 * math.pi * f_hz
    return (2 * fs * math.tan(w / (2 * rate_hz)) / w - 1.0) * 100.0


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
