"""The vocabulary an action's value check is written in: one `StepCheck` per step, whose
helpers (a finite number in a range, text, a flag, a protocol mode, a file that loads,
a generator channel) word every problem the same way - "FILE: run 2 step 4 (dwell):
seconds = -5 - must be a finite number > 0".  `CampaignChecker` holds what all the steps
of one campaign share: the dictionary, the testbed and the files already loaded."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

from ..core.errors import GroundStationError
from ..instruments import spec4050
from .model import Step


class CampaignChecker:
    """What the checks of one campaign share; loads each referenced file once (a matrix
    names the same design in many runs)."""

    def __init__(self, path: Path, dictionary, testbed):
        self.path = path
        self.d = dictionary
        self.testbed = testbed                            # None: the file did not load
        self._loaded: dict[tuple, str | None] = {}       # (kind, args) -> problem or None
        #: synthesised base-motion profiles (or why not), by (psd, duration, seed, rms)
        self.base_motion: dict[tuple, Any] = {}

    def command_arg(self, command: str, name: str):
        return next(i for i in self.d.command(command).args if i.name == name)

    def modes(self) -> dict[str, int]:
        return dict(self.command_arg("SET_MODE", "mode").states)

    def once(self, key: tuple, load: Callable[[], Any]) -> str | None:
        """Why `load()` fails (None: it loads), remembered under `key`."""
        if key not in self._loaded:
            try:
                load()
                self._loaded[key] = None
            except GroundStationError as exc:
                self._loaded[key] = str(exc).strip() or type(exc).__name__
            except (OSError, ValueError) as exc:
                self._loaded[key] = f"{type(exc).__name__}: {exc}"
        return self._loaded[key]

    def step(self, step: Step) -> "StepCheck":
        return StepCheck(self, step)


class StepCheck:
    """One step's values under check; the problems found collect in `problems`."""

    def __init__(self, checker: CampaignChecker, step: Step):
        self.checker = checker
        self.step = step
        self.args = step.args
        self.testbed = checker.testbed
        self.head = f"{checker.path.name}: {step.where()}"
        self.problems: list[str] = []

    def problem(self, text: str) -> None:
        """A problem that is not about one key's value ("psd: the profile needs ...")."""
        self.problems.append(f"{self.head}: {text}")

    def bad(self, key: str, text: str) -> None:
        self.problems.append(f"{self.head}: {key} = {show(self.args.get(key))} - {text}")

    def number(self, key: str, *, lo: float | None = None, hi: float | None = None,
               positive: bool = False, what: str = "") -> float | None:
        """The value as a finite number, or None after a problem (absent: None)."""
        if key not in self.args:
            return None
        v = self.args[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            rule = "must be a finite number"
            if positive:
                rule += " > 0"
            elif lo is not None and hi is not None:
                rule += f" in [{lo:g}, {hi:g}]"
            self.bad(key, rule + (f" ({what})" if what else ""))
            return None
        if positive and not v > 0:
            self.bad(key, "must be a finite number > 0" + (f" ({what})" if what else ""))
            return None
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            self.bad(key, f"outside [{'-inf' if lo is None else f'{lo:g}'}, "
                          f"{'inf' if hi is None else f'{hi:g}'}]" + (f" ({what})" if what else ""))
            return None
        return float(v)

    def text(self, key: str, *, empty_ok: bool = False) -> None:
        if key in self.args:
            v = self.args[key]
            if not isinstance(v, str) or (not empty_ok and not v.strip()):
                self.bad(key, "must be text" + ("" if empty_ok else " (not empty)"))

    def flag(self, key: str) -> None:
        if key in self.args and not (isinstance(self.args[key], bool) or self.args[key] in (0, 1)):
            self.bad(key, "must be true or false")

    def mode(self, key: str) -> None:
        if key in self.args:
            modes = self.checker.modes()
            if self.args[key] not in modes:
                self.bad(key, f"not a mode of the protocol (SET_MODE: {', '.join(modes)})")

    def loads(self, key: str, kind: str, load: Callable[[], Any]) -> bool:
        """The file named by `key` loads with `load()`; otherwise a problem saying why."""
        problem = self.checker.once((kind, self.args[key]), load)
        if problem:
            self.problem(f"{key}: {problem}")
        return problem is None

    def channel(self) -> int | None:
        """The generator channel (1 when absent), or None after a problem."""
        if "channel" not in self.args:
            return 1
        v = self.args["channel"]
        if isinstance(v, bool) or v not in spec4050.CHANNELS:
            self.bad("channel", f"must be one of the generator's channels "
                                f"{', '.join(map(str, spec4050.CHANNELS))}")
            return None
        return int(v)


def show(v: Any) -> str:
    """A value as a problem quotes it: text quoted, 5.0 as 5."""
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, float) and v.is_integer():
        return f"{v:g}"
    return str(v)
