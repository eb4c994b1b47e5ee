"""The architecture as rules: packages only at the top of groundstation/, a layer table
with no import upward, no cycles, Qt only in gui/, a command line that starts light.
docs/architecture.md draws the same map and says where to change what."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "groundstation"


def test_no_qt_outside_the_gui_package():
    offenders = []
    for path in PKG.rglob("*.py"):
        if "gui" in path.relative_to(PKG).parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            offenders += [f"{path.name}: {n}" for n in names
                          if n.split(".")[0] in ("PySide6", "pyqtgraph", "shiboken6")]
    assert not offenders, offenders


def _package_of(path: Path) -> str:
    """The unit a module belongs to: its top-level package under groundstation/, or the
    module itself for a top-level module (cli.py -> 'cli')."""
    return path.relative_to(PKG).parts[0].removesuffix(".py")


def _imported_units(path: Path) -> set[str]:
    """Top-level units of groundstation that `path` imports (relative or absolute)."""
    parts = path.relative_to(PKG).with_suffix("").parts
    folder = list(parts[:-1])                    # the package the module sits in
    units: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = folder[:len(folder) - (node.level - 1)] if node.level > 1 else folder
            target = base + (node.module.split(".") if node.module else [])
            if target:
                units.add(target[0])
            else:                                # `from .. import cli_logs`
                units.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("groundstation."):
            units.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            units.update(a.name.split(".")[1] for a in node.names
                         if a.name.startswith("groundstation."))
    return units


def package_imports() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for path in PKG.rglob("*.py"):
        unit = _package_of(path)
        graph.setdefault(unit, set()).update(u for u in _imported_units(path) if u != unit)
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one unit (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


#: the layers, bottom first.  A package imports only packages of layers below its own:
#: data flows up from the foundation (core) and the wire (codec) to the programs (cli,
#: which also launches the window).  The package's own __init__ and __main__ are the
#: entry points and stand outside the table.
LAYERS = [
    ("core",),                                            # errors, dictionary, contracts, kinds
    ("codec",),                                           # frames, CRC, sequence and tick counting
    ("link", "plant", "live", "instruments", "profiles", "firmware_kit"),
    ("logs", "params"),                                   # the recorder reads the link's blocks
    ("sim", "analysis", "fanout", "conformance"),         # twin, metrics, consoles, suite
    ("basemotion", "identification"),                     # generator profiles; the rig's own twin
    ("station",),                                         # one session: rig, clock, recording
    ("campaign",),
    ("gui",),
    ("cli",),                                             # `groundstation gui` starts the window
]
ENTRY_POINTS = {"__init__", "__main__", "__version__"}


def test_only_packages_at_the_top():
    """groundstation/ holds packages and its two entry points, no loose modules: a new
    module goes into the package of its layer."""
    loose = sorted(p.name for p in PKG.glob("*.py") if p.stem not in ENTRY_POINTS)
    assert not loose, f"loose modules at the top of groundstation/: {loose}"
    packages = {p.name for p in PKG.iterdir() if (p / "__init__.py").exists()}
    assert packages == {unit for layer in LAYERS for unit in layer}, \
        "every package has a place in the layer table (tests/test_architecture.py LAYERS)"


def test_no_package_imports_a_layer_above_its_own():
    rank = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}
    upward = []
    for unit, imported in package_imports().items():
        if unit in ENTRY_POINTS:
            continue
        upward += [f"{unit} (layer {rank[unit]}) imports {other} (layer {rank[other]})"
                   for other in sorted(imported - ENTRY_POINTS) if rank[other] >= rank[unit]]
    assert not upward, "\n".join(upward)


def test_the_cycle_finder_finds_a_cycle():
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_between_packages():
    """Data flows one way: no package (or top-level module) imports, directly or through
    others, one that imports it back.  The testbed model (plant/) is read by the
    simulator and the controller design and reads neither."""
    graph = package_imports()
    assert "plant" in graph["params"] and "plant" in graph["sim"]      # the scan sees imports
    assert import_cycles(graph) == []
    assert not graph.get("plant", set()) & {"sim", "params", "link", "gui", "logs"}


def test_the_command_line_starts_without_the_heavy_libraries():
    """`groundstation --help` and every command's argument parsing import only the
    standard library: numpy, scipy, h5py, Qt, pyvisa, numba and pyserial are imported by
    the commands that use them (start-up time: benchmarks/bench_cli.py, in the README)."""
    import subprocess
    import sys

    heavy = ["numpy", "scipy", "h5py", "PySide6", "pyqtgraph", "pyvisa", "pyvisa_sim", "numba",
             "matplotlib", "serial", "zmq", "dask"]
    code = ("import sys, groundstation.cli.main as c; c.build_parser(); "
            f"print(sorted({{m.split('.')[0] for m in sys.modules}} & set({heavy!r})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]", f"imported at start-up: {out}"


def test_the_control_rate_is_not_a_literal():
    """The controller's rate (1200 Hz) lives in protocol/telemetry.toml
    (`[protocol] control_rate_hz`): code takes it from a Dictionary or from
    dictionary.default_control_rate_hz(), never from a number 1200 written in the code.
    Comments and docstrings may say "1200 Hz" (they are not numbers in the syntax tree)."""
    offenders = []
    for path in sorted(PKG.rglob("*.py")):
        name = str(path.relative_to(PKG))
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Constant) and type(node.value) in (int, float)
                    and node.value == 1200):
                offenders.append(f"{name}:{node.lineno}")
    assert not offenders, f"literal control rate 1200 in code: {offenders}"


#: what builds a rig: a simulated testbed, a device link, a generator
RIG_BUILDERS = ("open_client", "DeviceClient", "SimulatorProcess", "SteppedSimulatorProcess",
                "open_generator")
#: where they may be called: station/rig.py (the one place), the packages that define them
#: (link/, sim/ - a simulator serves its own generator - and instruments/)
RIG_HOMES = ("station/rig.py", "link/", "sim/", "instruments/")


def test_only_the_rig_module_builds_a_simulator_a_link_or_a_generator():
    """A script's Station, the keeper, the window and the `fg` commands all start the
    simulated testbed, open the link and open the generator through station/rig.py, so
    they are started, watched (the local device's liveness) and bounded (the generator's
    safety limits) the same way everywhere."""
    offenders = []
    for path in sorted(PKG.rglob("*.py")):
        name = path.relative_to(PKG).as_posix()
        if name.startswith(RIG_HOMES):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                called = (node.func.id if isinstance(node.func, ast.Name) else
                          node.func.attr if isinstance(node.func, ast.Attribute) else "")
                if called in RIG_BUILDERS:
                    offenders.append(f"{name}:{node.lineno}: {called}()")
    assert not offenders, offenders


#: what builds or draws widgets: the window's model may use neither
WIDGET_MODULES = ("PySide6.QtWidgets", "pyqtgraph")


def absolute_imports(node: ast.AST) -> list[str]:
    """The modules an import statement names (`from a import b` names a and a.b);
    relative imports are the project's own and name nothing here."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom) and node.module and not node.level:
        return [node.module] + [f"{node.module}.{a.name}" for a in node.names]
    return []


