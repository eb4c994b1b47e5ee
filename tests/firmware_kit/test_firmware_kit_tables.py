"""The kit's tables and its other-version hook, compiled and run:

* hfb_params[] and every command's args[] say what the ground station's own reading of
  the dictionary says (groundstation.core.dictionary, groundstation.params.table):
  ids, names, types, offsets, shapes, ranges (f32 ones rounded to float), the sos flag,
  states, units, and each entry's default bytes;
* hfb_value_in_range / hfb_arg_valid judge values as SPEC 3.2 and 11.1 do (compared in
  the item's own type; NaN and infinities out), at and one step beyond every bound;
* the same TOML gives the same bytes, and an entry added to the TOML shows up in the
  tables with no other change;
* a frame with another version byte is handed to the handler set with
  hfb_deframer_on_other_version when its CRC is good, whole or in pieces, also through
  the smallest buffer - and the counters stay those of the Python deframer.
"""

from __future__ import annotations

import shutil
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from groundstation.codec import FrameCodec
from groundstation.core.dictionary import load_dictionary
from groundstation.firmware_kit import export_c, render_c
from groundstation.params.table import default_values, pack, table_dtype
from test_firmware_kit_c import (COUNTERS, ROOT, RUN_ENV, SANITIZE, STRICT, compile_c, feed_script,
                                 python_deframe, run, sim_stream, split_frames)

SIZES = {"u8": 1, "i8": 1, "u16": 2, "i16": 2, "u32": 4, "i32": 4, "u64": 8, "i64": 8,
         "f32": 4, "f64": 8}
CODE = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i",
        "u64": "Q", "i64": "q", "f32": "f", "f64": "d"}

# A small program on the kit alone: `tables` prints the tables, `check` judges values
# read from stdin, `other` deframes a feed script with the other-version handler set.
PROGRAM = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hfb_protocol.h"

static const char *const TYPES[] = {"u8", "i8", "u16", "i16", "u32", "i32", "u64", "i64",
                                    "f32", "f64", "str", "bytes"};

static void hex(const uint8_t *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++) {
        printf("%02x", p[i]);
    }
    if (n == 0u) {
        printf("-");
    }
}

static void tables(void)
{
    size_t i;
    unsigned k;
    for (i = 0; i < HFB_PARAM_ENTRIES; i++) {
        const hfb_param_info_t *e = &hfb_params[i];
        printf("param %u %s %s %u %lu %lu %u", (unsigned)e->id, e->name, TYPES[e->type],
               (unsigned)e->element_size, (unsigned long)e->offset, (unsigned long)e->count,
               (unsigned)e->dims);
        for (k = 0; k < HFB_PARAM_MAX_DIMS; k++) {
            printf(" %lu", (unsigned long)e->shape[k]);
        }
        printf(" %a %a %u [%s] ", e->min, e->max, (unsigned)e->sos, e->units);
        hex(e->defaults, (size_t)e->count * e->element_size);
        printf(" %d\n", hfb_param_info(e->id) == e);
    }
    for (i = 0; i < 0x10000u; i++) {
        const hfb_command_info_t *c = hfb_command_info((uint16_t)i);
        if (c == NULL) {
            continue;
        }
        printf("command %lu %s %u\n", (unsigned long)i, c->name, (unsigned)c->arg_count);
        for (k = 0; k < c->arg_count; k++) {
            const hfb_arg_info_t *a = &c->args[k];
            unsigned s;
            printf("arg %lu %s %s %u %u %a %a [%s]", (unsigned long)i, a->name, TYPES[a->type],
                   (unsigned)a->offset, (unsigned)a->has_range, a->min, a->max, a->units);
            for (s = 0; s < a->state_count; s++) {
                printf(" %lld", (long long)a->states[s]);
            }
            printf("\n");
        }
    }
}

/* stdin lines: "param ID INDEX HEX" (the element's bytes) or "arg OPCODE INDEX HEX" (the
   whole argument bytes); stdout: 1 or 0 */
static void check(void)
{
    char kind[16], data[2100];
    unsigned long id, index;
    while (scanf("%15s %lu %lu %2099s", kind, &id, &index, data) == 4) {
        uint8_t bytes[1100];
        size_t n = 0;
        unsigned b;
        while (data[2 * n] && sscanf(data + 2 * n, "%2x", &b) == 1) {
            bytes[n++] = (uint8_t)b;
        }
        if (strcmp(kind, "param") == 0) {
            const hfb_param_info_t *e = hfb_param_info((uint16_t)id);
            printf("%d\n", hfb_value_in_range(e->type, bytes, e->min, e->max));
        } else {
            const hfb_command_info_t *c = hfb_command_info((uint16_t)id);
            printf("%d\n", hfb_arg_valid(&c->args[index], bytes));
        }
    }
}

