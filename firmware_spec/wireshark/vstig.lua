-- Wireshark dissector for vstig-hw virtual stigmergy messages on CAN (firmware_spec/SPEC.md 6.5), in XBee API
-- frames (6.9) and in MAVLink 2 TUNNEL messages (6.10), the last two at the end of this file.
--
--   wireshark -X lua_script:firmware_spec/wireshark/vstig.lua capture.pcap
--   tshark -X lua_script:firmware_spec/wireshark/vstig.lua -r candump.log -T fields -e vstig.key
--
-- 11-bit frames of the default base (IDs 0x600-0x7FF) are claimed through the "can.id"
-- table; 29-bit frames of the default base (0x18000000) through a CAN heuristic, since
-- 2^24 extended IDs are too many to register one by one. A classic frame carries one
-- 8-byte message; a CAN FD frame 1, 2, 3, 4, 6 or 8 of them, each shown as its own subtree.
--
-- Tagged units (SPEC.md 10.5) on every link here: a CAN FD frame of data length 20, XBee RF data 0xA1 || N
-- records, a TUNNEL of payload_type 46450 with N records. Each 20-byte record (message || epoch || tag, 10.3) is
-- a subtree with the message's fields (the same `vstig.key`... as untagged messages: a filter finds both) and
-- `vstig.epoch`, `vstig.tag`; the tag is shown, not checked (the key is not Wireshark's).

local vstig = Proto("vstig", "vstig-hw virtual stigmergy")

local ops = { [0] = "PUT", [1] = "GET" }

local f = vstig.fields
f.id_op = ProtoField.uint8("vstig.id_op", "ID op", base.DEC, ops, nil, "op from the arbitration ID")
f.sender = ProtoField.uint16("vstig.sender", "Sender", base.HEX, nil, nil, "node that sent the frame (from the ID)")
f.stigmergy = ProtoField.uint8("vstig.stigmergy", "Stigmergy", base.DEC, nil, nil, "stigmergy id (29-bit IDs)")
f.base = ProtoField.uint32("vstig.base", "ID base", base.HEX)
f.count = ProtoField.uint8("vstig.count", "Messages", base.DEC)
f.op = ProtoField.uint8("vstig.op", "Op", base.DEC, ops, nil, "message op bit")
f.key = ProtoField.uint16("vstig.key", "Key", base.DEC)
f.value = ProtoField.uint16("vstig.value", "Value", base.DEC)
f.timestamp = ProtoField.uint16("vstig.timestamp", "Timestamp", base.DEC, nil, nil, "Lamport timestamp (0: no entry)")
f.robot = ProtoField.uint16("vstig.robot", "Robot", base.DEC, nil, nil, "robot that wrote the value")
f.epoch = ProtoField.uint32("vstig.epoch", "Epoch", base.DEC, nil, nil, "the entry's epoch (SPEC.md 10.4)")
f.tag = ProtoField.bytes("vstig.tag", "Tag", base.NONE, "the writer's MAC over the entry (SPEC.md 10.2)")

local e_op = ProtoExpert.new("vstig.op_mismatch", "op bit differs from the ID's op (dropped by receivers)",
    expert.group.MALFORMED, expert.severity.WARN)
local e_len = ProtoExpert.new("vstig.bad_dlc",
    "length is neither 1, 2, 3, 4, 6 or 8 messages nor one 20-byte record (dropped)", expert.group.MALFORMED,
    expert.severity.WARN)
vstig.experts = { e_op, e_len }

local can_id_field = Field.new("can.id")
local can_xtd_field = Field.new("can.flags.xtd")

local BASE_11 = 0x600
local BASE_29 = 0x18000000
local MESSAGE, RECORD = 8, 20  -- bytes of a message (SPEC.md 2) and of a tagged record (10.3)
local VALID_LENGTHS = { [8] = true, [16] = true, [24] = true, [32] = true, [48] = true, [64] = true, [RECORD] = true }

-- The ID fields per SPEC.md: returns base, stigmergy, op, sender (or nil if not ours).
local function id_fields()
    local id_f, xtd_f = can_id_field(), can_xtd_field()
    if not id_f then return nil end
    local id = id_f.value
    if xtd_f and xtd_f.value then
        if bit.band(id, 0x1E000000) ~= BASE_29 then return nil end
        return BASE_29, bit.band(bit.rshift(id, 17), 0xFF), bit.band(bit.rshift(id, 16), 1), bit.band(id, 0xFFFF)
    end
    if bit.band(id, 0x600) ~= BASE_11 then return nil end
    return BASE_11, 0, bit.band(bit.rshift(id, 8), 1), bit.band(id, 0xFF)
end

-- One message (the 8 bytes of `m`) as a subtree of `root` over `span` (the message, or the record holding it):
-- its fields, the sender when `link` names one (XBee, MAVLink: on CAN it is the ID's), and an expert info when its
-- op differs from the CAN ID's `link.id_op`. Returns the subtree and a summary for the Info column.
local function add_message(root, span, m, link)
    local head = m(0, 2):uint()
    local op, key = bit.rshift(head, 15), bit.band(head, 0x7FFF)
    local value, ts, robot = m(2, 2):uint(), m(4, 2):uint(), m(6, 2):uint()
    local label = string.format("%s key=%d value=%d ts=%d robot=%d", ops[op], key, value, ts, robot)
    local sub = root:add(vstig, span, label)
    if link.sender then sub:add(link.sender_field, link.sender):set_generated() end
    sub:add(f.op, m(0, 1), op)
    sub:add(f.key, m(0, 2), key)
    sub:add(f.value, m(2, 2))
    sub:add(f.timestamp, m(4, 2))
    sub:add(f.robot, m(6, 2))
    if link.id_op and op ~= link.id_op then sub:add_proto_expert_info(e_op) end
    return sub, string.format("%s k=%d v=%d ts=%d r=%d", ops[op], key, value, ts, robot)
end

-- One record (20 bytes: message || epoch || tag): its message's subtree, with the epoch and the tag added.
local function add_record(root, r, link)
    local sub, info = add_message(root, r, r(0, MESSAGE), link)
    local epoch, tag = r(8, 4), r(12, 8)
    sub:add(f.epoch, epoch)
    sub:add(f.tag, tag):append_text(" (not checked: the key is not Wireshark's)")
    sub:append_text(string.format(" epoch=%d tag=%s", epoch:uint(), tag:bytes():tohex(true)))
    return info .. " e=" .. epoch:uint()
end

-- `count` messages (or records, when `tagged`) back to back from `offset` of `data`; a summary for the Info column.
local function add_units(root, data, offset, count, tagged, link)
    local info = {}
    for i = 0, count - 1 do
        if tagged then
            info[#info + 1] = add_record(root, data(offset + i * RECORD, RECORD), link)
        else
            local m = data(offset + i * MESSAGE, MESSAGE)
            local _, text = add_message(root, m, m, link)
            info[#info + 1] = text
        end
    end
    return table.concat(info, "; ")
end

local function dissect(tvb, pinfo, tree, base_, stigmergy, id_op, sender)
    local len = tvb:len()
    pinfo.cols.protocol = "VSTIG"
    local root = tree:add(vstig, tvb())
    root:add(f.base, base_):set_generated()
    root:add(f.stigmergy, stigmergy):set_generated()
    root:add(f.id_op, id_op):set_generated()
    root:add(f.sender, sender):set_generated()
    if not VALID_LENGTHS[len] then
        root:add_proto_expert_info(e_len)
        pinfo.cols.info = string.format("vstig %s from 0x%x: bad length %d", ops[id_op], sender, len)
        return len
    end
    local tagged = len == RECORD  -- one record (SPEC.md 10.5); 20 is no whole number of messages
    local n = tagged and 1 or len / MESSAGE
    root:add(f.count, n):set_generated()
    local info = add_units(root, tvb, 0, n, tagged, { id_op = id_op })
    pinfo.cols.info = string.format("vstig from 0x%x: %s", sender, info)
    return len
end

function vstig.dissector(tvb, pinfo, tree)
    local base_, stigmergy, id_op, sender = id_fields()
    if not base_ then return 0 end
    return dissect(tvb, pinfo, tree, base_, stigmergy, id_op, sender)
end

local function heuristic(tvb, pinfo, tree)
    local base_, stigmergy, id_op, sender = id_fields()
    if base_ ~= BASE_29 or not VALID_LENGTHS[tvb:len()] then return false end
    dissect(tvb, pinfo, tree, base_, stigmergy, id_op, sender)
    return true
end

local can_table = DissectorTable.get("can.id")
for id = BASE_11, BASE_11 + 0x1FF do
    can_table:add(id, vstig)
end
vstig:register_heuristic("can", heuristic)

-- XBee API frames (SPEC.md 6.9), one per packet: what `vstig record` writes per line for an XBee link, turned into
-- a pcap of link type USER0 (147), e.g. with text2pcap -l 147 (docs/how-to/xbee.md). API mode 2 frames are
-- unescaped first (a frame whose length does not match its size as it stands). Receive Packets (0x90) and
-- Transmit Requests (0x10) carry N messages each, or 0xA1 and N records (SPEC.md 10.5: never 8*N bytes); the 64-bit
-- source of a 0x90 is the sender (vstig.xbee_sender).

local xbee = Proto("vstig_xbee", "XBee API frame (vstig-hw)")

local frame_types = { [0x10] = "Transmit Request", [0x90] = "Receive Packet", [0x8B] = "Transmit Status",
    [0x8A] = "Modem Status", [0x08] = "AT Command", [0x09] = "AT Command (queued)", [0x88] = "AT Command Response" }

local xf = xbee.fields
xf.escaped = ProtoField.bool("vstig_xbee.escaped", "API mode 2 (escaped)")
xf.length = ProtoField.uint16("vstig_xbee.length", "Length", base.DEC)
xf.frame_type = ProtoField.uint8("vstig_xbee.frame_type", "Frame type", base.HEX, frame_types)
xf.frame_id = ProtoField.uint8("vstig_xbee.frame_id", "Frame id", base.DEC)
xf.dest = ProtoField.uint64("vstig_xbee.dest", "64-bit destination", base.HEX)
xf.source = ProtoField.uint64("vstig_xbee.source", "64-bit source", base.HEX)
xf.options = ProtoField.uint8("vstig_xbee.options", "Options", base.HEX)
xf.checksum = ProtoField.uint8("vstig_xbee.checksum", "Checksum", base.HEX)
xf.marker = ProtoField.uint8("vstig_xbee.tagged_marker", "Tagged batch marker", base.HEX)
f.xbee_sender = ProtoField.uint64("vstig.xbee_sender", "Sender (XBee 64-bit source)", base.HEX)

local e_sum = ProtoExpert.new("vstig_xbee.checksum_bad", "frame data and checksum do not sum to 0xFF (dropped)",
    expert.group.CHECKSUM, expert.severity.WARN)
local e_xlen = ProtoExpert.new("vstig_xbee.bad_length", "RF data is not a whole number of 8-byte messages (dropped)",
    expert.group.MALFORMED, expert.severity.WARN)
local e_xtag = ProtoExpert.new("vstig_xbee.bad_tagged_length",
    "RF data 0xA1 is not followed by whole 20-byte records (dropped)", expert.group.MALFORMED, expert.severity.WARN)
local e_frame = ProtoExpert.new("vstig_xbee.not_a_frame", "not one whole API frame (dropped)",
    expert.group.MALFORMED, expert.severity.WARN)
xbee.experts = { e_sum, e_xlen, e_xtag, e_frame }
local BATCH_MARKER = 0xA1

-- The frame with mode 2's escapes undone, as a new tvb; nil when it holds a bad escape.
local function unescaped(tvb)
    local bytes = ByteArray.new()
    bytes:append(tvb(0, 1):bytes())
    local i, n = 1, tvb:len()
    while i < n do
        local b = tvb(i, 1):uint()
        if b == 0x7D then
            if i + 1 >= n then return nil end
            bytes:append(ByteArray.new(string.format("%02x", bit.bxor(tvb(i + 1, 1):uint(), 0x20))))
            i = i + 2
        else
            bytes:append(tvb(i, 1):bytes())
            i = i + 1
        end
    end
    return bytes:tvb("Unescaped frame")
end

-- The messages, or the marker and records, in the RF data from `offset` of a frame's data; a summary for the Info
-- column.
local function rf_data(data, offset, root, sender)
    local size, link = data:len() - offset, { sender = sender, sender_field = f.xbee_sender }
    if size > 0 and size % MESSAGE == 0 then return add_units(root, data, offset, size / MESSAGE, false, link) end
    if size == 0 or data(offset, 1):uint() ~= BATCH_MARKER then
        root:add_proto_expert_info(e_xlen)
        return "bad length " .. size
    end
    root:add(xf.marker, data(offset, 1))
    if size == 1 or (size - 1) % RECORD ~= 0 then
        root:add_proto_expert_info(e_xtag)
        return "bad tagged length " .. size
    end
    return add_units(root, data, offset + 1, (size - 1) / RECORD, true, link)
end

function xbee.dissector(tvb, pinfo, tree)
    if tvb:len() < 5 or tvb(0, 1):uint() ~= 0x7E then return 0 end
    pinfo.cols.protocol = "VSTIG-XBEE"
    local root = tree:add(xbee, tvb())
    local frame, escaped = tvb, false
    if tvb(1, 2):uint() + 4 ~= tvb:len() then
        frame, escaped = unescaped(tvb), true
        if frame == nil or frame:len() < 5 or frame(1, 2):uint() + 4 ~= frame:len() then
            root:add_proto_expert_info(e_frame)
            return tvb:len()
        end
    end
    root:add(xf.escaped, escaped):set_generated()
    local length = frame(1, 2):uint()
    root:add(xf.length, frame(1, 2))
    local data = frame(3, length)
    local kind = data(0, 1):uint()
    root:add(xf.frame_type, data(0, 1))
    local sum = 0
    for i = 0, length do sum = sum + frame(3 + i, 1):uint() end
    root:add(xf.checksum, frame(3 + length, 1))
    if bit.band(sum, 0xFF) ~= 0xFF then
        root:add_proto_expert_info(e_sum)
        pinfo.cols.info = "XBee frame: bad checksum"
        return tvb:len()
    end
    if kind == 0x90 and length >= 12 then
        local source = data(1, 8):uint64()
        root:add(xf.source, data(1, 8))
        root:add(xf.options, data(11, 1))
        pinfo.cols.info = string.format("XBee from %s: %s", source:tohex(), rf_data(data, 12, root, source))
    elseif kind == 0x10 and length >= 14 then
        root:add(xf.frame_id, data(1, 1))
        root:add(xf.dest, data(2, 8))
        pinfo.cols.info = string.format("XBee to %s: %s", data(2, 8):uint64():tohex(), rf_data(data, 14, root, nil))
    else
        pinfo.cols.info = string.format("XBee %s", frame_types[kind] or string.format("frame type 0x%02X", kind))
    end
    return tvb:len()
end

DissectorTable.get("wtap_encap"):add(wtap.USER0, xbee)

-- MAVLink 2 TUNNEL messages carrying our messages (SPEC.md 6.10): one or more frames per packet, from a pcap of
-- link type USER1 (148) made of a mavlink link's capture (text2pcap -l 148, docs/how-to/mavlink.md), or any UDP
-- datagram that starts with one (a heuristic: 0xFD, msgid 385). Our TUNNELs (payload_type 46449; 46450: records)
-- show their messages, the sender as sysid << 8 | compid (vstig.mavlink_sender); crc (with TUNNEL's CRC_EXTRA 147)
-- checked; a signed frame's link id, timestamp (10 us units since 2015) and signature shown, the signature not
-- checked (the key is not Wireshark's).

local mav = Proto("vstig_mavlink", "MAVLink TUNNEL (vstig-hw)")
local PAYLOAD_TYPE, PAYLOAD_TYPE_TAGGED, TUNNEL = 46449, 46450, 385

local mf = mav.fields
mf.length = ProtoField.uint8("vstig_mavlink.length", "Payload length", base.DEC)
mf.signed = ProtoField.bool("vstig_mavlink.signed", "Signed")
mf.seq = ProtoField.uint8("vstig_mavlink.seq", "Sequence", base.DEC)
mf.sysid = ProtoField.uint8("vstig_mavlink.sysid", "System id", base.DEC)
mf.compid = ProtoField.uint8("vstig_mavlink.compid", "Component id", base.DEC)
mf.msgid = ProtoField.uint32("vstig_mavlink.msgid", "Message id", base.DEC)
mf.payload_type = ProtoField.uint16("vstig_mavlink.payload_type", "TUNNEL payload_type", base.DEC)
mf.target = ProtoField.uint8("vstig_mavlink.target_system", "Target system", base.DEC)
mf.crc = ProtoField.uint16("vstig_mavlink.crc", "crc", base.HEX)
mf.link_id = ProtoField.uint8("vstig_mavlink.link_id", "Signing link id", base.DEC)
mf.sign_time = ProtoField.uint64("vstig_mavlink.signing_timestamp", "Signing timestamp", base.DEC, nil, nil,
    "10 us units since 2015-01-01 UTC (SPEC.md 6.10.1)")
mf.signature = ProtoField.bytes("vstig_mavlink.signature", "Signature", base.NONE,
    "the first 6 bytes of SHA-256(key || frame || link_id || timestamp) (SPEC.md 6.10.1)")
f.mavlink_sender = ProtoField.uint16("vstig.mavlink_sender", "Sender (sysid << 8 | compid)", base.DEC)

local e_crc = ProtoExpert.new("vstig_mavlink.crc_bad", "crc does not match (dropped)", expert.group.CHECKSUM,
    expert.severity.WARN)
local e_mlen = ProtoExpert.new("vstig_mavlink.bad_length", "payload_length is not 1 to 16 whole messages (dropped)",
    expert.group.MALFORMED, expert.severity.WARN)
local e_cut = ProtoExpert.new("vstig_mavlink.truncated", "not a whole MAVLink 2 frame (dropped)",
    expert.group.MALFORMED, expert.severity.WARN)
local e_mtag = ProtoExpert.new("vstig_mavlink.bad_tagged_length",
    "payload_length is not 1 to 6 whole 20-byte records (dropped)", expert.group.MALFORMED, expert.severity.WARN)
mav.experts = { e_crc, e_mlen, e_mtag, e_cut }

-- CRC-16/MCRF4XX (MAVLink's X.25) of tvb bytes [from, from + n), then the CRC_EXTRA byte.
local function x25(tvb, from, n, extra)
    local crc = 0xFFFF
    local function add(b)
        local t = bit.band(bit.bxor(b, crc), 0xFF)
        t = bit.band(bit.bxor(t, bit.lshift(t, 4)), 0xFF)
        crc = bit.band(bit.bxor(bit.rshift(crc, 8), bit.lshift(t, 8), bit.lshift(t, 3), bit.rshift(t, 4)), 0xFFFF)
    end
    for i = from, from + n - 1 do add(tvb(i, 1):uint()) end
    add(extra)
    return crc
end

-- One frame at `at`; the bytes it takes (0: no MAVLink 2 frame starts there) and a summary for the Info column.
local function mavlink_frame(tvb, at, tree)
    local left = tvb:len() - at
    if left < 12 or tvb(at, 1):uint() ~= 0xFD then return 0 end
    local len, flags = tvb(at + 1, 1):uint(), tvb(at + 2, 1):uint()
    local size = 12 + len + (bit.band(flags, 1) == 1 and 13 or 0)
    local root = tree:add(mav, tvb(at, math.min(size, left)))
    if size > left then
        root:add_proto_expert_info(e_cut)
        return left, "MAVLink: cut short"
    end
    local msgid = tvb(at + 7, 3):le_uint()
    local sysid, compid = tvb(at + 5, 1):uint(), tvb(at + 6, 1):uint()
    root:add(mf.length, tvb(at + 1, 1))
    root:add(mf.signed, bit.band(flags, 1) == 1):set_generated()
    root:add(mf.seq, tvb(at + 4, 1))
    root:add(mf.sysid, tvb(at + 5, 1))
    root:add(mf.compid, tvb(at + 6, 1))
    root:add_le(mf.msgid, tvb(at + 7, 3))
    root:add_le(mf.crc, tvb(at + 10 + len, 2))
    if bit.band(flags, 1) == 1 then
        root:add(mf.link_id, tvb(at + 12 + len, 1))
        root:add_le(mf.sign_time, tvb(at + 13 + len, 6))
        root:add(mf.signature, tvb(at + 19 + len, 6)):append_text(" (not checked: the key is not Wireshark's)")
    end
    if msgid ~= TUNNEL then return size, string.format("MAVLink %d/%d message %d", sysid, compid, msgid) end
    if x25(tvb, at + 1, 9 + len, 147) ~= tvb(at + 10 + len, 2):le_uint() then
        root:add_proto_expert_info(e_crc)
        return size, "MAVLink TUNNEL: bad crc"
    end
    local payload = ByteArray.new()  -- the payload with its cut trailing zeros put back
    if len > 0 then payload:append(tvb(at + 10, len):bytes()) end
    if payload:len() < 133 then payload:append(ByteArray.new(string.rep("00", 133 - payload:len()))) end
    local p = payload:tvb("TUNNEL payload")
    local ptype, carried = p(0, 2):le_uint(), p(4, 1):uint()
    root:add_le(mf.payload_type, p(0, 2))
    root:add(mf.target, p(2, 1))
    local tagged = ptype == PAYLOAD_TYPE_TAGGED
    if ptype ~= PAYLOAD_TYPE and not tagged then return size, string.format("MAVLink TUNNEL payload_type %d", ptype) end
    local unit, most = MESSAGE, 16
    if tagged then unit, most = RECORD, 6 end
    if carried == 0 or carried > unit * most or carried % unit ~= 0 then
        root:add_proto_expert_info(tagged and e_mtag or e_mlen)
        return size, "MAVLink TUNNEL: bad length " .. carried
    end
    local link = { sender = sysid * 256 + compid, sender_field = f.mavlink_sender }
    local info = add_units(root, p, 5, carried / unit, tagged, link)
    return size, string.format("MAVLink from %d/%d: %s", sysid, compid, info)
end

function mav.dissector(tvb, pinfo, tree)
    local at, info = 0, {}
    while at < tvb:len() do
        local took, text = mavlink_frame(tvb, at, tree)
        if took == 0 then break end
        info[#info + 1] = text
        at = at + took
    end
    if at == 0 then return 0 end
    pinfo.cols.protocol = "VSTIG-MAVLINK"
    pinfo.cols.info = table.concat(info, " | ")
    return at
end

local function mavlink_heuristic(tvb, pinfo, tree)
    if tvb:len() < 12 or tvb(0, 1):uint() ~= 0xFD or tvb(7, 3):le_uint() ~= TUNNEL then return false end
    return mav.dissector(tvb, pinfo, tree) > 0
end

DissectorTable.get("wtap_encap"):add(wtap.USER1, mav)
mav:register_heuristic("udp", mavlink_heuristic)
