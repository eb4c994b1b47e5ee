"""The suite's results for people (PASS/FAIL/SKIP lines with evidence) and for CI
(a JUnit XML file: one testcase per check, classname = SPEC section)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Callable, Iterable

from .context import FAIL, PASS, SKIP, Result


def print_result(r: Result, say: Callable[[str], None]) -> None:
    say(f"{r.status:<4}  {r.name}  ({r.seconds:.2f} s)")
    for line in r.lines:
        say(f"        {line}")


def summary(results: list[Result]) -> str:
    n = {s: sum(r.status == s for r in results) for s in (PASS, FAIL, SKIP)}
    return (f"{len(results)} checks: {n[PASS]} passed, {n[FAIL]} failed, {n[SKIP]} skipped")


def write_junit(results: Iterable[Result], path: str, *, suite: str, device: str) -> None:
    results = list(results)
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", {
        "name": suite, "tests": str(len(results)),
        "failures": str(sum(r.status == FAIL for r in results)),
        "errors": "0", "skipped": str(sum(r.status == SKIP for r in results)),
        "time": f"{sum(r.seconds for r in results):.3f}"})
    props = ET.SubElement(ts, "properties")
    ET.SubElement(props, "property", {"name": "device", "value": device})
    for r in results:
        case = ET.SubElement(ts, "testcase", {"classname": r.section, "name": r.name,
                                              "time": f"{r.seconds:.3f}"})
        text = "\n".join(r.lines)
        if r.status == FAIL:
            first = next((l[5:] for l in r.lines if l.startswith("FAIL ")), r.lines[-1] if r.lines else "")
            el = ET.SubElement(case, "failure", {"message": first, "type": "SpecDeviation"})
            el.text = text
        elif r.status == SKIP:
            ET.SubElement(case, "skipped", {"message": r.lines[0] if r.lines else ""})
        else:
            ET.SubElement(case, "system-out").text = text
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    ET.parse(path)          # what we wrote must read back as XML
