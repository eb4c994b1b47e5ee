"""SPEC §9.1: the watchdog comparison, on the simulated device.

The table's `watchdog_timeout` is an f32: 0.7 s is stored as 0.699999988..., and
1200 x that, computed in double, is 839.99998... ticks. SPEC says the watchdog trips in the
first period whose whole number of ticks since the reset is greater than that product, so
in the 840th period after the reset, not the 841st.
"""

from __future__ import annotations

import struct
import zlib

from groundstation.params import table as ptable


def test_watchdog_of_0_7_s_trips_in_the_840th_period_after_the_reset(client, device, dictionary):
    assert 1200 * struct.unpack(">f", struct.pack(">f", 0.7))[0] < 840
    client.connect()
    blob = ptable.pack(dictionary, {**ptable.default_values(dictionary), "watchdog_timeout": 0.7})
    client.command("PARAM_BEGIN", table_version=1, table_length=len(blob))
    for off in range(0, len(blob), 700):
        client.command("PARAM_WRITE", offset=off, data=blob[off:off + 700])
    client.command("PARAM_COMMIT", table_crc=zlib.crc32(blob))
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")                     # the last reset of the watchdog
    device.run_ticks(839)
    assert not device.faulted
    device.run_ticks(1)
    assert device.faulted
