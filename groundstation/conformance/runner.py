"""Run the selected checks against one device, in an order that keeps the rig safe,
and leave it as found: disarmed, with its parameter table restored and verified."""

from __future__ import annotations

import logging
import time
import zlib
from typing import Callable

from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError, LinkError
from ..link.address import DeviceAddress
from . import exchange, framing, profiles, session, table, watchdog
from .check import Check
from .context import FAIL, PASS, SKIP, Context, Result, Skip, Verdict
from .probe import Host

log = logging.getLogger(__name__)

# session first (it opens and re-takes the session), the table before anything arms,
# motion after, and the framing checks last: they judge every frame of the whole run
ALL_CHECKS: list[Check] = (session.CHECKS + exchange.CHECKS + table.CHECKS + watchdog.CHECKS
                           + profiles.CHECKS + framing.CHECKS)
RESTORE = Check("§11.1", "device left as found: disarmed, table restored and verified",
                lambda ctx, v: None)


class CannotRun(GroundStationError):
    """The suite cannot start against this device (exit status 2)."""


class Unframed(Exception):
    """CONNECT got no answer we could accept, but bytes came back that fail §2/§4: that
    is a finding about the device (a FAIL), not a device we cannot reach."""

    def __init__(self, result: Result):
        super().__init__(result.name)
        self.result = result


def open_session(d: Dictionary, address: DeviceAddress) -> Host:
    host = Host(d, address)
    ex = host.connect()
    if ex.final is None:
        host.close()
        if host.report.faults:
            lines = [f"sent CONNECT; no RESPONSE frame passed the §2/§4 checks"]
            lines += [f"FAIL {kind.replace('_', ' ')}: {getattr(host.report, kind)} - e.g. {text}"
                      for kind, text in host.report.examples.items()]
            raise Unframed(Result("§2.1", "CRC of every packet", FAIL, lines))
        raise CannotRun(f"{address}: no answer to CONNECT ({host.lost or 'nothing came back'})")
    if ex.final.stage != 3:
        errors = {v: k for k, v in d.error_codes.items()}
        reason = errors.get(ex.final.reason, str(ex.final.reason))
        hint = {"SESSION_BUSY": "another host owns the session - end it there first",
                "DICTIONARY_MISMATCH": "the device was built from another dictionary"}.get(reason, "")
        host.close()
        raise CannotRun(f"{address}: CONNECT refused with {reason}" + (f" ({hint})" if hint else ""))
    return host


def run_checks(d: Dictionary, address: DeviceAddress, *, only: list[str], allow_motion: bool,
               say: Callable[[str], None], on_result: Callable[[Result], None]) -> list[Result]:
    try:
        host = open_session(d, address)
    except Unframed as bad:
        on_result(bad.result)
        return [bad.result]
    ctx = Context(d, address, allow_motion=allow_motion, host=host)
    results: list[Result] = []
    try:
        try:
            ctx.found_table = ctx.read_table()
        except (RuntimeError, LinkError) as exc:
            raise CannotRun(f"{address}: cannot read the parameter table to restore it "
                            f"later: {exc}") from None
        try:
            hk = ctx.housekeeping_after(ctx.latest_tick(timeout=5.0))
            ctx.found_version = hk["param_table_version"] if hk else None
        except RuntimeError as exc:      # no good telemetry: a finding, not a reason to stop
            say(f"warning: {exc}; the checks that need telemetry will fail")
        say(f"device {address}: parameter table of {len(ctx.found_table)} bytes, CRC "
            f"0x{zlib.crc32(ctx.found_table):08X}, version {ctx.found_version} - restored at the end")
        for check in ALL_CHECKS:
            if not check.selected_by(only):
                continue
            r = _run_one(ctx, check)
            results.append(r)
            on_result(r)
            if host.lost:
                break
        r = _restore(ctx)
        results.append(r)
        on_result(r)
    finally:
        ctx.close_others()
        try:
            host.exchange("DISCONNECT", {}, resend=False)
        except LinkError as exc:         # the link is gone already: no session left to end
            log.debug("DISCONNECT at the end of the suite: %s", exc)
        host.close()
    return results


def _run_one(ctx: Context, check: Check) -> Result:
    v = Verdict()
    t0 = time.monotonic()
    status = PASS
    try:
        check.run(ctx, v)
        status = FAIL if v.failures else PASS
    except Skip as why:
        v.lines.insert(0, f"skipped: {why}")
        status = SKIP
    except (LinkError, RuntimeError) as exc:
        v.expect(False, f"could not complete: {exc}")
        status = FAIL
    except Exception as exc:             # a malformed answer must not end the whole run
        v.expect(False, f"could not complete: {type(exc).__name__}: {exc}")
        status = FAIL
    finally:
        ctx.close_others()
        try:
            if not ctx.host.lost:
                ctx.ensure_session()
        except (LinkError, RuntimeError) as exc:
            v.expect(False, f"after the check: {exc}")
            status = FAIL
    return Result(check.section, check.title, status, v.lines, time.monotonic() - t0)


def _restore(ctx: Context) -> Result:
    """ABORT and DISARM; the found table back if it changed; verified by read-back,
    HOUSEKEEPING and a HIGH_RATE frame showing the drives off."""
    v = Verdict()
    t0 = time.monotonic()
    try:
        if ctx.host.lost:
            raise RuntimeError(f"link lost: {ctx.host.lost}")
        ctx.make_safe()
        blob = ctx.read_table()
        if blob != ctx.found_table:
            v.note(f"active table CRC 0x{zlib.crc32(blob):08X} differs from the one found: "
                   f"uploading it again")
            _, commit = ctx.upload_table(ctx.found_table, ctx.found_version or 0)
            v.expect(ctx.is_ok(commit), f"PARAM_COMMIT of the found table: {ctx.outcome(commit)}")
            blob = ctx.read_table()
        v.expect(blob == ctx.found_table, f"read-back equals the table found (CRC "
                 f"0x{zlib.crc32(blob):08X})")
        hk = ctx.housekeeping_after(ctx.latest_tick())
        v.expect(hk is not None and hk["param_table_crc"] == zlib.crc32(ctx.found_table)
                 and hk["param_table_version"] == (ctx.found_version or 0),
                 f"HOUSEKEEPING: crc 0x{(hk or {}).get('param_table_crc', 0):08X}, version "
                 f"{(hk or {}).get('param_table_version')} (found version {ctx.found_version})")
        hr = ctx.high_rate_after(ctx.host.mark(), lambda f: True, 3.0)
        v.expect(hr is not None and not hr["armed"], f"HIGH_RATE tick {hr and hr['tick']}: "
                 f"armed {hr and hr['armed']}")
    except (LinkError, RuntimeError) as exc:
        v.expect(False, f"could not restore: {exc}")
    return Result(RESTORE.section, RESTORE.title, FAIL if v.failures else PASS, v.lines,
                  time.monotonic() - t0)
