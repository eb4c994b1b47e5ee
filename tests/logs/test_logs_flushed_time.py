"""The time a log reports as "flushed up to" (LogFile.last_host_time, sent with every
Flushed and Failed) is the newest arrival it holds, of any packet: one append groups its
blocks by packet, and the last group written need not hold the newest frame."""

from __future__ import annotations

from groundstation.logs import LogFile

from test_logs_reader import _simulate


def test_last_host_time_is_the_newest_arrival_of_any_packet(dictionary, tmp_path):
    fed = _simulate(dictionary, 1.0, lambda block: None)
    housekeeping = [b for b in fed if b.name == "HOUSEKEEPING"][-1]
    older_high_rate = [b for b in fed if b.name == "HIGH_RATE"
                       and b.host_time.max() < housekeeping.host_time.min()][-1]
    newest = float(housekeeping.host_time.max())
    lf = LogFile(tmp_path / "t.h5", dictionary)
    try:
        # HOUSEKEEPING first: its group is written first, the older HIGH_RATE one last
        lf.append([housekeeping, older_high_rate])
        assert lf.last_host_time == newest
        lf.append([older_high_rate])            # an older arrival never moves it back
        assert lf.last_host_time == newest
    finally:
        lf.close()
