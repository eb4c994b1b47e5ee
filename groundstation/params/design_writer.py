"""A controller design written back as a design file (`profiles/controllers/*.toml`).

The design workbench edits a design's transfer functions factor by factor and saves the
result in the format design_file.load_design reads: a gain times monic factors, [a] for
(s + a), [b, c] for (s^2 + b s + c), [0] for s.  This module is the Qt-free half of that:

- `Factored`: one transfer function as the file writes it (gain, numerator and
  denominator factors), to and from a TransferFunction (`factored`: real roots become
  [a], conjugate pairs [b, c]);
- `controller_problems`: what load_design refuses in a controller (a root at the
  bilinear map's singular point, more zeros than poles), so an edit is refused at once
  instead of when the file is read back;
- `design_text` / `write_design`: the whole file.  The file stands alone (no `base`);
  paths (testbed, c0.equivalent_to, the slope table) are written relative to the new
  file's folder.  c0 is written as `equivalent_to` when the design's c0 is
  output-equivalent to another design file, otherwise as its factors.  `write_design`
  reads the file back with load_design and refuses to keep it unless every transfer
  function it gives matches the design's (`transfer_function_mismatch`).

Numbers are written with 15 significant digits, which drops the last-bit noise of
factors recomputed from roots (86099.99999999999 -> 86100.0) and changes a transfer
function's value by less than 1e-14, relative.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.kinds import Setup
from ..core.tomlfile import relative_path, toml_number, toml_string
from .design_file import ControllerDesign, load_design
from .discretise import _singular_text, singular_factors
from .tf_algebra import (CANCEL_TOLERANCE, CONTROL_RATE_HZ, DesignError, TransferFunction,
                         _factor_text, _roots_of_factors, _snap_integrators)

#: a conjugate partner must lie this close to conj(root), relative to |root|
PAIR_TOLERANCE = 1e-9
#: a root whose imaginary part is this small, relative to |root|, is written as real
REAL_TOLERANCE = 1e-12
#: write_design's read-back check: the largest relative difference allowed on the grid
ROUND_TRIP_TOLERANCE = 1e-9

Factor = tuple[float, ...]          # (a,) for (s + a), (b, c) for (s^2 + b s + c)


@dataclass(frozen=True)
class Factored:
    """gain * prod(numerator factors) / prod(denominator factors), as a design file writes it."""

    gain: float
    numerator: tuple[Factor, ...] = ()
    denominator: tuple[Factor, ...] = ()

    def transfer_function(self) -> TransferFunction:
        tf = TransferFunction.from_factors(self.gain, [list(f) for f in self.numerator],
                                           [list(f) for f in self.denominator])
        return _snap_integrators(tf)

    def side(self, name: str) -> tuple[Factor, ...]:
        if name not in ("numerator", "denominator"):
            raise ValueError(f"side must be 'numerator' or 'denominator', got {name!r}")
        return getattr(self, name)


def factor_text(factor: Factor) -> str:
    """(s+a), (s^2+bs+c) or s, as the reference writes it."""
    return _factor_text(_roots_of_factors([list(factor)])) or "1"


def factored(tf: TransferFunction) -> Factored:
    """The factors of a transfer function, in the order of its roots."""
    return Factored(float(tf.gain), _factors_of_roots(tf.zeros), _factors_of_roots(tf.poles))


def _factors_of_roots(roots: np.ndarray) -> tuple[Factor, ...]:
    roots = np.asarray(roots, complex)
    used = np.zeros(len(roots), bool)
    out: list[Factor] = []
    for i, r in enumerate(roots):
        if used[i]:
            continue
        used[i] = True
        size = abs(r)
        if abs(r.imag) <= REAL_TOLERANCE * size:
            out.append((_clean(-r.real),))
            continue
        gaps = [(abs(roots[j] - np.conj(r)), j) for j in range(len(roots)) if not used[j]]
        gap, j = min(gaps, default=(math.inf, -1))
        if not gap <= PAIR_TOLERANCE * size:
            raise DesignError(f"the root {r:.6g} has no conjugate partner: a transfer function "
                              f"with real coefficients cannot be written as factors")
        used[j] = True
        out.append((_clean(-(r + roots[j]).real), _clean((r * roots[j]).real)))
    return tuple(out)


def _clean(x: float) -> float:
    """15 significant digits (see the module's docstring); -0.0 becomes 0.0."""
    return float(f"{float(x):.15g}") + 0.0


def controller_problems(design: ControllerDesign) -> list[str]:
    """What load_design would refuse in c0, c1', c2' of `design` (empty: none)."""
    labels = {"c0": "c0", "c1": "Q (c1' = Q)" if design.q is not None else "c1", "c2": "c2"}
    out = [_singular_text(labels[name], kind, r, CONTROL_RATE_HZ, design.prewarp_hz)
           for name, tf in design.cascades.items()
           for kind, r in singular_factors(tf, CONTROL_RATE_HZ, design.prewarp_hz)]
    for name, tf in design.cascades.items():
        if len(tf.zeros) > len(tf.poles):
            out.append(f"{labels[name]} has {len(tf.zeros)} zeros and {len(tf.poles)} poles: it "
                       f"must be proper (no more zeros than poles) to run as a filter")
    return out


# ======================================================================================
# the file
# ======================================================================================
def _number(x: float) -> str:
    return toml_number(x, DesignError)


def _factors_line(factors: tuple[Factor, ...]) -> str:
    return "[" + ", ".join("[" + ", ".join(_number(v) for v in f) + "]" for f in factors) + "]"


def _tf_lines(key: str, f: Factored, unit: str = "") -> list[str]:
    text = f.transfer_function().text()
    return [f"# {key} = {text}{('   ' + unit) if unit else ''}", f"[{key}]",
            f"gain = {_number(f.gain)}", f"numerator = {_factors_line(f.numerator)}",
            f"denominator = {_factors_line(f.denominator)}", ""]


def design_text(design: ControllerDesign, path: str | Path, *, name: str | None = None,
                description: str | None = None, c0_equivalent_to: Path | None = None,
                cancel_tolerance: float | None = None, source: str | None = None) -> str:
    """The design file for `design`, to be saved at `path` (paths are written relative to
    its folder).  c0 is written as `equivalent_to = c0_equivalent_to` when one is given
    (the caller states that c0 was computed that way, with cancel_tolerance or the
    default), otherwise as its factors.  `source` says in a comment where it came from."""
    folder = Path(path).resolve().parent
    if c0_equivalent_to is not None and Path(c0_equivalent_to).resolve() == Path(path).resolve():
        raise DesignError(f"{path}: c0 cannot be output-equivalent to the file itself; write "
                          f"its factors instead")
    lines = [f"# {name or design.name}: written by the ground station's design workbench"
             + (f" from {source}" if source else ""),
             "# Factors: [a] is (s + a), [b, c] is (s^2 + b s + c), [0] is s; `gain` multiplies them.",
             "", "[design]", f"name = {toml_string(name or design.name)}"]
    desc = design.description if description is None else description
    if desc:
        lines.append(f"description = {toml_string(desc)}")
    lines += [f"mode = {toml_string(design.mode)}",
              f"testbed = {toml_string(relative_path(design.testbed.path, folder))}"]
    if design.outer_loop_gain_per_s is not None:
        lines.append(f"outer_loop_gain_per_s = {_number(design.outer_loop_gain_per_s)}")
    if design.prewarp_hz is not None:
        lines.append(f"prewarp_hz = {_number(design.prewarp_hz)}")
    lines += ["", "[saturation]", f"coarse_in_oz = {_number(design.saturation_coarse_in_oz)}",
              f"fine_in_oz = {_number(design.saturation_fine_in_oz)}",
              f"anti_windup = {toml_string(design.anti_windup)}", "", "[friction_compensation]"]
    fc = design.friction
    lines.append(f"enabled = {'true' if fc.enabled else 'false'}")
    if fc.model is not None:
        lines.append(f"model = {toml_string(fc.model)}")
    for key, value in (("sigma_in_oz_per_rad", fc.sigma_in_oz_per_rad),
                       ("coulomb_torque_in_oz", fc.coulomb_torque_in_oz), ("alpha", fc.alpha)):
        if value is not None:
            lines.append(f"{key} = {_number(value)}")
    if fc.slope_table is not None:
        lines.append(f"slope_table = {toml_string(relative_path(fc.slope_table, folder))}")
    lines.append("")
    unit = "in-oz/(rad/s)" if design.mode == Setup.INERTIAL else "in-oz/rad"
    if c0_equivalent_to is not None:
        lines += [f"# c0 = {design.c0.text()}   {unit}",
                  "# (output-equivalent: recomputed from that design when this file is read)",
                  "[c0]", f"equivalent_to = {toml_string(relative_path(c0_equivalent_to, folder))}"]
        if cancel_tolerance is not None and cancel_tolerance != CANCEL_TOLERANCE:
            lines.append(f"cancel_tolerance = {_number(cancel_tolerance)}")
        lines.append("")
    else:
        lines += _tf_lines("c0", factored(design.c0), unit)
    if design.q is not None:
        lines += _tf_lines("Q", factored(design.q), "c1' = Q, c2' = 1")
    else:
        lines += _tf_lines("c1", factored(design.c1)) + _tf_lines("c2", factored(design.c2))
    return "\n".join(lines)


def transfer_function_mismatch(a: ControllerDesign, b: ControllerDesign,
                               freqs_hz: np.ndarray | None = None) -> float:
    """The largest relative difference between c0, c1', c2' of two designs on a grid
    (0.01 Hz to Nyquist by default); the responses, so factor order does not matter."""
    f = np.logspace(-2, math.log10(CONTROL_RATE_HZ / 2), 400) if freqs_hz is None else freqs_hz
    worst = 0.0
    for key in ("c0", "c1", "c2"):
        x, y = a.cascades[key].frequency_response(f), b.cascades[key].frequency_response(f)
        scale = np.maximum(np.abs(x), 1e-300)
        worst = max(worst, float(np.max(np.abs(y - x) / scale)))
    return worst


def write_design(design: ControllerDesign, path: str | Path, **options) -> ControllerDesign:
    """Write `design` to `path` (design_text's options) and read it back: returns the
    design as load_design gives it.  The text goes to a temporary file beside `path`
    first and replaces `path` only when it reproduces the design's transfer functions
    within ROUND_TRIP_TOLERANCE (DesignError otherwise, and `path` is left as it was)."""
    out = Path(path)
    problems = controller_problems(design)
    if problems:
        raise DesignError(f"{out}: not written: " + "; ".join(problems))
    text = design_text(design, out, **options)
    tmp = out.with_name(f".{out.name}.writing")
    try:
        tmp.write_text(text + "\n", encoding="utf-8")
        back = load_design(tmp)
        gap = transfer_function_mismatch(design, back)
        if not gap <= ROUND_TRIP_TOLERANCE:
            raise DesignError(f"{out}: the file would give transfer functions that differ from "
                              f"the design by {gap:.2g} (relative); not written")
        os.replace(tmp, out)
    except OSError as exc:
        raise DesignError(f"{out}: cannot write ({exc.strerror or exc})") from None
    finally:
        tmp.unlink(missing_ok=True)
    return replace(back, path=out.resolve())
