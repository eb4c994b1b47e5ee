"""The design workbench's state and numbers: no Qt, no widgets.

Two slots (#1 and #2) each hold a controller design as loaded from its file and as
edited: the transfer functions c0 and Q (or c1', c2') as gain and factors, the way the
design file writes them (groundstation.params.design_writer.Factored).  An edit builds
a new ControllerDesign (dataclasses.replace of the loaded one, so the testbed, mode,
saturation, friction compensation and K_p stay) and is refused, with the slot
unchanged, when load_design would refuse the result.

"Keep output-equivalent": with a reference design set, c0 is not edited but recomputed
after every edit of Q by tf_algebra.output_equivalent_c0, so that the loop gain
c0 (c1' g1 + c2' g2) stays the reference's (the file format's `c0.equivalent_to`).
A design whose file says `c0.equivalent_to` opens with that design as its reference.

The numbers come from the PQ modules and nothing else:

- `fast_views`: the frequency views on the 800-point grid (pq_design.analyze), T_I(0)
  (dc_input_sensitivity), the alignment at the report's frequencies and the PQ
  crossovers (pq_report) - a few milliseconds, done at every edit on the GUI thread;
- `slow_views`: what `params analyze` prints beyond that - the validation's margins and
  verdict and the linear responses with their predicted saturation (pq_report.summarize,
  which runs loop.validate and pq_response.linear_responses): tens of milliseconds
  (inertial: the three margins alone take 70-85 ms), so the workbench runs it on a worker
  thread.  It only reads the design and the dictionary, so it may.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ...core.dictionary import Dictionary, load_dictionary
from ...params.design_file import ControllerDesign, load_design
from ...params.design_writer import (Factored, controller_problems, factored,
                                     transfer_function_mismatch, write_design)
from ...params.pq_design import (DCMatrix, PQAnalysis, analyze, dc_input_sensitivity,
                                 frequency_grid, ratio_alignment_deg)
from ...params.pq_report import DEFAULT_FREQS_HZ, DesignSummary, pq_crossovers, summarize
from ...params.tf_algebra import DesignError, TransferFunction, output_equivalent_c0

SLOTS = 2
SIDES = ("numerator", "denominator")
NEW_FACTOR = (100.0,)               # what "add a zero/pole" starts from: (s + 100)


# ======================================================================================
# the numbers
# ======================================================================================
@dataclass(frozen=True, eq=False)
class FastViews:
    """One design's frequency views and the numbers computed with them."""

    design: ControllerDesign
    analysis: PQAnalysis                    # on frequency_grid()
    dc: DCMatrix | None                     # T_I(0); None when the limit needs more terms
    dc_problem: str
    freqs_hz: np.ndarray                    # the report's frequencies
    phi_at_deg: np.ndarray                  # phi there
    crossovers: tuple[tuple[float, float], ...]   # (Hz, angle PQ deg) where |PQ| = 1
    seconds: float                          # the time these took


def fast_views(design: ControllerDesign, freqs_hz=DEFAULT_FREQS_HZ) -> FastViews:
    t0 = time.perf_counter()
    a = analyze(design, frequency_grid())
    f = np.asarray(freqs_hz, float)
    try:
        dc, problem = dc_input_sensitivity(design), ""
    except ValueError as exc:
        dc, problem = None, str(exc)
    return FastViews(design, a, dc, problem, f, analyze(design, f).phi_deg, pq_crossovers(a),
                     time.perf_counter() - t0)


def slow_views(design: ControllerDesign, dictionary: Dictionary) -> DesignSummary:
    """Margins, verdict and linear responses: pq_report.summarize (worker thread)."""
    return summarize(design, dictionary=dictionary)


def q_one_alignment(testbed, freqs_hz: np.ndarray) -> np.ndarray:
    """phi of Q = 1 (c1' = c2' = 1) on the testbed, the reference's comparison."""
    one = TransferFunction.constant(1.0)
    return ratio_alignment_deg(testbed, one, one, freqs_hz)


def parse_numbers(text: str) -> tuple[float, ...]:
    """'60.27', '25.92, 86100' or '[25.92, 86100]' -> the numbers (ValueError if not)."""
    parts = text.replace("[", " ").replace("]", " ").replace(",", " ").split()
    values = tuple(float(p) for p in parts)
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{text!r}: expected finite numbers")
    return values


