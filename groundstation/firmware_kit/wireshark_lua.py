"""The fixed part of the exported Wireshark dissector, in Lua: CRC-32, the walk over
the frames of a UDP datagram or a TCP stream, and the generic item reader that the
generated layout tables drive (wireshark_export.py writes those tables).

Written against Wireshark's Lua API as documented (Proto, ProtoField.new, Pref,
DissectorTable, TreeItem, TvbRange, desegmentation); it runs on Lua 5.2 (Wireshark
3.x/4.0, which has bit32) and on later Lua versions through the native operators.
"""

from __future__ import annotations

READERS = r"""
-- ---------------------------------------------------------------- bit operations
local band, bxor, rshift
if bit32 then
  band, bxor, rshift = bit32.band, bit32.bxor, bit32.rshift
elseif bit then
  band, bxor, rshift = bit.band, bit.bxor, bit.rshift
else
  band = load("return function(a, b) return a & b end")()
  bxor = load("return function(a, b) return a ~ b end")()
  rshift = load("return function(a, n) return (a & 0xFFFFFFFF) >> n end")()
end
local TWO32 = 4294967296
local function u32(x) return x % TWO32 end

-- ---------------------------------------------------------------- CRC-32/ISO-HDLC
local CRC_TABLE = {}
for n = 0, 255 do
  local c = n
  for _ = 1, 8 do
    if band(c, 1) ~= 0 then c = bxor(0xEDB88320, rshift(c, 1)) else c = rshift(c, 1) end
  end
  CRC_TABLE[n] = u32(c)
end

local function crc32(tvb, offset, length)
  local bytes = tvb(offset, length):bytes()
  local c = 0xFFFFFFFF
  for i = 0, length - 1 do
    c = bxor(CRC_TABLE[band(bxor(c, bytes:get_index(i)), 0xFF)], rshift(c, 8))
  end
  return u32(bxor(c, 0xFFFFFFFF))
end

-- ---------------------------------------------------------------- item reader
local function engineering(it, raw)
  if it.poly then                       -- Horner, as numpy's polyval
    local v = 0.0
    for k = #it.poly, 1, -1 do v = v * raw + it.poly[k] end
    return v
  end
  local v = raw * it.scale
  if it.add ~= 0 then v = v + it.add end
  return v
end

local function read_raw(it, range)
  if it.type == "u64" then return range:uint64():tonumber() end
  if it.type == "i64" then return range:int64():tonumber() end
  if it.type:sub(1, 1) == "u" then return range:uint() end
  return range:int()
end

-- add the items of `layout` found in tvb[start, start + length) to `tree`
local function add_items(tvb, start, length, tree, layout)
  if length < layout.fixed then
    tree:add_proto_expert_info(E_LENGTH, "only " .. length .. " bytes, the layout needs " .. layout.fixed)
    return
  end
  for _, it in ipairs(layout.items) do
    local pos = start + it.off
    if it.rest then
      local n = length - it.off
      if n == 0 then
        tree:add(tvb(pos, 0), it.label .. ": (empty)")
      elseif it.type == "str" then
        local r = tvb(pos, n)
        tree:add(it.field, r, r:string(ENC_UTF_8))
      else
        tree:add(it.field, tvb(pos, n))
      end
    else
      local r = tvb(pos, it.size)
      if it.raw then
        tree:add(it.field, r, engineering(it, read_raw(it, r)))
        tree:add(it.raw, r)
      else
        local item = tree:add(it.field, r)
        if it.check_hash and r:uint() ~= DICTIONARY_HASH then
          item:add_proto_expert_info(E_HASH, string.format(
            "dictionary hash 0x%08X, this dissector was exported from 0x%08X", r:uint(), DICTIONARY_HASH))
        end
        if it.flags then
          for _, flag in ipairs(it.flags) do item:add(flag, r) end
        end
      end
    end
  end
end

"""

