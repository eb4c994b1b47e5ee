"""The exported C kit (`groundstation protocol export-c`), compiled with the system C
compiler and run against the Python side:

* frames the C code encodes are, byte for byte, the frames built here with `struct` and
  `zlib` from SPEC.md's rules, and decode in the Python codec to the values sent;
* byte streams made by the simulator's encoder, damaged (junk, sync words in junk, bad
  CRC, truncation, false headers) and cut into pieces, deframe in C into the same frames
  with the same counters as the Python StreamDeframer, after every piece;
* the C unpack functions read back what the Python side packed (the device's view);
* byte order is explicit: on this little-endian host the C code writes SPEC.md's
  big-endian worked examples;
* a change to the TOML changes the generated header and its hash constant.

The C driver is tests/fixtures/firmware_kit/driver.c plus driver_records.h, written
here from the dictionary.  The kit is compiled with -Werror and the sanitizers.
"""

from __future__ import annotations

import os
import random
import re
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from groundstation.codec import FrameCodec, StreamDeframer, decode_items
from groundstation.core.dictionary import Item, load_dictionary
from groundstation.firmware_kit import export_c, render_c
from groundstation.firmware_kit.layout import C_TYPES, default_table, lower, macro

ROOT = Path(__file__).resolve().parents[2]
DRIVER = ROOT / "tests" / "fixtures" / "firmware_kit" / "driver.c"
CODE = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i",
        "u64": "Q", "i64": "q", "f32": "f", "f64": "d"}
STRICT = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wconversion", "-Wsign-conversion",
          "-Wshadow", "-Wstrict-prototypes", "-Wmissing-prototypes", "-Wcast-align", "-Werror"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
RUN_ENV = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0", "UBSAN_OPTIONS": "halt_on_error=1"}
COUNTERS = ("frames", "bytes_in", "junk_bytes", "resyncs", "crc_errors", "version_errors",
            "unknown_packet_errors", "length_errors")


def gcc() -> str:
    path = shutil.which("gcc")
    if path is None:
        pytest.fail("gcc is not installed: run `make setup` (tools/system-deps.sh installs gcc "
                    "and libc6-dev), or `apt-get install gcc libc6-dev` as root")
    return path


