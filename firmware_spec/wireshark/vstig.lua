-- Wireshark dissector for vstig-hw virtual stigmergy messages on CAN (firmware_spec/SPEC.md 6.5).
--
--   wireshark -X lua_script:firmware_spec/wireshark/vstig.lua capture.pcap
--   tshark -X lua_script:firmware_spec/wireshark/vstig.lua -r candump.log -T fields -e vstig.key
--
-- 11-bit frames of the default base (IDs 0x600-0x7FF) are claimed through the "can.id"
-- table; 29-bit frames of the default base (0x18000000) through a CAN heuristic, since
-- 2^24 extended IDs are too many to register one by one. A classic frame carries one
-- 8-byte message; a CAN FD frame 1, 2, 3, 4, 6 or 8 of them, each shown as its own subtree.

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

local e_op = ProtoExpert.new("vstig.op_mismatch", "op bit differs from the ID's op (dropped by receivers)",
    expert.group.MALFORMED, expert.severity.WARN)
local e_len = ProtoExpert.new("vstig.bad_dlc", "length is not a whole number of 8-byte messages (dropped)",
    expert.group.MALFORMED, expert.severity.WARN)
vstig.experts = { e_op, e_len }

local can_id_field = Field.new("can.id")
local can_xtd_field = Field.new("can.flags.xtd")

local BASE_11 = 0x600
local BASE_29 = 0x18000000
local VALID_LENGTHS = { [8] = true, [16] = true, [24] = true, [32] = true, [48] = true, [64] = true }

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
    local n = len / 8
    root:add(f.count, n):set_generated()
    local info = {}
    for i = 0, n - 1 do
        local m = tvb(i * 8, 8)
        local head = m(0, 2):uint()
        local op = bit.rshift(head, 15)
        local key = bit.band(head, 0x7FFF)
        local value, ts, robot = m(2, 2):uint(), m(4, 2):uint(), m(6, 2):uint()
        local sub = root:add(vstig, m, string.format("%s key=%d value=%d ts=%d robot=%d", ops[op], key, value, ts, robot))
        sub:add(f.op, m(0, 1), op)
        sub:add(f.key, m(0, 2), key)
        sub:add(f.value, m(2, 2))
        sub:add(f.timestamp, m(4, 2))
        sub:add(f.robot, m(6, 2))
        if op ~= id_op then sub:add_proto_expert_info(e_op) end
        info[#info + 1] = string.format("%s k=%d v=%d ts=%d r=%d", ops[op], key, value, ts, robot)
    end
    pinfo.cols.info = string.format("vstig from 0x%x: %s", sender, table.concat(info, "; "))
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
