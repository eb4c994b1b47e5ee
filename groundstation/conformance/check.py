"""A conformance check: the SPEC section it tests, a title, and the function that runs
it against a Context and fills a Verdict."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .context import Context, Verdict


@dataclass(frozen=True)
class Check:
    section: str                # "§7", "§11.1" - also the JUnit classname
    title: str
    run: Callable[[Context, Verdict], None]

    @property
    def name(self) -> str:
        return f"{self.section} {self.title}"

    def selected_by(self, only: list[str]) -> bool:
        """--only §7 takes §7 and §7.x; --only 11 works too; a title word selects as well."""
        if not only:
            return True
        for want in only:
            w = want if want.startswith("§") else "§" + want
            if self.section == w or self.section.startswith(w + "."):
                return True
            if not want.lstrip("§").replace(".", "").isdigit() and want.lower() in self.title.lower():
                return True
        return False
