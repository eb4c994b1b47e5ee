"""protocol/SPEC.md §13: the worked examples, read out of SPEC.md itself and decoded by the
ground station's `FrameCodec.decode_frame`, so the document cannot drift from the code."""

from __future__ import annotations

import re
import struct
import zlib

import pytest
from spec_helpers import HEADER, PROTOCOL, RESIDUE, assert_item, parse_number, spec_text

from groundstation.codec import FrameCodec
from groundstation.core.dictionary import load_dictionary


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary(PROTOCOL)


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


def spec_hex_examples() -> list[tuple[str, bytes, list[tuple[str, str, str]]]]:
    """```hex blocks: (title, frame bytes, [(field, value text, rest of annotation)])."""
    examples = []
    for block in re.findall(r"^```hex\n(.*?)^```", spec_text(), re.S | re.M):
        title, data, notes = "", bytearray(), []
        for line in block.splitlines():
            if line.startswith("#"):
                title = line[1:].strip()
                continue
            if not line.strip():
                continue
            code, _, note = line.partition(";")
            fields = code.split()
            assert int(fields[0]) == len(data), f"{title}: offset column out of step: {line}"
            data += bytes(int(x, 16) for x in fields[1:])
            m = re.match(r"\s*(\w+) = (\S+)\s*(.*)", note)
            assert m, f"{title}: annotation not 'name = value': {line}"
            notes.append(m.groups())
        examples.append((title, bytes(data), notes))
    return examples


def test_spec_worked_examples_decode_as_stated(codec, dictionary):
    examples = spec_hex_examples()
    titles = [t for t, _, _ in examples]
    assert len(examples) >= 4, titles
    assert any(t.startswith("HIGH_RATE") for t in titles)
    assert any("ARM" in t and t.startswith("COMMAND") for t in titles)
    assert any("ACCEPTED" in t for t in titles) and any("COMPLETED" in t for t in titles)

    for title, frame, notes in examples:
        block = codec.decode_frame(frame)
        pkt = block.packet
        assert title.split()[0] == pkt.name
        assert zlib.crc32(frame) == RESIDUE
        # the annotated fields are the frame's fields, in wire order
        expected_order = ["sync", "version", "packet_id", "length", "sequence", "tick"]
        expected_order += [i.name for i in pkt.fixed_items] + ["crc"]
        assert [n for n, _, _ in notes] == expected_order, title
        sync, version, pid, length, seq, tick = HEADER.unpack_from(frame)
        header = {"sync": int.from_bytes(sync, "big"), "version": version, "packet_id": pid,
                  "length": length, "sequence": seq, "tick": tick,
                  "crc": struct.unpack("<I", frame[-4:])[0]}
        assert header["crc"] == zlib.crc32(frame[:-4])
        assert length == len(frame) - 18
        items = pkt.item_by_name
        for name, value_text, rest in notes:
            value = parse_number(value_text)
            if name in header:
                assert header[name] == value, (title, name)
                if name in ("sequence", "tick"):
                    assert block.columns[name][0] == value
                continue
            item = items[name]
            decoded = block.columns[name][0]
            assert_item(item.scale, item.type, decoded, value, f"{title}: {name}")
            label = re.match(r"\((\w+)", rest)
            if item.states and label:
                assert item.states[label.group(1)] == value, (title, name)
            if item.bits:
                named = {flag: int(bit) for bit, flag in re.findall(r"(\d+) (\w+)", rest)}
                for flag, bit in item.bits.items():
                    assert bool(block.columns[flag][0]) == (flag in named), (title, flag)
                    if flag in named:
                        assert named[flag] == bit
            if name == "opcode" and label:
                assert dictionary.command(label.group(1)).opcode == value
            if "raw" in rest:                               # "(raw N counts)"
                raw = int(re.search(r"raw (-?\d+)", rest).group(1))
                assert int(block.raw[name][0]) == raw, (title, name)
        if pkt.name == "COMMAND":
            assert block.columns["arguments"][0] == b""
        if pkt.name == "RESPONSE":
            assert block.columns["data"][0] == b""


def test_arm_exchange_is_consistent():
    """The three ARM frames of §13.2 belong together (sequence, token, opcode, stages)."""
    frames = {t: f for t, f, _ in spec_hex_examples()}
    cmd = frames["COMMAND example frame: ARM"]
    acc = frames["RESPONSE example frame: ARM ACCEPTED"]
    com = frames["RESPONSE example frame: ARM COMPLETED"]
    assert HEADER.unpack_from(cmd)[4] == 7 and HEADER.unpack_from(cmd)[5] == 0
    assert struct.unpack_from(">IH", cmd, 14) == (0x1234ABCD, 0x0011)
    assert struct.unpack_from(">IHBH", acc, 14) == (7, 0x0011, 1, 0)
    assert struct.unpack_from(">IHBH", com, 14) == (7, 0x0011, 3, 0)
    assert HEADER.unpack_from(com)[4] == HEADER.unpack_from(acc)[4] + 1