def compile_c(sources: list[Path], out: Path, flags: list[str]) -> Path:
    res = subprocess.run([gcc(), *flags, "-o", str(out), *map(str, sources)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, f"gcc failed:\n{res.stderr}"
    return out


def run(exe: Path, mode: str, data: bytes) -> str:
    res = subprocess.run([str(exe), mode], input=data, capture_output=True, timeout=60, env=RUN_ENV)
    assert res.returncode == 0 and not res.stderr, res.stderr.decode(errors="replace")
    return res.stdout.decode()


# ------------------------------------------------------------------ the driver's records
def _setter(item: Item) -> str:
    name = lower(item.name)
    if item.is_variable:
        return (f"{{ v.{name}_len = parse_hex(vals[i], varbuf, sizeof varbuf); "
                f"v.{name} = varbuf; }}")
    ctype = {"f32": "float", "f64": "double"}.get(item.type)
    if ctype:
        return f"v.{name} = ({ctype})parse_float(vals[i]);"
    parse = "parse_uint" if item.type.startswith("u") else "parse_int"
    return f"v.{name} = ({C_TYPES[item.type][0]}){parse}(vals[i]);"


def _printer(item: Item) -> str:
    name = lower(item.name)
    if item.is_variable:
        return f'print_hex(" {item.name}=", v.{name}, v.{name}_len);'
    if item.type in ("f32", "f64"):
        return f'printf(" {item.name}=%a", (double)v.{name});'
    if item.type.startswith("u"):
        return f'printf(" {item.name}=%llu", (unsigned long long)v.{name});'
    return f'printf(" {item.name}=%lld", (long long)v.{name});'


def records_of(d) -> list[tuple[str, str, str, tuple[Item, ...]]]:
    """(kind, dictionary name, C base name, items) of every layout with items."""
    out = [("pkt", p.name, lower("hfb_pkt", p.name), p.items) for p in d.packets]
    for c in d.commands:
        for kind, items in (("args", c.args), ("reply", c.reply)):
            if items:
                out.append((kind, c.name, lower("hfb_cmd", c.name, kind), items))
    return out


def driver_records(d) -> str:
    lines = ["static uint8_t varbuf[HFB_MAX_PAYLOAD];",
             "static int packet_id_of(const char *name)", "{"]
    lines += [f'    if (strcmp(name, "{p.name}") == 0) return {macro("HFB_PKT", p.name, "ID")};'
              for p in d.packets]
    lines += ["    return -1;", "}", "static long opcode_of(const char *name)", "{"]
    lines += [f'    if (strcmp(name, "{c.name}") == 0) return {macro("HFB_CMD", c.name, "OPCODE")};'
              for c in d.commands]
    lines += ["    return -1;", "}"]
    for _, _, base, items in records_of(d):
        lines += [f"static size_t pack_{base}(int n, char **keys, char **vals, uint8_t *out, size_t cap)",
                  "{", f"    {base}_t v;", "    int i;", "    memset(&v, 0, sizeof v);",
                  "    for (i = 0; i < n; i++) {"]
        for k, item in enumerate(items):
            lines.append(f'        {"else " if k else ""}if (strcmp(keys[i], "{item.name}") == 0) {_setter(item)}')
        lines += ['        else { fprintf(stderr, "unknown field %s\\n", keys[i]); exit(3); }', "    }",
                  f"    return {base}_pack(&v, out, cap);", "}",
                  f"static void print_{base}(const uint8_t *in, size_t len)", "{", f"    {base}_t v;",
                  f'    if ({base}_unpack(&v, in, len) != 0) {{ fputs(" unpack-failed", stdout); return; }}']
        lines += [f"    {_printer(item)}" for item in items]
        lines.append("}")
    lines += ["static size_t pack_record(const char *kind, const char *name, int n, char **keys,",
              "                          char **vals, uint8_t *out, size_t cap)", "{"]
    for kind, name, base, _ in records_of(d):
        lines.append(f'    if (strcmp(kind, "{kind}") == 0 && strcmp(name, "{name}") == 0) '
                     f"return pack_{base}(n, keys, vals, out, cap);")
    lines += ["    return 0;", "}"]
    # decode side: a frame's payload, and for COMMAND / a COMPLETED RESPONSE the
    # arguments / reply of its opcode
    lines += ["static void print_payload(uint8_t id, const uint8_t *p, size_t len)", "{",
              "    hfb_pkt_command_t c;", "    hfb_pkt_response_t r;", "    switch (id) {"]
    for p in d.packets:
        lines += [f"    case {macro('HFB_PKT', p.name, 'ID')}:",
                  f'        fputs(" pkt {p.name}", stdout);',
                  f"        print_{lower('hfb_pkt', p.name)}(p, len);"]
        if p.name in ("COMMAND", "RESPONSE"):
            kind, var, struct_ = ("args", "c", "command") if p.name == "COMMAND" else ("reply", "r", "response")
            data = "arguments" if kind == "args" else "data"
            cond = "" if kind == "args" else f" && r.stage == HFB_PKT_RESPONSE_STAGE_COMPLETED"
            lines += [f"        if (hfb_pkt_{struct_}_unpack(&{var}, p, len) == 0{cond}) {{",
                      f"            switch ({var}.opcode) {{"]
            for cmd in d.commands:
                items = cmd.args if kind == "args" else cmd.reply
                if items:
                    lines += [f"            case {macro('HFB_CMD', cmd.name, 'OPCODE')}:",
                              f'                fputs(" | {kind} {cmd.name}", stdout);',
                              f"                print_{lower('hfb_cmd', cmd.name, kind)}({var}.{data}, {var}.{data}_len);",
                              "                break;"]
            lines += ["            default:", "                break;", "            }", "        }"]
        lines.append("        break;")
    lines += ["    default:", '        fputs(" unknown", stdout);', "    }", "}"]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary()


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


@pytest.fixture(scope="module")
def kit(tmp_path_factory, dictionary):
    """The kit exported and compiled: strict object, sanitized drivers (default buffer and
    the smallest allowed one, which makes a large feed go through in many passes)."""
    base = tmp_path_factory.mktemp("kit")
    export_c(dictionary, base)
    (base / "driver_records.h").write_text(driver_records(dictionary))
    shutil.copy(DRIVER, base / "driver.c")
    obj = compile_c([base / "hfb_protocol.c"], base / "hfb_protocol.o", [*STRICT, "-O2", "-c"])
    drivers = {}
    for name, extra in (("default", []), ("small", ["-DHFB_DEFRAMER_CAPACITY=1042u"])):
        drivers[name] = compile_c([base / "hfb_protocol.c", base / "driver.c"], base / f"driver_{name}",
                                  ["-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-g", *SANITIZE,
                                   f"-I{base}", *extra])
    return {"dir": base, "obj": obj, **drivers}


# ------------------------------------------------------------------ the Python side
def f32(x: float) -> float:
    return struct.unpack(">f", struct.pack(">f", x))[0]


def pack_items(items, values) -> bytes:
    """SPEC §3 with struct: each item big-endian, back to back; the variable item last."""
    out = b""
    for item in items:
        v = values[item.name]
        out += v if item.is_variable else struct.pack(">" + CODE[item.type], v)
    return out


def frame_bytes(d, pid: int, seq: int, tick: int, payload: bytes) -> bytes:
    """SPEC §2 with struct and zlib: header big-endian, CRC least significant byte first."""
    body = struct.pack(">2sBBHII", b"\xEB\x90", d.version_major, pid, len(payload), seq, tick) + payload
    return body + struct.pack("<I", zlib.crc32(body))


def random_raw(item: Item, rng: random.Random, special: bool = True):
    """A wire value of `item` (bytes for str/bytes items) that the dictionary allows."""
    if item.is_variable:
        n = rng.choice([0, 1, rng.randrange(2, 60)])
        if item.type == "str":
            return "".join(rng.choice("aZ 9_\u00b1\u00e9\u4e2d\U0001f600") for _ in range(n)).encode()
        return bytes(rng.randrange(256) for _ in range(n))
    if item.states:
        return rng.choice(sorted(item.states.values()))
    if item.bits:
        return sum(1 << b for b in item.bits.values() if rng.random() < 0.5)
    if item.type in ("f32", "f64"):
        if item.value_range is not None:
            x = rng.choice([item.value_range[0], item.value_range[1], rng.uniform(*item.value_range)])
        else:
            x = rng.choice([0.0, -0.0, 1.25, -0.5, rng.uniform(-1, 1) * 10.0 ** rng.randint(-40, 38)]
                           + ([float("inf"), float("-inf"), float("nan")] if special else []))
        return f32(x) if item.type == "f32" else x
    bits = C_TYPES[item.type][1] * 8
    lo, hi = (0, 2 ** bits - 1) if item.type.startswith("u") else (-2 ** (bits - 1), 2 ** (bits - 1) - 1)
    if item.value_range is not None:
        lo, hi = max(lo, int(np.ceil(item.value_range[0]))), min(hi, int(np.floor(item.value_range[1])))
    return rng.choice([lo, hi, rng.randint(lo, hi)])


def token(item: Item, v) -> str:
    if item.is_variable:
        return v.hex() or "-"
    return float(v).hex() if item.type in ("f32", "f64") else str(v)


def line_values(items, values) -> str:
    return " ".join(f"{i.name}={token(i, values[i.name])}" for i in items)


def same_wire(item: Item, a, b) -> bool:
    """Equal as sent: floats compared by their bits (NaN, -0.0), the rest by value."""
    if item.type in ("f32", "f64") and not item.is_variable:
        code = ">" + CODE[item.type]
        return struct.pack(code, a) == struct.pack(code, b)
    return a == b


def parse_c_value(item: Item, text: str):
    if item.is_variable:
        return b"" if text == "-" else bytes.fromhex(text)
    if item.type in ("f32", "f64"):
        try:
            return float.fromhex(text)
        except ValueError:
            return float(text.replace("-nan", "nan"))
    return int(text)


def feed_script(pieces) -> bytes:
    """deframe-mode input: ('D', bytes) feeds, 'F' flushes, 'R' starts a new deframer."""
    out = bytearray()
    for p in pieces:
        if p in ("F", "R"):
            out += p.encode()
        else:
            out += b"D" + struct.pack(">I", len(p)) + p
    return bytes(out)


def python_deframe(codec, pieces) -> list[tuple[list[bytes], tuple[int, ...]]]:
    """What the ground station's StreamDeframer does with the same pieces: per feed or
    flush, the frames (by packet id, in order within a packet) and the counters."""
    results = []
    deframer = StreamDeframer(codec)
    for p in pieces:
        if p == "R":
            deframer = StreamDeframer(codec)
            continue
        blocks = deframer.flush(0.0) if p == "F" else deframer.feed(p, 0.0)
        frames = []
        for b in blocks:
            frames += [r.tobytes() for r in b.raw] if b.raw is not None else list(b.frames)
        c = deframer.counters.as_dict()
        results.append((frames, tuple(c[k] for k in COUNTERS)))
    return results


def c_deframe(exe: Path, pieces) -> list[tuple[list[bytes], tuple[int, ...]]]:
    results, frames = [], []
    for line in run(exe, "deframe", feed_script(pieces)).splitlines():
        kind, _, rest = line.partition(" ")
        if kind == "frame":
            frames.append(bytes.fromhex(rest))
        else:
            # the Python decoder hands frames over grouped by packet id: so sort ours
            frames.sort(key=lambda f: f[3])
            results.append((frames, tuple(int(x) for x in rest.split())))
            frames = []
    return results


def sim_stream(seconds: float = 0.25) -> bytes:
    """The simulated device's real telemetry bytes (HIGH_RATE, HOUSEKEEPING, EVENT)."""
    from groundstation.sim import SimulatedDevice

    dev = SimulatedDevice(pacing="manual", seed=3)
    out: list[bytes] = []
    dev.run_fast(seconds, out.append, batch=50)
    return b"".join(out)


def split_frames(codec, data: bytes) -> list[bytes]:
    d = StreamDeframer(codec)
    blocks = d.feed(data, 0.0) + d.flush(0.0)
    assert d.counters.junk_bytes == 0
    frames = []
    for b in blocks:
        frames += [r.tobytes() for r in b.raw] if b.raw is not None else list(b.frames)
    return sorted(frames, key=lambda f: data.index(f))


def chop(data: bytes, rng: random.Random, big: bool = True) -> list[bytes]:
    """Pieces of 0 to 300 bytes, and (big=True) one piece far larger than the C buffer."""
    pieces, i = [], 0
    while i < len(data):
        n = rng.choice([0, 1, 2, 13, 14, 15, rng.randrange(1, 300)])
        if big and rng.random() < 0.05:
            n = 12000
        pieces.append(data[i:i + n])
        i += n
    return pieces


def damaged(d, codec, frames: list[bytes], rng: random.Random) -> bytes:
    """Frames with junk between them (some with sync words and false headers of every
    kind), corrupted CRCs, truncated frames, and frames hidden inside payloads."""
    hr = d.packet("HIGH_RATE")

    def false_header() -> bytes:
        kind = rng.randrange(5)
        pid, length, version = hr.id, hr.fixed_payload_size, d.version_major
        if kind == 0:
            version += 1
        elif kind == 1:
            pid = 0x55
        elif kind == 2:
            length += 1
        elif kind == 3:                      # plausible: holds later frames back
            pid, length = d.packet("EVENT").id, rng.randrange(3, 200)
        head = struct.pack(">2sBBHII", b"\xEB\x90", version, pid, length, 1, 2)
        return head[:rng.randrange(2, 15)] if kind == 4 else head

    out = bytearray()
    for frame in frames:
        r = rng.random()
        if r < 0.08:
            out += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
        elif r < 0.16:
            out += bytes(rng.randrange(256) for _ in range(rng.randrange(0, 5))) + false_header()
        elif r < 0.20:
            out += b"\xEB"
        r = rng.random()
        if r < 0.06:
            bad = bytearray(frame)
            bad[rng.randrange(2, len(bad))] ^= 1 << rng.randrange(8)
            out += bad
        elif r < 0.10:
            out += frame[:rng.randrange(2, len(frame))]
        elif r < 0.13:                       # a whole frame as an EVENT's text
            out += codec.frame(d.packet("EVENT").id, b"\x01\x00\x3C" + frame, rng.randrange(99), 7)
        else:
            out += frame
    if rng.random() < 0.5:
        out += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 30))) + b"\xEB"
    return bytes(out)


