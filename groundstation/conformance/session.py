"""§7 session and §8 dictionary hash: token, ownership, take-over, other hosts, ABORT."""

from __future__ import annotations

from .check import Check
from .context import Context, Verdict


def _another_or_the_line(ctx: Context, v: Verdict):
    """A second host over TCP; on a serial link (one host) the line itself, which is just
    as good for what needs no session: the owner's own CONNECT is refused on the
    dictionary before anything else (§7 step 1), and ABORT takes any token."""
    if ctx.address.kind == "tcp":
        v.note("from a second TCP connection (another host, §7)")
        return ctx.other_host()
    v.note("on the serial line (a single host there)")
    return ctx.host


def connect_reply(ctx: Context, v: Verdict) -> None:
    """§7/§8: the CONNECT that opened this run's session, and a fresh CONNECT by the owner."""
    h = ctx.host
    ex = h.connect()             # the owner's own connection: never busy, a fresh session
    v.note(f"sent CONNECT (hash 0x{ctx.d.hash:08X}, take_over 0) on the owner's connection")
    v.note(f"got {ctx.outcome(ex)}")
    if not v.expect(ctx.is_ok(ex), "§7: a CONNECT on the owner's own connection is never "
                                   "busy: ACCEPTED then COMPLETED"):
        return
    r = h.reply(ex, "CONNECT")
    v.expect(r["session_token"] != 0, f"§7: session_token non-zero (0x{r['session_token']:08X})")
    v.expect(r["protocol_major"] == ctx.d.version_major and r["protocol_minor"] == ctx.d.version_minor,
             f"§7: device protocol {r['protocol_major']}.{r['protocol_minor']}, ours "
             f"{ctx.d.version_major}.{ctx.d.version_minor}")
    v.expect(r["dictionary_hash"] == ctx.d.hash, f"§8: dictionary hash 0x{r['dictionary_hash']:08X}"
             f", ours 0x{ctx.d.hash:08X}")
    ex2 = h.connect()
    r2 = h.reply(ex2, "CONNECT") if ctx.is_ok(ex2) else {"session_token": None}
    v.expect(r2["session_token"] not in (None, 0, r["session_token"]),
             "§7: each CONNECT gives a new token (two CONNECTs, two different tokens)")


def dictionary_mismatch(ctx: Context, v: Verdict) -> None:
    """§8/§7 step 1: a CONNECT with another hash is REJECTED DICTIONARY_MISMATCH, with the
    device's identity in the data."""
    other = _another_or_the_line(ctx, v)
    wrong = ctx.d.hash ^ 0xA5A5A5A5
    ex = other.connect(dictionary_hash=wrong, telemetry_port=0)
    v.note(f"sent CONNECT with dictionary_hash 0x{wrong:08X}")
    v.note(f"got {ctx.outcome(ex)}")
    if not v.expect(ctx.refused(ex, 2, "DICTIONARY_MISMATCH"), "REJECTED DICTIONARY_MISMATCH (6)"):
        return
    r = other.reply(ex, "CONNECT")
    v.expect(r["session_token"] == 0, f"data laid out as CONNECT's reply with session_token 0 "
             f"(got {r['session_token']})")
    v.expect(r["dictionary_hash"] == ctx.d.hash, f"data names the device's hash "
             f"0x{r['dictionary_hash']:08X}")
    info = other.exchange("GET_INFO", {}, token=0)
    if v.expect(ctx.is_ok(info), f"§7: GET_INFO needs no session: {ctx.outcome(info)}"):
        v.expect(other.reply(info, "GET_INFO")["dictionary_hash"] == ctx.d.hash,
                 "§8: GET_INFO reports the same dictionary hash")