WALK = r"""
-- ---------------------------------------------------------------- one frame
-- total length of the frame at `pos` if its header is good and it is all in the
-- first `n` bytes, else nil and why
local function check_frame(tvb, pos, n)
  if n - pos < HEADER_SIZE then return nil, "fewer than " .. HEADER_SIZE .. " bytes" end
  if tvb(pos, 1):uint() ~= 0xEB or tvb(pos + 1, 1):uint() ~= 0x90 then return nil, "no sync word" end
  local version = tvb(pos + 2, 1):uint()
  if version ~= PROTOCOL_MAJOR then return nil, "protocol version " .. version end
  local pid = tvb(pos + 3, 1):uint()
  local lim = LIMITS[pid]
  if not lim then return nil, string.format("unknown packet id 0x%02X", pid) end
  local length = tvb(pos + 4, 2):uint()
  if length < lim[1] or length > lim[2] then return nil, "length " .. length .. " does not fit" end
  return length + HEADER_SIZE + CRC_SIZE, nil
end

local function dissect_frame(tvb, pos, total, pinfo, tree, info)
  local pid = tvb(pos + 3, 1):uint()
  local length = total - HEADER_SIZE - CRC_SIZE
  local name = PACKET_NAMES[pid]
  local sequence = tvb(pos + 6, 4):uint()
  local sub = tree:add(hfb, tvb(pos, total), string.format("%s, sequence %d, tick %d", name, sequence,
                                                            tvb(pos + 10, 4):uint()))
  sub:add(F.sync, tvb(pos, 2))
  sub:add(F.version, tvb(pos + 2, 1))
  sub:add(F.packet_id, tvb(pos + 3, 1))
  sub:add(F.length, tvb(pos + 4, 2))
  sub:add(F.sequence, tvb(pos + 6, 4))
  sub:add(F.tick, tvb(pos + 10, 4))
  local start = pos + HEADER_SIZE
  local text = name .. " #" .. sequence
  add_items(tvb, start, length, sub, LAYOUTS["pkt:" .. name])
  local extra = EXTRA[name]
  if extra then
    local more = extra(tvb, start, length, sub)
    if more then text = text .. " " .. more end
  end
  local crc_range = tvb(start + length, CRC_SIZE)
  local crc_item = sub:add_le(F.crc, crc_range)
  local good = crc32(tvb, pos, HEADER_SIZE + length) == crc_range:le_uint()
  sub:add(F.crc_good, crc_range, good)
  if not good then
    crc_item:add_proto_expert_info(E_CRC)
    text = text .. " [bad CRC]"
  end
  info[#info + 1] = text
end

local function next_sync(tvb, pos, n)
  while pos + 1 < n do
    if tvb(pos, 1):uint() == 0xEB and tvb(pos + 1, 1):uint() == 0x90 then return pos end
    pos = pos + 1
  end
  return n
end

local function add_junk(tvb, pos, stop, tree, why)
  local item = tree:add(F.junk, tvb(pos, stop - pos))
  item:add_proto_expert_info(E_JUNK, (stop - pos) .. " bytes outside any frame (" .. why .. ")")
end

local function show_info(pinfo, info)
  local text = table.concat(info, ", ")
  if #info > 4 then text = table.concat(info, ", ", 1, 3) .. ", ... (" .. #info .. " frames)" end
  if tostring(pinfo.cols.protocol) == "HFB" then
    -- called again for the same packet (TCP: a reassembled frame, then the rest)
    if text ~= "" then pinfo.cols.info:append(", " .. text) end
  else
    pinfo.cols.protocol = "HFB"
    pinfo.cols.info = text
  end
end

-- ---------------------------------------------------------------- UDP: whole frames
local function dissect_datagram(tvb, pinfo, tree)
  local n = tvb:len()
  local root = tree:add(hfb, tvb(), "HFB telemetry datagram")
  local info, pos = {}, 0
  while pos < n do
    local total, why = check_frame(tvb, pos, n)
    if total and pos + total <= n then
      dissect_frame(tvb, pos, total, pinfo, root, info)
      pos = pos + total
    else
      -- a frame never spans two datagrams (SPEC.md 4.2): the rest up to the next
      -- sync word is junk
      local stop = next_sync(tvb, pos + 1, n)
      add_junk(tvb, pos, stop, root, why or "frame runs past the end of the datagram")
      pos = stop
    end
  end
  show_info(pinfo, info)
  return n
end

-- ---------------------------------------------------------------- TCP: a byte stream
local function dissect_stream(tvb, pinfo, tree)
  local n = tvb:len()
  local info, pos, root = {}, 0, nil
  -- the tree item only once there is a frame or junk to show: a segment that only
  -- waits for more bytes shows nothing
  local function here()
    root = root or tree:add(hfb, tvb(), "HFB command channel")
    return root
  end
  while pos < n do
    local at_sync = n - pos >= 2 and tvb(pos, 1):uint() == 0xEB and tvb(pos + 1, 1):uint() == 0x90
    if (n - pos == 1 and tvb(pos, 1):uint() == 0xEB) or (at_sync and n - pos < HEADER_SIZE) then
      pinfo.desegment_offset = pos                 -- half a sync word or header: wait
      pinfo.desegment_len = DESEGMENT_ONE_MORE_SEGMENT
      break
    end
    local total, why = nil, "no sync word"
    if at_sync then total, why = check_frame(tvb, pos, n) end
    if total and pos + total > n then
      pinfo.desegment_offset = pos                 -- the rest of this frame is to come
      pinfo.desegment_len = pos + total - n
      break
    elseif total then
      dissect_frame(tvb, pos, total, pinfo, here(), info)
      pos = pos + total
    else
      local stop = next_sync(tvb, pos + 1, n)
      if stop == n and n - 1 > pos and tvb(n - 1, 1):uint() == 0xEB then
        stop = n - 1                               -- keep a last 0xEB: half a sync word
      end
      add_junk(tvb, pos, stop, here(), why)
      pos = stop
    end
  end
  if root then show_info(pinfo, info) end
  return n
end

-- ---------------------------------------------------------------- registration
-- two small protocols carry the two transports' walks; every field belongs to hfb
local UDP_PROTO = Proto("hfb_udp", "HFB telemetry (UDP datagrams of whole frames)")
local TCP_PROTO = Proto("hfb_tcp", "HFB command channel (TCP byte stream)")
local registered = {}
local function register()
  local udp, tcp = DissectorTable.get("udp.port"), DissectorTable.get("tcp.port")
  if registered.udp then udp:remove(registered.udp, UDP_PROTO) end
  if registered.tcp then tcp:remove(registered.tcp, TCP_PROTO) end
  registered.udp, registered.tcp = hfb.prefs.udp_port, hfb.prefs.tcp_port
  udp:add(registered.udp, UDP_PROTO)
  tcp:add(registered.tcp, TCP_PROTO)
end

UDP_PROTO.dissector = dissect_datagram
TCP_PROTO.dissector = dissect_stream
hfb.prefs_changed = register
register()

-- ---------------------------------------------------------------- any other port
-- a device on another port is found by its first whole frame: sync word, version,
-- known packet id, a length its packet allows, and a good CRC (a false match of all of
-- them in other traffic is below one in 2^50).  The frame's conversation (both
-- addresses and ports) is then claimed, so that the rest of it - a damaged frame, a
-- frame split over TCP segments - is decoded as on the preference's port.
local function first_frame_good(tvb)
  local n = tvb:len()
  local total = check_frame(tvb, 0, n)
  if not total or total > n then return false end
  return crc32(tvb, 0, total - CRC_SIZE) == tvb(total - CRC_SIZE, CRC_SIZE):le_uint()
end

local function heuristic(proto, walk)
  return function(tvb, pinfo, tree)
    if not hfb.prefs.heuristics or not first_frame_good(tvb) then return false end
    pinfo.conversation = proto
    walk(tvb, pinfo, tree)
    return true
  end
end

UDP_PROTO:register_heuristic("udp", heuristic(UDP_PROTO, dissect_datagram))
TCP_PROTO:register_heuristic("tcp", heuristic(TCP_PROTO, dissect_stream))
"""