# ------------------------------------------------------------------ tests
def test_the_system_c_compiler_is_installed():
    """Without gcc every test here fails (the kit fixture too): this one says why first."""
    assert Path(gcc()).exists()


def test_byte_order_is_explicit_on_this_little_endian_host(kit, dictionary):
    lines = run(kit["default"], "selftest", b"").splitlines()
    facts = dict(line.split(" ", 1) for line in lines if not line.startswith("command "))
    commands = [line.split()[1:] for line in lines if line.startswith("command ")]
    want = []
    for c in sorted(dictionary.commands, key=lambda c: c.opcode):
        fixed = [sum(C_TYPES[i.type][1] for i in items if not i.is_variable) for items in (c.args, c.reply)]
        var = [int(bool(items) and items[-1].is_variable) for items in (c.args, c.reply)]
        want.append([c.name, str(c.opcode), str(fixed[0]), str(var[0]), str(fixed[1]), str(var[1]),
                     str(int(c.needs_session)), str(int(c.critical))])
    assert commands == want
    assert facts["host_order"] == sys.byteorder == "little", \
        "this check proves explicit byte order only on a little-endian host"
    assert facts["put_u32"] == "12345678"               # most significant byte first
    assert facts["put_i16"] == struct.pack(">h", -311).hex() == "fec9"
    assert facts["put_f32"] == struct.pack(">f", 1.25).hex() == "3fa00000"
    assert facts["put_f64"] == struct.pack(">d", -0.5).hex()
    assert facts["get_i32"] == "-42" and facts["get_u16"] == str(0xFFD6)
    assert facts["crc_check"] == "cbf43926"              # SPEC §2.1 check value
    assert facts["residue"] == "2144df1c"                # whole frame, CRC sent LSB first
    assert facts["refuses_short"] == "1"
    assert facts["dictionary_hash"] == f"{dictionary.hash:08x}"
    # SPEC §3.2: 0.0389 A is 389 counts; rounding to nearest; saturation, not wrapping;
    # the encoder example's 1 mrad is 683565 counts, as SPEC §13.1 and the codec have it
    hr = dictionary.packet("HIGH_RATE").item_by_name["encoder_outer"]
    assert facts["counts"].split() == ["389", "-312", "32767", "-32768", "0",
                                       str(int(hr.to_raw(0.001))), "0", "255"]
    from groundstation.params.table import default_values, pack

    spec_crc = f"{zlib.crc32(pack(dictionary, default_values(dictionary))):08x}"
    assert facts["default_table_crc"] == f"{spec_crc} {spec_crc}"
    assert default_table(dictionary) == pack(dictionary, default_values(dictionary))