def test_the_window_session_imports_no_widgets():
    """gui/session/ is the window's model (links, recording, playback, campaigns as
    QObjects and their signals): it imports QtCore at most, never QtWidgets or
    pyqtgraph, so it runs headless and the panels are the only views of it."""
    offenders = []
    for path in sorted((PKG / "gui" / "session").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            offenders += [f"{path.relative_to(PKG).as_posix()}:{node.lineno}: {n}"
                          for n in absolute_imports(node)
                          if any(n == m or n.startswith(m + ".") for m in WIDGET_MODULES)]
    assert not offenders, offenders


#: what computes rather than shows: the window asks analysis/, live/ and params/ for
#: figures and draws them (unit and dB/degree conversions, axis ranges and the colours
#: of a band are presentation and stay in gui/)
NUMERIC_MODULES = ("scipy", "numpy.fft", "numpy.linalg", "numpy.polynomial", "numpy.random",
                   "numba")
NUMERIC_CALLS = {"cumsum", "cumprod", "trapz", "trapezoid", "convolve", "correlate", "polyfit",
                 "polyval", "mean", "nanmean", "std", "nanstd", "var", "median", "histogram",
                 "gradient", "interp", "fft", "rfft", "lstsq", "solve", "inv", "eig"}


def numerics_in(path: Path, name: str) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        found += [f"{name}:{node.lineno}: imports {m}" for m in absolute_imports(node)
                  if any(m == n or m.startswith(n + ".") for n in NUMERIC_MODULES)]
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and isinstance(node.func.value, ast.Name) and node.func.value.id in ("np", "numpy")
                and node.func.attr in NUMERIC_CALLS):
            found.append(f"{name}:{node.lineno}: np.{node.func.attr}()")
    return found