def foreign_host_refused(ctx: Context, v: Verdict) -> None:
    """§7 step 2: another host's CONNECT without take_over is SESSION_BUSY; the owner keeps
    the session; a wrong token is NOT_SESSION_OWNER with the owner named."""
    other = ctx.other_host()
    ex = other.connect(telemetry_port=0)
    v.note(f"sent CONNECT take_over 0 from a second TCP connection while this run owns the "
           f"session; got {ctx.outcome(ex)}")
    v.expect(ctx.refused(ex, 2, "SESSION_BUSY"), "§7: REJECTED SESSION_BUSY (5)")
    mark = ctx.host.mark()
    hb = other.exchange("HEARTBEAT", {}, token=ctx.host.token ^ 0x5A5A5A5A)
    v.note(f"sent HEARTBEAT with a wrong token from the second connection; got {ctx.outcome(hb)}")
    if v.expect(ctx.refused(hb, 2, "NOT_SESSION_OWNER"), "§7: REJECTED NOT_SESSION_OWNER (4)"):
        text = hb.final.data.decode("utf-8", "replace")
        v.expect(text.startswith("owner ") and " since tick " in text,
                 f"§7: data names the owner: {text!r}")
    v.expect(ctx.wait_event(mark, "COMMAND_REJECTED") is not None,
             "§6.3: the owner receives EVENT COMMAND_REJECTED")
    mine = ctx.host.exchange("HEARTBEAT", {})
    v.expect(ctx.is_ok(mine), f"§7: the owner's token still works: HEARTBEAT {ctx.outcome(mine)}")


def take_over(ctx: Context, v: Verdict) -> None:
    """§7 step 3: take_over = 1 opens a new session, the old token dies, the device goes
    to the safe state and says SESSION_TAKEN_OVER to the new owner."""
    other = ctx.other_host()
    old = ctx.host.token
    ex = other.connect(take_over=True, telemetry_port=0)
    v.note(f"sent CONNECT take_over 1 from a second connection; got {ctx.outcome(ex)}")
    if not v.expect(ctx.is_ok(ex), "§7: ACCEPTED then COMPLETED"):
        return
    v.expect(other.token not in (0, old), "§7: a new, non-zero token")
    ev = other.wait_frame(lambda f: f.packet_id == ctx.ids["EVENT"]
                          and int.from_bytes(f.payload[1:3], "big")
                          == ctx.d.event_codes["SESSION_TAKEN_OVER"], 0, 2.0)
    v.expect(ev is not None, "§7: EVENT SESSION_TAKEN_OVER reaches the new owner")
    hb = ctx.host.exchange("HEARTBEAT", {}, token=old)
    v.note(f"old owner's HEARTBEAT with its old token: {ctx.outcome(hb)}")
    v.expect(ctx.refused(hb, 2, "NOT_SESSION_OWNER"), "§7: the old token is refused "
             "(NOT_SESSION_OWNER)")
    back = ctx.host.connect(take_over=True)
    v.expect(ctx.is_ok(back), f"taking the session back: CONNECT take_over 1 {ctx.outcome(back)}")


def abort_always(ctx: Context, v: Verdict) -> None:
    """§7/§9.2: ABORT is accepted from anyone, always, and does not end the session."""
    other = _another_or_the_line(ctx, v)
    for token in (0, 0xDEADBEEF):
        ex = other.exchange("ABORT", {}, token=token)
        v.note(f"sent ABORT with token 0x{token:08X} (not the session token); "
               f"got {ctx.outcome(ex)}")
        v.expect(ctx.is_ok(ex), "ACCEPTED then COMPLETED")
    mine = ctx.host.exchange("HEARTBEAT", {})
    v.expect(ctx.is_ok(mine), f"the session survives ABORT: owner's HEARTBEAT {ctx.outcome(mine)}")