def spec_examples() -> dict[str, bytes]:
    """SPEC.md §13's ```hex blocks: title -> frame bytes."""
    text = (ROOT / "protocol" / "SPEC.md").read_text(encoding="utf-8")
    out = {}
    for block in re.findall(r"^```hex\n(.*?)^```", text, re.S | re.M):
        title, data = "", bytearray()
        for line in block.splitlines():
            if line.startswith("#"):
                title = line[1:].strip()
            elif line.strip():
                data += bytes(int(x, 16) for x in line.partition(";")[0].split()[1:])
        out[title] = bytes(data)
    return out


def test_c_writes_the_spec_worked_examples(kit, codec, dictionary):
    """The C structs hold native values; the bytes out are SPEC.md's big-endian frames."""
    ex = spec_examples()
    hr_frame = ex["HIGH_RATE example frame"]
    raw = codec.decode_frame(hr_frame).raw[0]
    hr = dictionary.packet("HIGH_RATE")
    values = {i.name: raw[i.name].item() for i in hr.items}
    lines = [f"pkt HIGH_RATE {raw['sequence']} {raw['tick']} {line_values(hr.items, values)}",
             "args ARM 7 0x1234ABCD",
             "reply ARM 41 123500 7 1 0",
             "reply ARM 42 123501 7 3 0"]
    out = run(kit["default"], "encode", "\n".join(lines).encode() + b"\n").split()
    assert [bytes.fromhex(h) for h in out] == [
        hr_frame, ex["COMMAND example frame: ARM"], ex["RESPONSE example frame: ARM ACCEPTED"],
        ex["RESPONSE example frame: ARM COMPLETED"]]