static void on_frame(void *context, const uint8_t *frame, size_t length)
{
    (void)context;
    printf("frame ");
    hex(frame, length);
    printf("\n");
}

static void on_other(void *context, const uint8_t *frame, size_t length)
{
    printf("other %s ", (const char *)context);
    hex(frame, length);
    printf("\n");
}

static hfb_deframer_t rx;
static uint8_t piece[1u << 16];

static void other(void)
{
    int kind;
    static char context[] = "ctx";
    hfb_deframer_init(&rx, on_frame, context);
    hfb_deframer_on_other_version(&rx, on_other);
    while ((kind = getchar()) != EOF) {
        const hfb_framing_counters_t *c = &rx.counters;
        if (kind == 'D') {
            uint8_t len[4];
            size_t n;
            if (fread(len, 1, 4, stdin) != 4) {
                exit(3);
            }
            n = (size_t)hfb_get_u32(len);
            if (n > sizeof piece || fread(piece, 1, n, stdin) != n) {
                exit(3);
            }
            hfb_deframer_feed(&rx, piece, n);
        } else if (kind == 'F') {
            hfb_deframer_flush(&rx);
        } else {
            exit(3);
        }
        printf("counters %lu %lu %lu %lu %lu %lu %lu %lu\n", (unsigned long)c->frames,
               (unsigned long)c->bytes_in, (unsigned long)c->junk_bytes, (unsigned long)c->resyncs,
               (unsigned long)c->crc_errors, (unsigned long)c->version_errors,
               (unsigned long)c->unknown_packet_errors, (unsigned long)c->length_errors);
    }
}

int main(int argc, char **argv)
{
    if (argc == 2 && strcmp(argv[1], "tables") == 0) {
        tables();
    } else if (argc == 2 && strcmp(argv[1], "check") == 0) {
        check();
    } else if (argc == 2 && strcmp(argv[1], "other") == 0) {
        other();
    } else {
        return 2;
    }
    return 0;
}
"""


def build(directory: Path, dictionary, extra: tuple[str, ...] = ()) -> Path:
    """Export the kit for `dictionary` into `directory` and compile the program on it:
    strict warnings as errors (-std=c99 -pedantic ...), with the sanitizers."""
    export_c(dictionary, directory)
    (directory / "tables.c").write_text(PROGRAM)
    compile_c([directory / "hfb_protocol.c"], directory / "kit.o", [*STRICT, "-O2", "-c"])
    return compile_c([directory / "hfb_protocol.c", directory / "tables.c"], directory / "tables",
                     ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O1", "-g",
                      *SANITIZE, f"-I{directory}", *extra])


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary()


@pytest.fixture(scope="module")
def program(tmp_path_factory, dictionary):
    return build(tmp_path_factory.mktemp("tables"), dictionary)


# ------------------------------------------------------------------ what Python says
def rounded(value: float, wire_type: str) -> float:
    """A bound as compared in the item's type (SPEC 3.2): f32 ones rounded to float."""
    return float(np.float32(value)) if wire_type == "f32" else float(value)


def expected_tables(d) -> list[str]:
    """The lines `tables` must print, from the ground station's reading of the TOML."""
    dt = table_dtype(d)
    blob = pack(d, default_values(d))
    dims = max([1] + [len(p.shape) for p in d.parameters])
    lines = []
    for p in d.parameters:
        offset = dt.fields[p.name][1]
        count = int(np.prod(p.shape, dtype=np.int64)) if p.shape else 1
        size = SIZES[p.type]
        shape = " ".join(str(n) for n in list(p.shape) + [0] * (dims - len(p.shape)))
        lo, hi = (rounded(v, p.type).hex() for v in p.value_range)
        lines.append(f"param {p.id} {p.name} {p.type} {size} {offset} {count} {len(p.shape)} {shape} "
                     f"{lo} {hi} {int(p.filter == 'sos')} [{p.units}] "
                     f"{blob[offset:offset + count * size].hex()} 1")
    for c in sorted(d.commands, key=lambda c: c.opcode):
        lines.append(f"command {c.opcode} {c.name} {len(c.args)}")
        offset = 0
        for item in c.args:
            if item.value_range is not None:
                lo, hi = (rounded(v, item.type).hex() for v in item.value_range)
            else:
                lo = hi = (0.0).hex()
            states = "".join(f" {v}" for v in item.states.values())
            lines.append(f"arg {c.opcode} {item.name} {item.type} {offset} "
                         f"{int(item.value_range is not None)} {lo} {hi} [{item.units}]{states}")
            offset += 0 if item.is_variable else SIZES[item.type]
    return lines