def disconnect_ends_session(ctx: Context, v: Verdict) -> None:
    """§7 ending a session / §1.3: DISCONNECT completes, the token dies ('no session
    open'), and over Ethernet the telemetry stops."""
    h = ctx.host
    token = h.token
    ex = h.exchange("DISCONNECT", {})
    v.note(f"sent DISCONNECT: {ctx.outcome(ex)}")
    if not v.expect(ctx.is_ok(ex), "ACCEPTED then COMPLETED, on the command connection"):
        return
    h.token = 0                       # no heartbeats without a session
    h.session_changed()
    end = ex.final.tick
    hb = h.exchange("HEARTBEAT", {}, token=token)
    text = hb.final.data.decode("utf-8", "replace") if hb.final else ""
    v.expect(ctx.refused(hb, 2, "NOT_SESSION_OWNER") and text == "no session open",
             f"the old token afterwards: {ctx.outcome(hb)}, data {text!r} (expected "
             f"NOT_SESSION_OWNER, 'no session open')")
    if ctx.address.kind == "tcp":
        # frames produced after the session ended (a tick or two of slack for the period
        # in which DISCONNECT ran); waiting for an absence needs a deadline: half a second
        late = h.wait_frame(lambda f: f.packet_id in (ctx.ids["HIGH_RATE"], ctx.ids["HOUSEKEEPING"])
                            and 2 < ((f.tick - end) & 0xFFFFFFFF) < 0x80000000, h.mark(), 0.5)
        v.expect(late is None, "§1.3: no telemetry produced after the session ended"
                 + (f" (got packet 0x{late.packet_id:02X} of tick {late.tick}, DISCONNECT at "
                    f"{end})" if late else ""))
    back = h.connect()
    v.expect(ctx.is_ok(back), f"a new CONNECT opens a session again: {ctx.outcome(back)}")


def replay_only_on_its_connection(ctx: Context, v: Verdict) -> None:
    """§6.4: the retry history is kept per connection.  Another connection that sends the
    owner's CONNECT byte for byte is a new command - SESSION_BUSY - and must never get the
    owner's recorded reply, which carries the session token: with one history for all
    connections, any host on the network could read the token by guessing a sequence
    number and command the rig."""
    other = ctx.other_host()
    h = ctx.host
    built = h.build("CONNECT", {
        "protocol_major": ctx.d.version_major, "protocol_minor": ctx.d.version_minor,
        "dictionary_hash": ctx.d.hash, "telemetry_port": h.telemetry_port, "take_over": 0},
        token=0)
    mine = h.exchange("CONNECT", frame=built)
    v.note(f"the owner sent CONNECT seq {built[1]} on its own connection: {ctx.outcome(mine)}")
    if not v.expect(ctx.is_ok(mine), "§7: a CONNECT on the owner's own connection completes"):
        return
    token = h.reply(mine, "CONNECT")["session_token"]
    h.token = token
    h.session_changed()
    theirs = other.exchange("CONNECT", frame=built, resend=False)
    v.note(f"a second connection sent the identical frame: {ctx.outcome(theirs)}")
    v.expect(ctx.refused(theirs, 2, "SESSION_BUSY"),
             "§6.4/§7: a new command on that connection, REJECTED SESSION_BUSY (5) - not a "
             "replay of the owner's answer")
    leaked = [s for s in theirs.stages if token.to_bytes(4, "big") in s.data]
    v.expect(not leaked, "the owner's session token appears in no response to the other "
                         "connection")
    mine_still = h.exchange("HEARTBEAT", {})
    v.expect(ctx.is_ok(mine_still), f"the owner's session goes on: HEARTBEAT "
                                    f"{ctx.outcome(mine_still)}")


CHECKS = [
    Check("§7", "CONNECT reply and fresh session on the owner's connection", connect_reply),
    Check("§8", "dictionary hash mismatch refused at CONNECT", dictionary_mismatch),
    Check("§7", "foreign host refused, token and ownership", foreign_host_refused),
    Check("§6.4", "a replay is only for the connection that sent the command",
          replay_only_on_its_connection),
    Check("§7", "take-over", take_over),
    Check("§7", "ABORT always accepted", abort_always),
    Check("§7", "DISCONNECT ends the session and its telemetry", disconnect_ends_session),
]