def test_frames_encoded_in_c_decode_in_python_bit_for_bit(kit, codec, dictionary):
    rng = random.Random(20)
    d = dictionary
    lines, expected, checks = [], [], []
    for kind, name, _, items in records_of(d):
        for _ in range(25 if kind == "pkt" else 6):
            values = {i.name: random_raw(i, rng, special=kind == "pkt") for i in items}
            seq, tick = rng.randrange(2 ** 32), rng.randrange(2 ** 32)
            data = pack_items(items, values)
            if kind == "pkt":
                lines.append(f"pkt {name} {seq} {tick} {line_values(items, values)}")
                expected.append(frame_bytes(d, d.packet(name).id, seq, tick, data))
            elif kind == "args":
                token_ = rng.randrange(2 ** 32)
                lines.append(f"args {name} {seq} {token_} {line_values(items, values)}")
                payload = struct.pack(">IH", token_, d.command(name).opcode) + data
                expected.append(frame_bytes(d, d.packet("COMMAND").id, seq, 0, payload))
            else:
                cseq = rng.randrange(2 ** 32)
                lines.append(f"reply {name} {seq} {tick} {cseq} 3 0 {line_values(items, values)}")
                payload = struct.pack(">IHBH", cseq, d.command(name).opcode, 3, 0) + data
                expected.append(frame_bytes(d, d.packet("RESPONSE").id, seq, tick, payload))
            checks.append((kind, name, items, values))
    # the encoder refuses frames that break the length rules (SPEC §2) or have no id
    refused = [f"frame {d.packet('HIGH_RATE').id} 1 2 {'00' * 59}",
               f"frame {d.packet('HOUSEKEEPING').id} 1 2 {'00' * 46}",
               f"frame {d.packet('EVENT').id} 1 2 {'00' * (d.max_payload + 1)}",
               f"frame {d.packet('COMMAND').id} 1 2 {'00' * 5}",
               "frame 85 1 2 00"]
    for p in d.packets:                      # shortest and longest legal payloads
        lo, hi = codec.payload_limits[p.id]
        for n in sorted({lo, hi}):
            payload = bytes(rng.randrange(256) for _ in range(n))
            lines.append(f"frame {p.id} 5 6 {payload.hex() or '-'}")
            expected.append(frame_bytes(d, p.id, 5, 6, payload))
            checks.append(None)
    out = run(kit["default"], "encode", ("\n".join(lines + refused) + "\n").encode()).split()
    assert out[len(lines):] == ["refused"] * len(refused)
    for got, want, check in zip(out, expected, checks):
        frame = bytes.fromhex(got)
        assert frame == want, check
        block = codec.decode_frame(frame)       # strict: raises on any defect
        if check is None:
            continue
        kind, name, items, values = check
        if kind == "pkt" and block.raw is not None:
            decoded = {i.name: block.raw[i.name][0].item() for i in items}
        else:
            payload = frame[14:-4]
            if kind != "pkt":
                payload = payload[6:] if kind == "args" else payload[9:]
            decoded = decode_items(items, payload, name)
        for item in items:
            want_v = values[item.name]
            if item.type == "str":
                want_v = want_v.decode("utf-8", errors="replace")
            assert same_wire(item, decoded[item.name], want_v), (name, item.name)