def c_floats(line: str) -> str:
    """printf's %a and Python's float.hex spell the same number differently (0x1p+0 /
    0x1.0000000000000p+0): respell every hex float of a line as Python does."""
    return " ".join(float.fromhex(w).hex() if w.startswith(("0x", "-0x")) else w
                    for w in line.split(" "))


def test_tables_agree_with_the_dictionary(program, dictionary):
    got = [c_floats(line) for line in run(program, "tables", b"").splitlines()]
    assert got == expected_tables(dictionary)
    # what the device relies on: the entries tile the table in id order, no gap, no overlap
    params = [line.split() for line in got if line.startswith("param ")]
    ends = [int(p[5]) + int(p[4]) * int(p[6]) for p in params]
    assert [int(p[5]) for p in params] == [0] + ends[:-1]
    assert ends[-1] == table_dtype(dictionary).itemsize == 4008          # SPEC 11.1


def near(value: float, wire_type: str, up: bool) -> float:
    """The next value of the type beyond `value` (one ulp of f32/f64, one count else)."""
    if wire_type == "f32":
        return float(np.nextafter(np.float32(value), np.float32(np.inf if up else -np.inf)))
    if wire_type == "f64":
        return float(np.nextafter(value, np.inf if up else -np.inf))
    return value + (1 if up else -1)


def candidates(wire_type: str, lo: float, hi: float) -> list:
    if wire_type in ("f32", "f64"):
        lo_t, hi_t = rounded(lo, wire_type), rounded(hi, wire_type)
        vals = [lo, hi, lo_t, hi_t, near(lo_t, wire_type, False), near(hi_t, wire_type, True),
                near(lo_t, wire_type, True), near(hi_t, wire_type, False), 0.0, -0.0,
                float("nan"), float("inf"), float("-inf"), (lo + hi) / 2]
        return [v for v in vals if wire_type == "f64" or abs(v) < 3.4e38 or not np.isfinite(v)]
    bits = SIZES[wire_type] * 8
    tlo, thi = (0, 2 ** bits - 1) if wire_type[0] == "u" else (-2 ** (bits - 1), 2 ** (bits - 1) - 1)
    vals = {tlo, thi, 0, 1}
    for b in (lo, hi):
        for v in (int(np.floor(b)) - 1, int(np.floor(b)), int(np.ceil(b)), int(np.ceil(b)) + 1):
            vals.add(v)
    return sorted(v for v in vals if tlo <= v <= thi)


def in_type(value, wire_type: str, lo: float, hi: float) -> bool:
    """SPEC 3.2 / 11.1 rules 1-2 in Python: finite, and within the bounds in the type."""
    if wire_type in ("f32", "f64"):
        if not np.isfinite(value):
            return False
        if wire_type == "f32":
            return bool(np.float32(lo) <= np.float32(value) <= np.float32(hi))
        return lo <= value <= hi
    return lo <= value <= hi                    # Python compares int and float exactly


def test_range_checks_judge_as_the_spec_does(program, dictionary):
    lines, want = [], []
    for p in dictionary.parameters:
        for v in candidates(p.type, *p.value_range):
            lines.append(f"param {p.id} 0 {struct.pack('>' + CODE[p.type], v).hex()}")
            want.append(in_type(v, p.type, *p.value_range))
    for c in dictionary.commands:
        fixed = [i for i in c.args if not i.is_variable]
        for k, item in enumerate(fixed):
            lo, hi = item.value_range if item.value_range is not None else (-1e300, 1e300)
            values = candidates(item.type, lo, hi) + sorted(item.states.values())
            for v in values:
                args = b"".join(struct.pack(">" + CODE[i.type], v if i is item else 0) for i in fixed)
                lines.append(f"arg {c.opcode} {k} {(args + b'tail').hex()}")
                ok = in_type(v, item.type, lo, hi)
                if item.value_range is not None:
                    ok = ok and item.in_range(v)
                if item.states:
                    ok = ok and v in item.states.values()
                want.append(ok)
    got = run(program, "check", ("\n".join(lines) + "\n").encode()).split()
    assert [g == "1" for g in got] == want
    # the cases SPEC 3.2 names: the f32 defaults at their own bound, the NaN reference
    assert any(w for w, line in zip(want, lines) if line.endswith(struct.pack(">f", 81.3).hex()))
    assert sum(not w for w in want) > 50 and sum(want) > 50