def test_the_window_does_no_numerics():
    """Spectra, integrals, statistics, fits and solvers live in the Qt-free packages,
    where the CLI, the reports and the tests use the same code the window shows."""
    found = []
    for path in sorted((PKG / "gui").rglob("*.py")):
        found += numerics_in(path, path.relative_to(PKG).as_posix())
    assert not found, "\n".join(found)


def test_the_numerics_rule_sees_an_integral_and_a_scipy_import(tmp_path):
    sample = tmp_path / "view.py"
    sample.write_text("import numpy as np\nfrom scipy.signal import welch\n"
                      "total = np.sqrt(np.cumsum(p * df))\nlabel = np.log10(x)\n")
    assert [f.split(": ", 1)[1] for f in numerics_in(sample, "view.py")] == [
        "imports scipy.signal", "imports scipy.signal.welch", "np.cumsum()"]


#: the longest a function may be, in lines from its `def` to its last line
MAX_FUNCTION_LINES = 80
#: where longer functions stand: the simulator's compiled core, written as one loop per
#: tick for numba, where a call per step would cost what the compilation saves
LONG_FUNCTIONS_ALLOWED = ("sim/core.py",)


def test_no_function_is_over_80_lines():
    """A function says one thing: past 80 lines it is several, and is split into named
    helpers (or a small class) - methods and nested functions count on their own."""
    long = []
    for path in sorted(PKG.rglob("*.py")):
        name = path.relative_to(PKG).as_posix()
        if name in LONG_FUNCTIONS_ALLOWED:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{name}:{node.lineno}: {node.name} ({lines} lines)")
    assert not long, "\n".join(long)


#: parameter names that hold a device connection or an instrument, and the contracts
#: (core/contracts.py) their annotation may name
DEVICE_FACING = {"client": ("DeviceLink", "CommandChannel", "TelemetrySource"),
                 "fg": ("BaseMotionInstrument",)}
#: the packages that implement the contracts use their own classes
CONTRACT_HOMES = ("link/", "instruments/", "sim/", "core/contracts.py")


def device_facing_problems(path: Path, name: str) -> list[str]:
    problems = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        a = node.args
        for arg in a.posonlyargs + a.args + a.kwonlyargs:
            allowed = DEVICE_FACING.get(arg.arg)
            if allowed is None:
                continue
            text = ast.unparse(arg.annotation) if arg.annotation is not None else ""
            named = {n.id for n in ast.walk(ast.parse(text.strip("'\""), mode="eval"))
                     if isinstance(n, ast.Name)} if text else set()
            if not named & set(allowed):
                problems.append(f"{name}:{node.lineno}: {node.name}({arg.arg}: {text or '?'}) "
                                f"- annotate with {' or '.join(allowed)}")
    return problems


def test_device_facing_parameters_are_annotated_with_the_contracts():
    """What holds a device connection (`client`) or the function generator (`fg`) says
    which side of the contract it needs, not which class provides it: a replay, a test
    double or another link then stands in without an adapter."""
    problems = []
    for path in sorted(PKG.rglob("*.py")):
        name = path.relative_to(PKG).as_posix()
        if not name.startswith(CONTRACT_HOMES):
            problems += device_facing_problems(path, name)
    assert not problems, "\n".join(problems)