def test_simulator_stream_deframes_in_c_with_the_same_frames_and_counters(kit, codec, dictionary):
    """Junk, a false header that holds frames back, a corrupted CRC, a truncated frame,
    a lone 0xEB at a piece's end, a sync word in the last bytes of a piece's last frame,
    and at the end a false header whose claimed span the stream never fills."""
    frames = split_frames(codec, sim_stream())
    assert {f[3] for f in frames} >= {1, 2, 3}           # HIGH_RATE, HOUSEKEEPING, EVENT
    bad_crc = bytearray(frames[5])
    bad_crc[30] ^= 0x40
    ev = dictionary.packet("EVENT")
    false_header = struct.pack(">2sBBHII", b"\xEB\x90", 1, ev.id, 500, 0, 0)
    sync_at_end = codec.encode("HIGH_RATE", {"profile_index": 0xEB90}, 77, 77,
                               engineering=False)                    # 0xEB 0x90 at offset 72
    stream = [b"\x00\x17junk\xEB\x90\x07", frames[0], frames[1], b"\xEB",
              frames[2] + frames[3][:40],                                      # truncated
              frames[4], bytes(bad_crc), frames[6], false_header,
              b"".join(frames[7:20]), b"".join(frames[20:-3]), b"trailing junk \xEB",
              sync_at_end + b"abc", frames[-3], false_header + frames[-2] + frames[-1], "F"]
    pieces = []
    for p in stream:
        pieces += [p] if p == "F" or p.startswith(sync_at_end) else [p[:len(p) // 2], p[len(p) // 2:]]
    want = python_deframe(codec, pieces)
    assert want[-1][1][COUNTERS.index("crc_errors")] >= 2       # the bad one and the cut one
    assert sum(len(f) for f, _ in want) == len(frames) - 1      # all but the bad and the cut
    assert want[-1][0] == [frames[-2], frames[-1]]              # found at the flush
    for exe in ("default", "small"):
        assert c_deframe(kit[exe], pieces) == want, exe


def test_damaged_random_streams_deframe_identically(kit, codec, dictionary):
    rng = random.Random(4)
    frames = split_frames(codec, sim_stream(0.1))
    extra = [codec.encode_variable("EVENT", {"level": "INFO", "code": 2, "text": "\u00eb\x90 sync"}, 9, 9),
             codec.frame(dictionary.packet("COMMAND").id, b"\x00" * 6 + b"\xEB\x90" * 20, 3, 0),
             codec.frame(dictionary.packet("RESPONSE").id, bytes(9) + b"\xEB" * 30, 8, 8)]
    pieces: list = []
    for _ in range(30):
        pick = rng.sample(frames, rng.randrange(1, 40)) + rng.sample(extra, rng.randrange(0, 3))
        rng.shuffle(pick)
        pieces += chop(damaged(dictionary, codec, pick, rng), rng) + ["F", "R"]
    want = python_deframe(codec, pieces)
    totals = np.sum([c for _, c in want], axis=0)
    assert all(totals[COUNTERS.index(k)] > 0 for k in COUNTERS), dict(zip(COUNTERS, totals))
    for exe in ("default", "small"):
        assert c_deframe(kit[exe], pieces) == want, exe


def test_c_unpacks_what_the_python_side_packs(kit, codec, dictionary):
    """The device's view: telemetry from the simulator and commands as a host sends them,
    read back by the generated unpack functions."""
    rng = random.Random(7)
    d = dictionary
    frames = split_frames(codec, sim_stream(0.05))
    expect = []
    for f in frames:
        pkt = d.packet(f[3])
        expect.append((pkt.name, f, decode_raw(pkt.items, f[14:-4]), None))
    for c in d.commands:
        for kind, items in (("args", c.args), ("reply", c.reply)):
            values = {i.name: random_raw(i, rng, special=False) for i in items}
            data = pack_items(items, values)
            if kind == "args":
                payload = struct.pack(">IH", rng.randrange(2 ** 32), c.opcode) + data
                pkt = d.packet("COMMAND")
            else:
                payload = struct.pack(">IHBH", rng.randrange(2 ** 32), c.opcode, 3, 0) + data
                pkt = d.packet("RESPONSE")
            f = codec.frame(pkt.id, payload, rng.randrange(2 ** 32), rng.randrange(2 ** 32))
            expect.append((pkt.name, f, decode_raw(pkt.items, payload),
                           (kind, c.name, items, values) if items else None))
    out = run(kit["default"], "decode", b"".join(f for _, f, _, _ in expect)).splitlines()
    assert len(out) == len(expect)
    for line, (name, f, values, sub) in zip(out, expect):
        head, _, tail = line.partition(" | ")
        seq, tick, _, got_name, *fields = head.split(" ")
        assert (int(seq), int(tick), got_name) == (*struct.unpack(">II", f[6:14]), name)
        pkt = d.packet(name)
        assert_fields(pkt.items, fields, values)
        if sub is None:
            assert not tail, line
            continue
        kind, cname, items, svalues = sub
        skind, sname, *sfields = tail.split(" ")
        assert (skind, sname) == (kind, cname)
        assert_fields(items, sfields, svalues)


def decode_raw(items, payload: bytes) -> dict:
    values, pos = {}, 0
    for item in items:
        if item.is_variable:
            values[item.name] = payload[pos:]
            continue
        code = ">" + CODE[item.type]
        values[item.name] = struct.unpack_from(code, payload, pos)[0]
        pos += struct.calcsize(code)
    return values


def assert_fields(items, fields: list[str], values: dict) -> None:
    got = dict(f.split("=", 1) for f in fields)
    assert list(got) == [i.name for i in items]
    for item in items:
        assert same_wire(item, parse_c_value(item, got[item.name]), values[item.name]), item.name


def test_kit_needs_only_the_c_standard_library_and_no_allocation(kit):
    res = subprocess.run(["nm", "-u", str(kit["obj"])], capture_output=True, text=True, check=True)
    undefined = {line.split()[-1] for line in res.stdout.splitlines() if line.strip()}
    assert undefined <= {"memcpy", "memmove", "memset"}, undefined
    text = (kit["dir"] / "hfb_protocol.c").read_text() + (kit["dir"] / "hfb_protocol.h").read_text()
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)          # code only, not the comments
    assert not re.search(r"\b(malloc|calloc|realloc|free|htonl|ntohl|__attribute__|#pragma)\b", text)
    assert set(re.findall(r"#include <([^>]+)>", text)) <= {"float.h", "stddef.h", "stdint.h", "string.h"}


def test_a_change_to_the_toml_regenerates_the_header_and_its_hash(tmp_path, dictionary):
    proto = tmp_path / "protocol"
    shutil.copytree(ROOT / "protocol", proto)
    text = (proto / "telemetry.toml").read_text()
    anchor = '  { name = "profile_index"'
    line = next(ln for ln in text.splitlines() if ln.startswith(anchor))
    text = text.replace(line, line + '\n  { name = "spare_counter", type = "u16", units = "counts", '
                        'description = "added by the test" },')
    (proto / "telemetry.toml").write_text(text)
    changed = load_dictionary(proto)
    assert changed.hash != dictionary.hash
    cli = [sys.executable, "-m", "groundstation"]
    for args, out in (([], tmp_path / "a"), (["--protocol-dir", str(proto)], tmp_path / "b"),
                      (["--protocol-dir", str(proto)], tmp_path / "c")):
        res = subprocess.run([*cli, *args, "protocol", "export-c", str(out)], capture_output=True,
                             text=True, timeout=60, cwd=ROOT)
        assert res.returncode == 0, res.stderr
        assert "hfb_protocol.h" in res.stdout
    old, new = ((tmp_path / x / "hfb_protocol.h").read_text() for x in "ab")
    assert old.encode() == render_c(dictionary)["hfb_protocol.h"].encode()
    assert f"#define HFB_DICTIONARY_HASH 0x{dictionary.hash:08X}u" in old
    assert f"#define HFB_DICTIONARY_HASH 0x{changed.hash:08X}u" in new
    assert "HFB_PKT_HIGH_RATE_SPARE_COUNTER_OFFSET 60u" in new and "SPARE_COUNTER" not in old
    assert re.search(r"#define HFB_PKT_HIGH_RATE_SIZE 62u", new)
    assert re.search(r"#define HFB_PKT_HIGH_RATE_FRAME_SIZE 80u", new)
    for name in ("hfb_protocol.h", "hfb_protocol.c"):       # deterministic: same TOML, same bytes
        assert (tmp_path / "b" / name).read_bytes() == (tmp_path / "c" / name).read_bytes()
    # the new layout compiles, and its frames decode with the changed dictionary
    build = tmp_path / "b"
    (build / "driver_records.h").write_text(driver_records(changed))
    shutil.copy(DRIVER, build / "driver.c")
    exe = compile_c([build / "hfb_protocol.c", build / "driver.c"], build / "driver",
                    ["-std=c99", "-Wall", "-Wextra", "-Werror", "-O0", f"-I{build}"])
    out = run(exe, "encode", b"pkt HIGH_RATE 1 2 mode=1 spare_counter=513\n")
    block = FrameCodec(changed).decode_frame(bytes.fromhex(out.strip()))
    assert block["spare_counter"][0] == 513 and block["mode"][0] == 1


def test_the_example_in_the_firmware_guide_compiles(kit):
    """docs/firmware.md sketches a controller with the kit: it must stay true to the
    header it describes."""
    text = (ROOT / "docs" / "firmware.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```c\n(.*?)^```", text, re.S | re.M)
    assert blocks, "docs/firmware.md has no C example"
    for k, code in enumerate(blocks):
        src = kit["dir"] / f"doc_example_{k}.c"
        src.write_text(code)
        compile_c([src], kit["dir"] / f"doc_example_{k}.o",
                  ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wconversion", "-Werror", "-c",
                   f"-I{kit['dir']}"])