def test_same_toml_same_bytes_and_a_new_entry_needs_no_hand_edit(tmp_path, dictionary):
    assert render_c(dictionary) == render_c(load_dictionary())
    for text in render_c(dictionary).values():
        text.encode("ascii")                                       # ASCII, or this raises
    proto = tmp_path / "protocol"
    shutil.copytree(ROOT / "protocol", proto)
    with (proto / "parameters.toml").open("a") as f:
        f.write('\n[[parameter]]\nid = 30\nname = "spare_gains"\ntype = "f32"\nshape = [2, 3]\n'
                'units = "1/s"\nrange = [-0.349, 2.5]\ndefault = [[0.1, 0.2, 0.3], [1.0, 2.0, 2.5]]\n'
                'description = "added by the test"\n')
    text = (proto / "commands.toml").read_text()
    text = text.replace('range = [-0.349, 0.349], description = "Angle reference"',
                        'range = [-0.25, 0.3], description = "Angle reference"')
    (proto / "commands.toml").write_text(text)
    changed = load_dictionary(proto)
    first = render_c(changed)
    assert first == render_c(load_dictionary(proto))               # deterministic
    assert first != render_c(dictionary)
    exe = build(tmp_path / "kit", changed)
    for name, text in first.items():
        assert (tmp_path / "kit" / name).read_bytes() == text.encode("ascii")
    got = [c_floats(line) for line in run(exe, "tables", b"").splitlines()]
    assert got == expected_tables(changed)
    assert any(line.startswith("param 30 spare_gains f32 4 4008 6 2 2 3 ") for line in got)


# ------------------------------------------------------------------ other versions
def other_frame(d, codec, version: int, opcode: int, args: bytes, seq: int) -> bytes:
    """A COMMAND frame as a host of another major version sends it (SPEC 7: the header
    and the COMMAND payload keep their layout)."""
    payload = struct.pack(">IH", 0, opcode) + args
    body = struct.pack(">2sBBHII", b"\xEB\x90", version, d.packet("COMMAND").id, len(payload),
                       seq, 0) + payload
    return body + struct.pack("<I", zlib.crc32(body))


def c_other(exe: Path, pieces):
    """(frames accepted, frames of another version surfaced, counters) per piece."""
    results, frames, others = [], [], []
    for line in run(exe, "other", feed_script(pieces)).splitlines():
        kind, _, rest = line.partition(" ")
        if kind == "frame":
            frames.append(bytes.fromhex(rest))
        elif kind == "other":
            ctx, _, data = rest.partition(" ")
            assert ctx == "ctx"                                     # the deframer's context
            others.append(bytes.fromhex(data))
        else:
            frames.sort(key=lambda f: f[3])
            results.append((frames, others, tuple(int(x) for x in rest.split())))
            frames, others = [], []
    return results


@pytest.mark.parametrize("capacity", [None, 1042])
def test_frames_of_another_version_are_surfaced_without_changing_framing(tmp_path, dictionary,
                                                                          capacity):
    d = dictionary
    codec = FrameCodec(d)
    extra = () if capacity is None else (f"-DHFB_DEFRAMER_CAPACITY={capacity}u",)
    exe = build(tmp_path, d, extra)
    good = split_frames(codec, sim_stream(0.05))
    connect = struct.pack(">BBIHB", 2, 0, 0x12345678, 5021, 0)
    v2 = other_frame(d, codec, 2, 0x0001, connect, 7)
    v0 = other_frame(d, codec, 0, 0x0003, b"", 8)
    big = other_frame(d, codec, 3, 0x0021, bytes(range(256)) * 3 + b"\xEB\x90\x01", 9)  # 1018 + 6 bytes
    bad = bytearray(other_frame(d, codec, 2, 0x0001, connect, 10))
    bad[20] ^= 1                                                    # CRC no longer matches
    cut = other_frame(d, codec, 2, 0x0001, connect, 11)
    pieces = [b"junk\xEB", v2[:1], v2[1:9], v2[9:20], v2[20:] + good[0],   # in pieces, after a lone 0xEB
              good[1] + v0 + good[2],                                      # whole, between frames
              bytes(bad) + good[3],                                        # bad CRC: not surfaced
              big[:500], big[500:] + good[4],                              # the largest frame, in two
              b"".join(good[5:40]) + v2 + b"".join(good[40:]),             # one feed beyond the buffer
              good[-1] + cut[:30], "F"]                                    # cut by the end of the stream
    got = c_other(exe, pieces)
    want = python_deframe(codec, pieces)
    assert [(f, c) for f, _, c in got] == want                     # framing: the host's, unchanged
    surfaced = [o for _, others, _ in got for o in others]
    assert surfaced == [v2, v0, big, v2]
    assert [len(others) for _, others, _ in got] == [0, 0, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0]
    assert want[-1][1][COUNTERS.index("version_errors")] >= 6
