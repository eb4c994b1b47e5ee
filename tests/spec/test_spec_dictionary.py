"""protocol/SPEC.md's statements about the dictionary checked against the ground station:
the §5.1 HIGH_RATE layout table and the §8 dictionary-hash recipe."""

from __future__ import annotations

import re
import struct

import pytest
from spec_helpers import PROTOCOL, load_toml, spec_text

from groundstation.core.dictionary import load_dictionary


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary(PROTOCOL)


def test_spec_high_rate_table_matches_codec(dictionary):
    """§5.1's layout table agrees with PacketDef.frame_dtype and the TOML scales."""
    pkt = dictionary.packet("HIGH_RATE")
    dt = pkt.frame_dtype
    section = spec_text().split("### 5.1 HIGH_RATE")[1].split("### 5.2")[0]
    rows = re.findall(r"^\| (\d+) \| (\d+|—) \| [`*](\w+)[`*][^|]*\| ([^|]+)\| (\d+) \| ([^|]+)\|",
                      section, re.M)
    assert [r[2] for r in rows] == list(dt.names)
    for frame_off, payload_off, name, _type, size, conv in rows:
        assert int(frame_off) == dt.fields[name][1], name
        assert int(size) == dt.fields[name][0].itemsize, name
        if payload_off != "—":
            assert int(payload_off) == dt.fields[name][1] - 14, name
            item = pkt.item_by_name[name]
            m = re.match(r"\s*([0-9.]+e-?\d+|[0-9.]+)\b", conv)
            if item.scale is not None:
                assert m and float(m.group(1)) == item.scale, name
            else:
                assert not m, name
    assert dt.itemsize == 78


def test_spec_dictionary_hash_recipe(dictionary):
    """§8's recipe, followed with hashlib + json + tomllib, gives the codec's hash."""
    import hashlib
    import json

    docs = {"telemetry": load_toml("telemetry.toml"), "commands": load_toml("commands.toml"),
            "parameters": load_toml("parameters.toml")}
    canonical = json.dumps(docs, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    digest = hashlib.sha256(canonical.encode("ascii")).digest()
    assert struct.unpack(">I", digest[:4])[0] == dictionary.hash