# ======================================================================================
# the slots
# ======================================================================================
@dataclass
class Slot:
    original: ControllerDesign              # as loaded
    partner: ControllerDesign | None        # its file's c0.equivalent_to design, loaded
    design: ControllerDesign                # as edited (the original until an edit)
    factors: dict[str, Factored]            # what the editor shows, per transfer function
    reference: ControllerDesign | None      # keep output-equivalent to this (None: off)
    name: str
    generation: int = 0                     # counts the edits
    saved_path: Path | None = None          # the file that holds this generation
    saved_generation: int = -1
    keys: tuple[str, ...] = field(default=())

    @property
    def edited(self) -> bool:
        """Do c0, c1', c2' or the name differ from the file's?  (An edit undone by hand
        is not an edit.)"""
        if self.name != self.original.name:
            return True
        return (self.design is not self.original
                and transfer_function_mismatch(self.design, self.original) > 1e-12)

    @property
    def saved(self) -> bool:
        return self.saved_generation == self.generation and self.saved_path is not None


def _tfs(design: ControllerDesign) -> dict[str, TransferFunction]:
    out = {"c0": design.c0}
    if design.q is not None:
        out["Q"] = design.q
    else:
        out.update(c1=design.c1, c2=design.c2)
    return out


class WorkbenchModel:
    """The two slots and every change to them.  Methods raise DesignError (naming what)
    and leave the slot as it was when a change cannot be made."""

    def __init__(self, dictionary: Dictionary | None = None):
        self.dictionary = dictionary or load_dictionary()
        self.slots: list[Slot | None] = [None] * SLOTS
        self._q_one: dict[Path, np.ndarray] = {}

    # ------------------------------------------------------------------ loading
    def open(self, index: int, path: str | Path) -> Slot:
        """Load a design file into slot `index` (and the design its c0 is equivalent to)."""
        return self.set_design(index, load_design(path))

    def set_design(self, index: int, design: ControllerDesign) -> Slot:
        if not design.testbed.is_2dof:
            raise DesignError(f"{design.path.name}: the workbench's PQ views need two inputs; "
                              f"{design.testbed.path.name} is {design.testbed.configuration}")
        partner = load_design(design.c0_equivalent_to) if design.c0_equivalent_to else None
        slot = Slot(design, partner, design, {k: factored(tf) for k, tf in _tfs(design).items()},
                    partner, design.name, keys=tuple(_tfs(design)))
        self.slots[index] = slot
        return slot

    def clear(self, index: int) -> None:
        self.slots[index] = None

    def slot(self, index: int) -> Slot:
        s = self.slots[index]
        if s is None:
            raise DesignError(f"no design in slot #{index + 1}")
        return s

    def q_one(self, index: int, freqs_hz: np.ndarray) -> np.ndarray:
        tb = self.slot(index).original.testbed
        if tb.path not in self._q_one:
            self._q_one[tb.path] = q_one_alignment(tb, freqs_hz)
        return self._q_one[tb.path]

    # ------------------------------------------------------------------ references
    def references(self, index: int) -> list[tuple[str, ControllerDesign]]:
        """The designs slot `index` may be kept output-equivalent to: its file's partner,
        itself as loaded, and the other slot's design as loaded (same mode only)."""
        s = self.slot(index)
        out: list[tuple[str, ControllerDesign]] = []
        if s.partner is not None:
            out.append((f"{s.partner.name} (its file's c0.equivalent_to)", s.partner))
        out.append((f"{s.original.name} as loaded", s.original))
        for j, other in enumerate(self.slots):
            if j != index and other is not None and other.original.mode == s.original.mode:
                out.append((f"#{j + 1} {other.original.name} as loaded", other.original))
        seen, unique = set(), []
        for label, d in out:
            if d.path not in seen:
                seen.add(d.path)
                unique.append((label, d))
        return unique

    def set_reference(self, index: int, reference: ControllerDesign | None) -> Slot:
        """Keep c0 output-equivalent to `reference` (None: c0 stays as it now is)."""
        s = self.slot(index)
        if reference is not None and reference.mode != s.original.mode:
            raise DesignError(f"{reference.name} is a {reference.mode} design; slot #{index + 1} "
                              f"holds a {s.original.mode} one")
        return self._apply(index, {}, reference)

    # ------------------------------------------------------------------ edits
    def edit(self, index: int, key: str, part: str, position: int | None, text: str) -> Slot:
        """Set the gain (part "gain") or one factor (part "numerator"/"denominator",
        `position` in that list) of transfer function `key` from the editor's text."""
        s = self.slot(index)
        try:
            numbers = parse_numbers(text)
        except ValueError as exc:
            raise DesignError(f"{key} {part}: {exc}") from None
        f = s.factors[key]
        if part == "gain":
            if len(numbers) != 1:
                raise DesignError(f"{key} gain: one number, got {text!r}")
            if key == "c0" and numbers[0] == 0.0:
                raise DesignError("c0 gain 0 would switch the loop off")
            new = replace(f, gain=numbers[0])
        else:
            if len(numbers) not in (1, 2):
                raise DesignError(f"{key} {part}: [a] for (s + a) or [b, c] for (s^2 + b s + c), "
                                  f"got {text!r}")
            items = list(f.side(part))
            if position is None or not 0 <= position < len(items):
                raise DesignError(f"{key} has no {part} factor {position}")
            items[position] = numbers
            new = replace(f, **{part: tuple(items)})
        return self._set_factors(index, key, new)

    def add_factor(self, index: int, key: str, side: str, factor=NEW_FACTOR) -> Slot:
        f = self.slot(index).factors[key]
        return self._set_factors(index, key, replace(f, **{side: (*f.side(side), tuple(factor))}))

    def remove_factor(self, index: int, key: str, side: str, position: int) -> Slot:
        f = self.slot(index).factors[key]
        items = list(f.side(side))
        if not 0 <= position < len(items):
            raise DesignError(f"{key} has no {side} factor {position}")
        del items[position]
        return self._set_factors(index, key, replace(f, **{side: tuple(items)}))

    def scale_gain(self, index: int, key: str, factor: float) -> Slot:
        f = self.slot(index).factors[key]
        return self._set_factors(index, key, replace(f, gain=f.gain * factor))

    def reset(self, index: int) -> Slot:
        """Back to the design as loaded (and its own reference)."""
        s = self.slot(index)
        self.slots[index] = fresh = replace(
            s, design=s.original, reference=s.partner, generation=s.generation + 1,
            factors={k: factored(tf) for k, tf in _tfs(s.original).items()})
        return fresh

    def _set_factors(self, index: int, key: str, f: Factored) -> Slot:
        s = self.slot(index)
        if key == "c0" and s.reference is not None:
            raise DesignError(f"c0 is kept output-equivalent to {s.reference.name}: turn that off "
                              f"to edit c0")
        return self._apply(index, {key: f}, s.reference)

    def _apply(self, index: int, changed: dict[str, Factored], reference) -> Slot:
        s = self.slot(index)
        tfs = _tfs(s.design)
        tfs.update({k: f.transfer_function() for k, f in changed.items()})
        if "Q" in tfs:
            c1, c2, q = tfs["Q"], TransferFunction.constant(1.0), tfs["Q"]
        else:
            c1, c2, q = tfs["c1"], tfs["c2"], None
        o = s.original
        notes = tuple(n for n in o.notes if not n.startswith("c0 is output-equivalent"))
        if reference is not None:
            c0, cancelled = output_equivalent_c0(reference, c1, c2, o.testbed,
                                                 where=f"slot #{index + 1}")
            notes += (f"c0 kept output-equivalent to {reference.name}: order {c0.order} after "
                      f"cancelling {cancelled} pole/zero pair(s)",)
        else:
            c0 = tfs["c0"]
        design = replace(o, c0=c0, c1=c1, c2=c2, q=q,
                         c0_equivalent_to=reference.path if reference is not None else None,
                         c0_order=c0.order, notes=notes)
        problems = controller_problems(design)
        if problems:
            raise DesignError("; ".join(problems))
        factors = dict(s.factors)
        factors.update(changed)
        if reference is not None or "c0" in changed:
            factors["c0"] = changed.get("c0") or factored(c0)
        self.slots[index] = fresh = replace(s, design=design, factors=factors, reference=reference,
                                            generation=s.generation + 1)
        return fresh

    # ------------------------------------------------------------------ saving
    def save(self, index: int, path: str | Path) -> ControllerDesign:
        """Write the slot's design as a design file (read back and checked by
        design_writer.write_design) and return it as load_design gives it.  A c0 kept
        output-equivalent is written as `equivalent_to` the reference's file, unless that
        is the file being written (then as its factors)."""
        s = self.slot(index)
        out = Path(path)
        eq = s.reference.path if s.reference is not None else None
        if eq is not None and eq.resolve() == out.resolve():
            eq = None
        back = write_design(s.design, out, name=s.name, c0_equivalent_to=eq,
                            source=s.original.path.name)
        s.saved_path, s.saved_generation = back.path, s.generation
        return back

    def rename(self, index: int, name: str) -> None:
        name = name.strip()
        if not name:
            raise DesignError("a design needs a name")
        s = self.slot(index)
        if name != s.name:
            s.name = name
            s.saved_generation = -1