def test_the_contract_rule_catches_a_bare_or_concrete_parameter(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("def a(client): pass\n"
                      "def b(client: DeviceClient): pass\n"
                      "def c(client: 'DeviceLink | None' = None, fg: BaseMotionInstrument = None): pass\n"
                      "def d(*, fg): pass\n")
    problems = device_facing_problems(sample, "sample.py")
    assert [p.split(":")[1] for p in problems] == ["1", "2", "4"], problems


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _absolute(path: Path, node: ast.ImportFrom) -> str:
    """The module an ImportFrom names, made absolute."""
    if not node.level:
        return node.module or ""
    package = _module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    base = package[:len(package) - (node.level - 1)]
    return ".".join(base + (node.module.split(".") if node.module else []))


def test_no_class_is_assembled_from_mixins():
    """A class that grew too big is split by extracting a collaborator object it owns, not
    by mixing in classes that use attributes only the final class provides: at most one
    base class of the project's own, and none called a mixin.  An exception may have two
    (ReplayDamagedError is a LogDamagedError and a ReplayError: `except` finds it as either)."""
    offenders = []
    own = {node.name for path in PKG.rglob("*.py") for node in ast.walk(ast.parse(path.read_text()))
           if isinstance(node, ast.ClassDef)}
    for path in sorted(PKG.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef):
                continue
            bases = [ast.unparse(b).split(".")[-1] for b in node.bases]
            ours = [b for b in bases if b in own]
            if all(b.endswith(("Error", "Exception")) for b in bases):
                continue
            if "Protocol" in bases:
                continue        # a contract made of contracts: no code of its own to mix
            if len(ours) > 1 or any(b.endswith("Mixin") for b in bases) or node.name.endswith("Mixin"):
                offenders.append(f"{path.relative_to(PKG)}:{node.lineno} {node.name}({', '.join(bases)})")
    assert not offenders, offenders


def test_no_module_re_exports_what_another_defines():
    """A name is imported from the module that defines it (a package's __init__ may name
    its public API): a module that passes on names it imported is a shim left by a split."""
    sources = sorted(PKG.rglob("*.py"))
    imported_into: dict[str, set[str]] = {}
    for path in sources:
        if path.name == "__init__.py":
            continue
        names = set()
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ImportFrom) and _absolute(path, node).startswith("groundstation"):
                names |= {a.asname or a.name for a in node.names}
        imported_into[_module_name(path)] = names
    offenders = []
    for path in sources + sorted((PKG.parent / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and path.is_relative_to(PKG) or (
                    isinstance(node, ast.ImportFrom) and (node.module or "").startswith("groundstation")):
                module = _absolute(path, node) if path.is_relative_to(PKG) else node.module
                passed_on = [a.name for a in node.names if a.name in imported_into.get(module, ())]
                if passed_on:
                    offenders.append(f"{path.relative_to(PKG.parent)}:{node.lineno}: {passed_on} "
                                     f"from {module}, which only imports them")
    assert not offenders, "\n".join(offenders)


#: the closed vocabularies (core/kinds.py) and the expressions that hold one of their words
VOCABULARY_WORDS = {"up", "lost", "ended", "closed", "connecting", "failed", "inertial",
                    "relative", "absolute", "inline", "process", "held", "realtime", "manual",
                    "auto", "none", "sim"}
VOCABULARY_HOLDERS = ("link_state", "setup", "mode", "origin", "between_steps", "fast_sim",
                      "pacing", "address", "device_spec", "generator_spec")


def test_closed_vocabularies_are_compared_as_enums_not_string_literals():
    """`client.link_state == LinkState.UP`, not `== "up"`: a misspelt member fails at import,
    a misspelt string is a comparison that is silently never true."""
    offenders = []
    for path in sorted(PKG.rglob("*.py")):
        if path.name == "kinds.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Compare):
                continue
            operands = [node.left, *node.comparators]
            words = [c.value for o in operands
                     for c in (o.elts if isinstance(o, (ast.Tuple, ast.List, ast.Set)) else [o])
                     if isinstance(c, ast.Constant) and c.value in VOCABULARY_WORDS]
            held = [o for o in operands if any(h in ast.unparse(o) for h in VOCABULARY_HOLDERS)
                    or ast.unparse(o) in ("state", "s")]
            if words and held:
                offenders.append(f"{path.relative_to(PKG)}:{node.lineno}: {ast.unparse(node)}")
    assert not offenders, "\n".join(offenders)
