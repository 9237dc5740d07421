--[[
Wireshark dissector for the captures of sj300_async (docs/CAPTURE.md).

Two protocols, one file:

  sj300   Hitachi SJ300 ASCII protocol        pcapng link type 147 (LINKTYPE_USER0)
  fr700   Mitsubishi FR-700 computer link     pcapng link type 148 (LINKTYPE_USER1)

Install: copy this file into ~/.local/lib/wireshark/plugins/ (Wireshark's
personal Lua plugins folder; "Help > About > Folders" shows yours), or load it
for one run: `tshark -X lua_script:contrib/wireshark/sj300_async.lua -r x.pcapng`.
Do not do both at once: a protocol cannot be registered twice.

What a packet is: one frame as it crossed the line (start code through the
check code and CR / CR LF), or a run of noise. The capture's packet flags
tell the direction (bits 0-1: inbound reached the host, outbound the host
wrote it); Wireshark turns them into pinfo.p2p_dir. When the direction is
unknown (a tap) the content decides. Packets flagged as symbol errors
(bit 31), and bytes that are no frame, are shown as noise. Packet comments
are Wireshark's own business (frame.comment).

Request/reply pairing is computed on the first pass, packet by packet, into
a table keyed by frame number; it shows on every later dissection (tshark
-2, or clicking a packet in Wireshark). The pairing key is the protocol and
the node (station): a reply answers the latest unanswered request to the
node it names. The interface is not part of the key (Wireshark does not give
it to a dissector on the first pass), so in a capture of several lines of
one protocol (the gateway's) two lines talking to the same node number at
the same moment can be mixed up.

Preferences: each protocol's link type (147..162, 0 for none) under
Protocols > SJ300 / FR700. Sites whose USER0 / USER1 already carry other
traffic set it to 0 and pick "sj300" / "fr700" in the DLT_USER table instead.
]]

----------------------------------------------------------------------------
-- shared helpers
----------------------------------------------------------------------------

local P2P_SENT, P2P_RECV = 0, 1 -- pinfo.p2p_dir: outbound, inbound (-1 unknown)

local STX, ETX, ENQ, ACK, CR, NAK = 0x02, 0x03, 0x05, 0x06, 0x0D, 0x15

local f_packet_flags = Field.new("frame.packet_flags")

-- XOR of two bytes, in arithmetic (Lua 5.2 has bit32, 5.4 has operators: neither is portable).
local function xor8(a, b)
    local r, bit = 0, 1
    for _ = 1, 8 do
        local x, y = a % 2, b % 2
        if x ~= y then r = r + bit end
        a, b, bit = (a - x) / 2, (b - y) / 2, bit * 2
    end
    return r
end

-- The packet's epb_flags word, when Wireshark has put it in the tree (it does
-- not on tshark's first pass, which has no tree): used only for the noise bit.
local function packet_flags()
    local ok, fi = pcall(f_packet_flags)
    if ok and fi ~= nil then return fi.value end
    return nil
end

local function noise_flag()
    local flags = packet_flags()
    return flags ~= nil and math.floor(flags / 2^31) % 2 == 1
end

local function is_hex(s) return s ~= "" and s:match("^[0-9A-Fa-f]+$") ~= nil end
local function is_dec(s) return s ~= "" and s:match("^[0-9]+$") ~= nil end

-- A time difference in seconds (doubles of epoch seconds), as an NSTime
-- rounded to the microsecond (the resolution of our captures).
local function delta_nstime(later, earlier)
    local us = math.floor((later - earlier) * 1e6 + 0.5)
    local secs = math.floor(us / 1e6)
    return NSTime.new(secs, (us - secs * 1e6) * 1000)
end

local function printable(s)
    return (s:gsub("[^\32-\126]", function(c) return string.format("<%02X>", c:byte()) end))
end

-- Registers a protocol on the wtap_encap table of a user link type (147..162),
-- and moves it when the preference changes.
local function register_linktype(proto, default)
    proto.prefs.linktype = Pref.uint("Link type",
        default, "pcapng link type of its captures: 147..162 (LINKTYPE_USER0..15), 0 for none")
    local encaps = DissectorTable.get("wtap_encap")
    local current, replaced = nil, nil -- our encapsulation, and who had it before (DLT_USER)
    local function apply()
        local lt = proto.prefs.linktype
        local encap = nil
        if lt >= 147 and lt <= 162 then encap = wtap["USER" .. (lt - 147)] end
        if encap == current then return end
        if current ~= nil then
            encaps:remove(current, proto)
            if replaced ~= nil then encaps:add(current, replaced) end
        end
        if encap ~= nil then
            replaced = encaps:get_dissector(encap)
            encaps:add(encap, proto)
        end
        current = encap
    end
    proto.prefs_changed = apply
    apply()
end

----------------------------------------------------------------------------
-- SJ300
----------------------------------------------------------------------------

local sj = Proto("sj300", "Hitachi SJ300 ASCII protocol")

local SJ_BROADCAST = 0xFF

local sj_commands = {
    [0x00] = "run", [0x01] = "set frequency", [0x02] = "set terminals",
    [0x03] = "read monitor", [0x04] = "read status", [0x05] = "read trip history",
    [0x06] = "read parameter", [0x07] = "write parameter", [0x08] = "initialize",
    [0x09] = "can store", [0x0A] = "store", [0x0B] = "recalculate",
}
-- Request data length per command (characters between command and BCC).
local sj_request_data = {
    [0x00] = 1, [0x01] = 6, [0x02] = 16, [0x03] = 0, [0x04] = 0, [0x05] = 0,
    [0x06] = 4, [0x07] = 12, [0x08] = 0, [0x09] = 0, [0x0A] = 0, [0x0B] = 0,
}
-- Data replies (no ACK): their data length.
local sj_data_reply = { [0x03] = 104, [0x04] = 8, [0x05] = 440 }
-- ACK + data replies: their data length.
local sj_ack_data_reply = { [0x06] = 8, [0x09] = 2 }

local sj_nak_codes = {
    [1] = "parity error", [2] = "check sum (BCC) error", [3] = "framing error",
    [4] = "overrun error", [5] = "protocol error", [6] = "ASCII code error",
    [7] = "receive buffer overrun", [8] = "receive time-out",
    [11] = "abnormal command code", [13] = "execution disabled",
    [16] = "abnormal parameter code or value",
}
local sj_run_modes = { [0] = "stop", [1] = "forward", [2] = "reverse" }
local sj_status_a = {
    [0] = "initial status", [2] = "on stopping", [3] = "on running", [4] = "on free-run stop",
    [5] = "on jog", [6] = "on dynamic braking", [7] = "on retry", [8] = "on trip",
    [9] = "on under-voltage",
}
local sj_status_b = { [0] = "on stopping", [1] = "on running", [2] = "on tripping" }
local sj_status_c = {
    [1] = "stop", [2] = "decelerating", [3] = "constant speed", [4] = "accelerating",
    [5] = "forward", [6] = "reverse", [7] = "reverse from forward",
    [8] = "forward from reverse", [9] = "forward start", [10] = "reverse start",
}

local sjf = {
    type = ProtoField.string("sj300.type", "Type",
        "request, reply, echo (the host's request handed back by the adapter) or noise"),
    node = ProtoField.uint8("sj300.node", "Node", base.DEC, nil, nil, "01..32, FF (255) broadcast"),
    broadcast = ProtoField.bool("sj300.broadcast", "Broadcast"),
    command = ProtoField.uint8("sj300.command", "Command", base.HEX, sj_commands),
    command_name = ProtoField.string("sj300.command_name", "Command name"),
    data = ProtoField.string("sj300.data", "Data"),
    kind = ProtoField.string("sj300.kind", "Reply kind", "ACK, ACK+data, data or NAK"),
    nak_code = ProtoField.uint8("sj300.nak_code", "NAK code", base.DEC, sj_nak_codes),
    nak_meaning = ProtoField.string("sj300.nak_meaning", "NAK meaning"),
    bcc = ProtoField.string("sj300.bcc", "BCC"),
    bcc_ok = ProtoField.bool("sj300.bcc_ok", "BCC valid"),
    bcc_expected = ProtoField.string("sj300.bcc_expected", "BCC expected"),
    run = ProtoField.uint8("sj300.run", "Run", base.DEC, sj_run_modes),
    frequency = ProtoField.double("sj300.frequency", "Frequency (Hz)"),
    terminals = ProtoField.string("sj300.terminals", "Intelligent input terminals (hex)"),
    param = ProtoField.string("sj300.param", "Parameter"),
    value = ProtoField.uint32("sj300.value", "Value", base.DEC),
    status_a = ProtoField.uint8("sj300.status_a", "Status A", base.DEC, sj_status_a),
    status_b = ProtoField.uint8("sj300.status_b", "Status B", base.DEC, sj_status_b),
    status_c = ProtoField.uint8("sj300.status_c", "Status C", base.DEC, sj_status_c),
    can_store = ProtoField.bool("sj300.can_store", "EEPROM store allowed"),
    request_in = ProtoField.framenum("sj300.request_in", "Request in", base.NONE, frametype.REQUEST),
    response_in = ProtoField.framenum("sj300.response_in", "Response in", base.NONE,
        frametype.RESPONSE),
    response_time = ProtoField.relative_time("sj300.response_time", "Response time",
        "from the host's write of the request to the arrival of the whole reply"),
    noise = ProtoField.bytes("sj300.noise", "Noise"),
}
sj.fields = {
    sjf.type, sjf.node, sjf.broadcast, sjf.command, sjf.command_name, sjf.data, sjf.kind,
    sjf.nak_code, sjf.nak_meaning, sjf.bcc, sjf.bcc_ok, sjf.bcc_expected, sjf.run,
    sjf.frequency, sjf.terminals, sjf.param, sjf.value, sjf.status_a, sjf.status_b,
    sjf.status_c, sjf.can_store, sjf.request_in, sjf.response_in, sjf.response_time, sjf.noise,
}

local sje = {
    bad_bcc = ProtoExpert.new("sj300.bcc_bad", "Wrong BCC", expert.group.CHECKSUM,
        expert.severity.ERROR),
    nak = ProtoExpert.new("sj300.nak", "Negative reply (NAK)", expert.group.RESPONSE_CODE,
        expert.severity.WARN),
    noise = ProtoExpert.new("sj300.noise.expert", "Noise: bytes outside any frame",
        expert.group.MALFORMED, expert.severity.WARN),
    malformed = ProtoExpert.new("sj300.malformed", "Malformed frame", expert.group.MALFORMED,
        expert.severity.ERROR),
    no_reply = ProtoExpert.new("sj300.no_reply", "No reply in the capture",
        expert.group.SEQUENCE, expert.severity.NOTE),
    unsolicited = ProtoExpert.new("sj300.unsolicited", "Reply to no request in the capture",
        expert.group.SEQUENCE, expert.severity.NOTE),
}
sj.experts = { sje.bad_bcc, sje.nak, sje.noise, sje.malformed, sje.no_reply, sje.unsolicited }

-- First-pass state (reset by sj.init): what each frame is and its pairing.
local sj_frames = {} -- frame number -> { type, node, command, request, responses, time }
local sj_pending = {} -- node -> frame number of its latest unanswered request
local sj_last_tx = nil -- bytes of the host's latest request (to recognize local echo)

function sj.init()
    sj_frames, sj_pending, sj_last_tx = {}, {}, nil
end

local function sj_node(chars)
    if chars == "FF" or chars == "ff" then return SJ_BROADCAST end
    if chars:match("^[0-9][0-9]$") then return tonumber(chars) end
    return nil
end

-- The BCC of a frame body (node .. last byte before the BCC).
local function sj_bcc(chars)
    local x = 0
    for i = 1, #chars do x = xor8(x, chars:byte(i)) end
    return string.format("%02X", x)
end

-- Decide request or reply (the body is between STX and CR).
local function sj_classify(body, dir)
    if dir == P2P_SENT then return "request" end
    local third = body:byte(3)
    if third == ACK or third == NAK then return "reply" end
    if dir == P2P_RECV then
        if sj_last_tx ~= nil and body == sj_last_tx then return "echo" end
        return "reply"
    end
    -- Unknown direction: a data reply (no ACK) is expected when the node's pending
    -- request reads the monitor, the status or the trip history, and has its length.
    local node = sj_node(body:sub(1, 2))
    local pending = node ~= nil and sj_pending[node] or nil
    if pending ~= nil then
        local want = sj_data_reply[sj_frames[pending].command]
        if want ~= nil and #body == 4 + want then return "reply" end
    end
    local command = tonumber(body:sub(3, 4), 16)
    local want = command ~= nil and is_hex(body:sub(3, 4)) and sj_request_data[command] or nil
    if want ~= nil and #body == 6 + want then return "request" end
    if #body == 108 or #body == 444 or #body == 12 then return "reply" end
    return "request"
end

local function sj_dissect_noise(tvb, pinfo, tree)
    pinfo.cols.info = string.format("Noise (%d bytes)", tvb:len())
    local t = tree:add(sj, tvb(), "SJ300 noise")
    t:add(sjf.type, "noise"):set_generated()
    t:add(sjf.noise, tvb())
    t:add_proto_expert_info(sje.noise)
    return tvb:len()
end

-- First pass: record the frame and pair it.
local function sj_first_pass(number, kind, node, command, time, body)
    local rec = { type = kind, node = node, command = command, time = time, responses = {} }
    sj_frames[number] = rec
    if kind == "request" then
        sj_last_tx = body
        if node ~= nil and node ~= SJ_BROADCAST then
            sj_pending[node] = number -- even an unknown command: it gets NAK 11
        end
    elseif kind == "reply" and node ~= nil then
        local request = sj_pending[node]
        if request ~= nil then
            rec.request = request
            rec.command = sj_frames[request].command
            table.insert(sj_frames[request].responses, number)
            sj_pending[node] = nil
        end
    end
    return rec
end

local function sj_add_value(t, tvb, off, chars, field)
    if is_dec(chars) then t:add(field, tvb(off, #chars), tonumber(chars)) end
end

local function sj_who(node)
    if node == SJ_BROADCAST then return "broadcast" end
    if node == nil then return "node ??" end
    return string.format("node %02d", node)
end

-- A request (or its echo): command and data. Returns the Info text and a problem or nil.
local function sj_render_request(t, tvb, body, kind, who)
    local verb = kind == "echo" and "Echo" or "Request"
    if #body < 6 then return string.format("%s %s", verb, who), "too short for a request" end
    local problem = nil
    local cc = body:sub(3, 4)
    local command = is_hex(cc) and tonumber(cc, 16) or nil
    local item = t:add(sjf.command, tvb(3, 2), command or 0)
    local name = command and sj_commands[command]
    if name == nil then
        problem = "unknown command " .. printable(cc)
        item:append_text(" (unknown)")
    else
        t:add(sjf.command_name, tvb(3, 2), name):set_generated()
    end
    local data = body:sub(5, -3)
    if #data > 0 then
        t:add(sjf.data, tvb(5, #data), data)
        if command == 0x00 and is_dec(data) then
            t:add(sjf.run, tvb(5, #data), tonumber(data))
        elseif command == 0x01 and is_dec(data) then
            t:add(sjf.frequency, tvb(5, #data), tonumber(data) / 100)
        elseif command == 0x02 then
            t:add(sjf.terminals, tvb(5, #data), data)
        elseif command == 0x06 or command == 0x07 then
            t:add(sjf.param, tvb(5, math.min(4, #data)), data:sub(1, 4))
            if command == 0x07 and #data > 4 then
                sj_add_value(t, tvb, 9, data:sub(5), sjf.value)
            end
        end
    end
    if name ~= nil and sj_request_data[command] ~= #data then
        problem = string.format("command %s takes %d data characters, got %d",
            cc, sj_request_data[command], #data)
    end
    return string.format("%s %s: %s %s%s", verb, who, cc, name or "?",
        #data > 0 and (" " .. printable(data)) or ""), problem
end

-- A reply: its kind, NAK code, data (decoded when the request is known).
local function sj_render_reply(t, tvb, body, command, who)
    local problem = nil
    if #body < 5 then problem = "too short for a reply" end
    local third = body:byte(3)
    local reply_kind, data, nak_code = nil, "", nil
    if third == ACK then
        data = body:sub(4, -3)
        reply_kind = #data > 0 and "ACK+data" or "ACK"
        t:add(sjf.kind, tvb(3, 1), reply_kind)
    elseif third == NAK then
        reply_kind = "NAK"
        t:add(sjf.kind, tvb(3, 1), reply_kind)
        local code = body:sub(4, -3)
        if #code == 2 and is_dec(code) then nak_code = tonumber(code) end
        if nak_code == nil then problem = "NAK code is not two digits" end
    else
        reply_kind = "data"
        data = body:sub(3, -3)
        t:add(sjf.kind, reply_kind):set_generated()
    end
    if command ~= nil then
        t:add(sjf.command, command):set_generated()
        t:add(sjf.command_name, sj_commands[command] or "?"):set_generated()
    end
    local to = command ~= nil
        and string.format(" (to %02X %s)", command, sj_commands[command] or "?") or ""
    if nak_code ~= nil then
        local meaning = sj_nak_codes[nak_code] or "unknown error code"
        local item = t:add(sjf.nak_code, tvb(4, 2), nak_code)
        t:add(sjf.nak_meaning, tvb(4, 2), meaning):set_generated()
        item:add_proto_expert_info(sje.nak, string.format("NAK %02d: %s", nak_code, meaning))
        return string.format("Reply %s: NAK %02d %s%s", who, nak_code, meaning, to), problem
    end
    if #data > 0 then
        local off = third == ACK and 4 or 3
        t:add(sjf.data, tvb(off, #data), data)
        if command == 0x04 and #data == 8 and is_dec(data) then
            t:add(sjf.status_a, tvb(off, 2), tonumber(data:sub(1, 2)))
            t:add(sjf.status_b, tvb(off + 2, 2), tonumber(data:sub(3, 4)))
            t:add(sjf.status_c, tvb(off + 4, 2), tonumber(data:sub(5, 6)))
        elseif command == 0x06 then
            sj_add_value(t, tvb, off, data, sjf.value)
        elseif command == 0x09 and (data == "00" or data == "01") then
            t:add(sjf.can_store, tvb(off, 2), data == "01")
        end
        local want = command ~= nil and (third == ACK and sj_ack_data_reply[command]
            or sj_data_reply[command]) or nil
        if want ~= nil and want ~= #data then
            problem = string.format("a reply to %02X carries %d data characters, got %d",
                command, want, #data)
        end
        return string.format("Reply %s: %s %s%s", who, reply_kind, printable(data), to), problem
    end
    return string.format("Reply %s: %s%s", who, reply_kind, to), problem
end

function sj.dissector(tvb, pinfo, tree)
    local len = tvb:len()
    if len == 0 then return 0 end
    pinfo.cols.protocol = "SJ300"
    local raw = tvb:raw()
    local rec = sj_frames[pinfo.number]
    if rec == nil and (noise_flag() or len < 2 or raw:byte(1) ~= STX or raw:byte(len) ~= CR) then
        return sj_dissect_noise(tvb, pinfo, tree)
    end
    local body = raw:sub(2, -2)
    local node = sj_node(body:sub(1, 2))
    if rec == nil then
        local kind = sj_classify(body, pinfo.p2p_dir)
        local command = nil
        if kind ~= "reply" and is_hex(body:sub(3, 4)) then command = tonumber(body:sub(3, 4), 16) end
        if pinfo.visited then -- no first pass (state was reset): no pairing
            rec = { type = kind, node = node, command = command, responses = {} }
        else
            rec = sj_first_pass(pinfo.number, kind, node, command, pinfo.abs_ts, body)
        end
    end
    local kind = rec.type

    local t = tree:add(sj, tvb(), "SJ300 " .. kind)
    t:add(sjf.type, kind):set_generated()
    local problem = nil
    if #body >= 2 then
        local item = t:add(sjf.node, tvb(1, 2), node or 0)
        if node == nil then
            problem = "node is not 01..32 or FF"
            item:append_text(" (invalid: " .. printable(body:sub(1, 2)) .. ")")
        elseif node == SJ_BROADCAST then
            item:append_text(" (broadcast)")
            t:add(sjf.broadcast, tvb(1, 2), true):set_generated()
        end
    end
    local who = sj_who(node)
    local info, trouble
    if kind == "reply" then
        info, trouble = sj_render_reply(t, tvb, body, rec.command, who)
    else
        info, trouble = sj_render_request(t, tvb, body, kind, who)
    end
    problem = problem or trouble

    -- The BCC: the last two characters before CR.
    if #body >= 4 then
        local got, want = body:sub(-2), sj_bcc(body:sub(1, -3))
        local ok = got:upper() == want
        t:add(sjf.bcc, tvb(len - 3, 2), got)
        local ok_item = t:add(sjf.bcc_ok, tvb(len - 3, 2), ok)
        ok_item:set_generated()
        if not ok then
            t:add(sjf.bcc_expected, tvb(len - 3, 2), want):set_generated()
            ok_item:add_proto_expert_info(sje.bad_bcc,
                "Wrong BCC " .. printable(got) .. ", expected " .. want)
            info = info .. " [bad BCC]"
        end
    end

    if kind == "request" then
        for _, response in ipairs(rec.responses) do
            t:add(sjf.response_in, response):set_generated()
        end
        if #rec.responses == 0 and node ~= SJ_BROADCAST and pinfo.visited then
            t:add_proto_expert_info(sje.no_reply)
        end
    elseif kind == "reply" then
        if rec.request ~= nil then
            t:add(sjf.request_in, rec.request):set_generated()
            t:add(sjf.response_time, delta_nstime(rec.time, sj_frames[rec.request].time))
                :set_generated()
        else
            t:add_proto_expert_info(sje.unsolicited)
        end
    end
    if problem ~= nil then t:add_proto_expert_info(sje.malformed, "Malformed: " .. problem) end
    pinfo.cols.info = info
    return len
end

register_linktype(sj, 147)

----------------------------------------------------------------------------
-- FR-700
----------------------------------------------------------------------------

local fr = Proto("fr700", "Mitsubishi FR-700 computer link")

local fr_named = {
    [0x6C] = "read second-parameter switch", [0x6D] = "read set frequency (RAM)",
    [0x6E] = "read set frequency (EEPROM)", [0x6F] = "output frequency",
    [0x70] = "output current", [0x71] = "output voltage",
    [0x73] = "read special-monitor selection", [0x79] = "extended status",
    [0x7A] = "status", [0x7B] = "read operation mode", [0x7F] = "read link-parameter extension",
    [0xEC] = "write second-parameter switch", [0xED] = "set frequency (RAM)",
    [0xEE] = "set frequency (RAM and EEPROM)", [0xF0] = "multi-command",
    [0xF3] = "write special-monitor selection", [0xF4] = "clear fault history",
    [0xF9] = "extended run command", [0xFA] = "run command", [0xFB] = "write operation mode",
    [0xFC] = "parameter clear", [0xFD] = "inverter reset", [0xFF] = "write link-parameter extension",
}

local function fr_instruction_name(code)
    if fr_named[code] ~= nil then return fr_named[code] end
    if code <= 0x63 then return string.format("read parameter (offset %d)", code) end
    if code >= 0x74 and code <= 0x77 then
        return string.format("fault history %d", code - 0x73)
    end
    if code >= 0x80 and code <= 0xE3 then
        return string.format("write parameter (offset %d)", code - 0x80)
    end
    return nil
end

local fr_instruction_vs = {}
for code = 0, 255 do fr_instruction_vs[code] = fr_instruction_name(code) end

local fr_nak_codes = {
    [0x0] = "computer NAK error: too many consecutive errors", [0x1] = "parity error",
    [0x2] = "sum check error", [0x3] = "protocol error", [0x4] = "framing error",
    [0x5] = "overrun error", [0x7] = "character error", [0xA] = "mode error",
    [0xB] = "instruction code error", [0xC] = "data range error", [0xF] = "no error",
}
local fr_formats = {
    A = "write, 4-digit data", A1 = "write, 2-digit data", A2 = "multi-command",
    B = "read", C = "ACK", C1 = "multi-command reply", D = "NAK",
    E = "read data, 4 digits", E1 = "read data, 2 digits", E2 = "read data, other width",
    E3 = "read data, 20 characters (model name)", F = "re-output request",
}
local fr_status_bits = {
    { 0, "RUN" }, { 1, "forward" }, { 2, "reverse" }, { 3, "SU (up to frequency)" },
    { 4, "OL (overload)" }, { 5, "IPF (power failure)" }, { 6, "FU (frequency detect)" },
    { 7, "ABC1 (fault)" }, { 8, "ABC2" }, { 15, "fault occurred" },
}

local frf = {
    type = ProtoField.string("fr700.type", "Type",
        "request, reply, host_answer (the host's ACK or re-output request), echo or noise"),
    format = ProtoField.string("fr700.format", "Format", "A, A1, A2, B, C, C1, D, E, E1, E2, E3, F"),
    station = ProtoField.uint8("fr700.station", "Station", base.DEC, nil, nil, "00..1F (0..31)"),
    instruction = ProtoField.uint8("fr700.instruction", "Instruction code", base.HEX,
        fr_instruction_vs),
    instruction_name = ProtoField.string("fr700.instruction_name", "Instruction"),
    wait = ProtoField.uint8("fr700.wait", "Waiting time (x 10 ms)", base.DEC),
    data = ProtoField.string("fr700.data", "Data"),
    value = ProtoField.uint32("fr700.value", "Value", base.HEX_DEC),
    frequency = ProtoField.double("fr700.frequency", "Frequency (Hz)"),
    status = ProtoField.string("fr700.status", "Status bits set"),
    send_type = ProtoField.string("fr700.send_type", "Send data type"),
    receive_type = ProtoField.string("fr700.receive_type", "Receive data type"),
    error1 = ProtoField.uint8("fr700.error1", "Error code 1", base.HEX, fr_nak_codes),
    error2 = ProtoField.uint8("fr700.error2", "Error code 2", base.HEX, fr_nak_codes),
    data1 = ProtoField.string("fr700.data1", "Data 1"),
    data2 = ProtoField.string("fr700.data2", "Data 2"),
    nak_code = ProtoField.uint8("fr700.nak_code", "NAK code", base.HEX, fr_nak_codes),
    nak_meaning = ProtoField.string("fr700.nak_meaning", "NAK meaning"),
    sum = ProtoField.string("fr700.sum", "Sum check"),
    sum_ok = ProtoField.bool("fr700.sum_ok", "Sum check valid"),
    sum_expected = ProtoField.string("fr700.sum_expected", "Sum check expected"),
    terminator = ProtoField.string("fr700.terminator", "Terminator", "none, CR or CR LF"),
    request_in = ProtoField.framenum("fr700.request_in", "Request in", base.NONE, frametype.REQUEST),
    response_in = ProtoField.framenum("fr700.response_in", "Response in", base.NONE,
        frametype.RESPONSE),
    response_time = ProtoField.relative_time("fr700.response_time", "Response time",
        "from the host's write of the request to the arrival of the whole reply"),
    reply_in = ProtoField.framenum("fr700.reply_in", "Answers the reply in", base.NONE,
        frametype.ACK),
    answer_in = ProtoField.framenum("fr700.answer_in", "Host answer in", base.NONE,
        frametype.ACK),
    noise = ProtoField.bytes("fr700.noise", "Noise"),
}
fr.fields = {
    frf.type, frf.format, frf.station, frf.instruction, frf.instruction_name, frf.wait, frf.data,
    frf.value, frf.frequency, frf.status, frf.send_type, frf.receive_type, frf.error1, frf.error2,
    frf.data1, frf.data2, frf.nak_code, frf.nak_meaning, frf.sum, frf.sum_ok, frf.sum_expected,
    frf.terminator, frf.request_in, frf.response_in, frf.response_time, frf.reply_in,
    frf.answer_in, frf.noise,
}

local fre = {
    bad_sum = ProtoExpert.new("fr700.sum_bad", "Wrong sum check", expert.group.CHECKSUM,
        expert.severity.ERROR),
    nak = ProtoExpert.new("fr700.nak", "Negative reply (NAK)", expert.group.RESPONSE_CODE,
        expert.severity.WARN),
    reoutput = ProtoExpert.new("fr700.reoutput", "The host asks for the reply again",
        expert.group.SEQUENCE, expert.severity.NOTE),
    noise = ProtoExpert.new("fr700.noise.expert", "Noise: bytes outside any frame",
        expert.group.MALFORMED, expert.severity.WARN),
    malformed = ProtoExpert.new("fr700.malformed", "Malformed frame", expert.group.MALFORMED,
        expert.severity.ERROR),
    no_reply = ProtoExpert.new("fr700.no_reply", "No reply in the capture",
        expert.group.SEQUENCE, expert.severity.NOTE),
    unsolicited = ProtoExpert.new("fr700.unsolicited", "Reply to no request in the capture",
        expert.group.SEQUENCE, expert.severity.NOTE),
}
fr.experts = {
    fre.bad_sum, fre.nak, fre.reoutput, fre.noise, fre.malformed, fre.no_reply, fre.unsolicited,
}

-- First-pass state (reset by fr.init).
local fr_frames = {} -- frame number -> { type, format, station, instruction, request, ... }
local fr_pending = {} -- station -> frame number of its latest request still open
local fr_last_tx = nil

function fr.init()
    fr_frames, fr_pending, fr_last_tx = {}, {}, nil
end

local function fr_station(chars)
    if #chars == 2 and is_hex(chars) then
        local n = tonumber(chars, 16)
        if n <= 31 then return n end
    end
    return nil
end

local function fr_sum(chars)
    local s = 0
    for i = 1, #chars do s = s + chars:byte(i) end
    return string.format("%02X", s % 256)
end

local function fr_dissect_noise(tvb, pinfo, tree)
    pinfo.cols.info = string.format("Noise (%d bytes)", tvb:len())
    local t = tree:add(fr, tvb(), "FR-700 noise")
    t:add(frf.type, "noise"):set_generated()
    t:add(frf.noise, tvb())
    t:add_proto_expert_info(fre.noise)
    return tvb:len()
end

-- A frame, its terminator taken off: start byte, the characters after it, the terminator.
local function fr_split(raw)
    local term = ""
    if raw:sub(-2) == "\r\n" then
        term = "CR LF"
        raw = raw:sub(1, -3)
    elseif raw:sub(-1) == "\r" then
        term = "CR"
        raw = raw:sub(1, -2)
    end
    return raw:byte(1), raw:sub(2), term
end

local function fr_is_frame(start, rest)
    if start == ENQ then return #rest >= 6 and is_hex(rest) end
    if start == STX then return #rest >= 5 and rest:byte(-3) == ETX end
    if start == ACK then return #rest == 2 end
    if start == NAK then return #rest == 2 or #rest == 3 end
    return false
end

-- Decide who sent it. ENQ frames are requests (or their echo), STX frames replies;
-- ACK and NAK are a drive's reply or the host's answer to read data.
local function fr_classify(start, rest, raw, dir)
    if dir == P2P_RECV and fr_last_tx ~= nil and raw == fr_last_tx then return "echo" end
    if start == ENQ then return dir == P2P_RECV and "echo" or "request" end
    if start == STX then return "reply" end
    if start == NAK then
        -- NAK + station + code is a drive's D, NAK + station the host's F.
        return #rest == 3 and "reply" or "host_answer"
    end
    -- ACK + station: a drive's C, or the host's C after read data.
    if dir == P2P_SENT then return "host_answer" end
    if dir == P2P_RECV then return "reply" end
    local station = fr_station(rest)
    local pending = station ~= nil and fr_pending[station] or nil
    if pending ~= nil and #fr_frames[pending].responses > 0 then return "host_answer" end
    return "reply"
end

-- The format of a frame (its terminator taken off), and the instruction of a request.
-- A data reply of 12 characters is a multi-command reply (C1) when the request was
-- HF0 or is not known, an E2 otherwise.
local function fr_format(start, rest, kind, request_instruction)
    if start == ENQ then
        local instruction = tonumber(rest:sub(3, 4), 16)
        -- ENQ station(2) instruction(2) [wait(1)] data sum(2). The dissector cannot know
        -- the drive's Pr.123 (does a request carry the waiting-time character?): the
        -- length decides. Without it the characters between ENQ and the terminator are
        -- even in number (B 6, A1 8, A 10, A2 16), with it odd (7, 9, 11, 17).
        local data_len = #rest - 6 - #rest % 2
        if instruction < 0x80 then return "B", instruction end
        if instruction == 0xF0 then return "A2", instruction end
        return data_len == 2 and "A1" or "A", instruction
    end
    if start == STX then
        local n = #rest - 5
        if n == 12 and (request_instruction == 0xF0 or request_instruction == nil) then
            return "C1"
        end
        if n == 4 then return "E" end
        if n == 2 then return "E1" end
        if n == 20 then return "E3" end
        return "E2"
    end
    if start == ACK then return "C" end
    return #rest == 3 and "D" or "F"
end

local fr_data_formats = { E = true, E1 = true, E2 = true, E3 = true, C1 = true }

-- First pass: record the frame and pair it with the request of its station.
local function fr_first_pass(number, rec, raw)
    fr_frames[number] = rec
    local station = rec.station
    if rec.type == "request" then
        fr_last_tx = raw
        if station ~= nil then
            -- The inverter reset (HFD) gets no reply.
            fr_pending[station] = rec.instruction ~= 0xFD and number or nil
        end
    elseif rec.type == "host_answer" then
        fr_last_tx = raw
        local request = station ~= nil and fr_pending[station] or nil
        if request ~= nil then
            local req = fr_frames[request]
            rec.request, rec.instruction = request, req.instruction
            rec.reply = req.responses[#req.responses]
            if rec.reply ~= nil then fr_frames[rec.reply].answer = number end
            -- After the host's ACK the exchange is over; after its re-output request
            -- (F) the drive sends its reply again, to the same request.
            if rec.format == "C" then fr_pending[station] = nil end
        end
    elseif rec.type == "reply" and station ~= nil then
        local request = fr_pending[station]
        if request ~= nil then
            local req = fr_frames[request]
            rec.request, rec.instruction = request, req.instruction
            table.insert(req.responses, number)
            -- Read data stays open for the host's ACK or re-output request.
            if not fr_data_formats[rec.format] then fr_pending[station] = nil end
        end
    end
    return rec
end

local function fr_add_value(t, tvb, off, data, instruction)
    if not is_hex(data) or #data > 8 then return end
    local value = tonumber(data, 16)
    t:add(frf.value, tvb(off, #data), value)
    if instruction == 0x6D or instruction == 0x6E or instruction == 0x6F
        or instruction == 0xED or instruction == 0xEE then
        t:add(frf.frequency, tvb(off, #data), value / 100)
    elseif instruction == 0x79 or instruction == 0x7A then
        local set = {}
        for _, b in ipairs(fr_status_bits) do
            if math.floor(value / 2^b[1]) % 2 == 1 then table.insert(set, b[2]) end
        end
        t:add(frf.status, tvb(off, #data), #set > 0 and table.concat(set, ", ") or "none")
    end
end

local function fr_add_multi(t, tvb, off, data, reply)
    t:add(frf.send_type, tvb(off, 1), data:sub(1, 1))
    t:add(frf.receive_type, tvb(off + 1, 1), data:sub(2, 2))
    if reply then
        for i, field in ipairs({ frf.error1, frf.error2 }) do
            local c = data:sub(2 + i, 2 + i)
            if is_hex(c) then t:add(field, tvb(off + 1 + i, 1), tonumber(c, 16)) end
        end
        off, data = off + 2, data:sub(3)
    end
    t:add(frf.data1, tvb(off + 2, 4), data:sub(3, 6))
    t:add(frf.data2, tvb(off + 6, 4), data:sub(7, 10))
end

-- ENQ station(2) instruction(2) [wait(1)] data sum(2): Info text and a problem or nil.
local function fr_render_request(t, tvb, rest, rec, who)
    local instruction, format = rec.instruction, rec.format
    local item = t:add(frf.instruction, tvb(3, 2), instruction)
    local name = fr_instruction_name(instruction)
    if name ~= nil then
        t:add(frf.instruction_name, tvb(3, 2), name):set_generated()
    else
        item:append_text(" (no name known)")
    end
    local data_at = 5
    if #rest % 2 == 1 then -- the waiting-time character (see fr_format)
        t:add(frf.wait, tvb(5, 1), tonumber(rest:sub(5, 5), 16))
        data_at = 6
    end
    local data = rest:sub(data_at, -3)
    local problem = nil
    if format == "B" and #data ~= 0 then
        problem = "a read (format B) carries no data"
    elseif format == "A2" and #data ~= 10 then
        problem = "a multi-command (A2) carries 10 characters of data"
    elseif format == "A" and #data ~= 4 then
        problem = "a write carries 2 or 4 digits of data"
    end
    if #data > 0 then
        t:add(frf.data, tvb(data_at, #data), data)
        if format == "A2" and #data == 10 then
            fr_add_multi(t, tvb, data_at, data, false)
        elseif format ~= "A2" then
            fr_add_value(t, tvb, data_at, data, instruction)
        end
    end
    return string.format("%s %s: H%02X %s%s", rec.type == "echo" and "Echo" or "Request", who,
        instruction, name or "?", #data > 0 and (" " .. data) or ""), problem
end

function fr.dissector(tvb, pinfo, tree)
    local len = tvb:len()
    if len == 0 then return 0 end
    pinfo.cols.protocol = "FR700"
    local raw = tvb:raw()
    local start, rest, term = fr_split(raw)
    local rec = fr_frames[pinfo.number]
    if rec == nil and (noise_flag() or not fr_is_frame(start, rest)) then
        return fr_dissect_noise(tvb, pinfo, tree)
    end
    local station = fr_station(rest:sub(1, 2))
    if rec == nil then
        local kind = fr_classify(start, rest, raw, pinfo.p2p_dir)
        local pending = station ~= nil and fr_pending[station] or nil
        local format, instruction = fr_format(start, rest, kind,
            pending and fr_frames[pending].instruction)
        rec = { type = kind, format = format, station = station, instruction = instruction,
            time = pinfo.abs_ts, responses = {} }
        if not pinfo.visited then fr_first_pass(pinfo.number, rec, raw) end
    end
    local kind, format = rec.type, rec.format

    local t = tree:add(fr, tvb(), "FR-700 " .. kind:gsub("_", " "))
    t:add(frf.type, kind):set_generated()
    t:add(frf.format, format):set_generated():append_text(" (" .. fr_formats[format] .. ")")
    local item = t:add(frf.station, tvb(1, 2), station or 0)
    local problem = nil
    if station == nil then
        problem = "station is not 00..1F"
        item:append_text(" (invalid: " .. printable(rest:sub(1, 2)) .. ")")
    end
    local who = station and string.format("station %d", station) or "station ??"

    local info, trouble
    local sum_over = nil -- the characters the sum check covers
    if start == ENQ then
        info, trouble = fr_render_request(t, tvb, rest, rec, who)
        sum_over = rest:sub(1, -3)
    elseif start == STX then
        -- STX station(2) data ETX sum(2)
        local data = rest:sub(3, -4)
        if #data == 0 then trouble = "a data reply without data" end
        if #data > 0 then
            t:add(frf.data, tvb(3, #data), data)
            if format == "C1" then
                fr_add_multi(t, tvb, 3, data, true)
            elseif format ~= "E3" then
                fr_add_value(t, tvb, 3, data, rec.instruction)
            end
        end
        info = string.format("Reply %s: %s %s", who, format, printable(data))
        sum_over = rest:sub(1, -4)
    elseif format == "C" then
        if kind == "host_answer" then
            info = string.format("Host ACK %s (reply received)", who)
        else
            info = string.format("Reply %s: ACK", who)
        end
    elseif format == "D" then
        local code = rest:sub(3, 3)
        local n = is_hex(code) and tonumber(code, 16) or nil
        if n ~= nil then
            local meaning = fr_nak_codes[n] or "unknown error code"
            local nak_item = t:add(frf.nak_code, tvb(3, 1), n)
            t:add(frf.nak_meaning, tvb(3, 1), meaning):set_generated()
            nak_item:add_proto_expert_info(fre.nak, string.format("NAK %X: %s", n, meaning))
            info = string.format("Reply %s: NAK %X %s", who, n, meaning)
        else
            trouble = "NAK code is not a hex digit"
            info = string.format("Reply %s: NAK ?", who)
        end
    else -- F
        t:add_proto_expert_info(fre.reoutput)
        info = string.format("Host NAK %s (send the reply again)", who)
    end
    problem = problem or trouble

    if sum_over ~= nil then
        local at = 1 + #rest - 2
        local got, want = rest:sub(-2), fr_sum(sum_over)
        local ok = got:upper() == want
        t:add(frf.sum, tvb(at, 2), got)
        local ok_item = t:add(frf.sum_ok, tvb(at, 2), ok)
        ok_item:set_generated()
        if not ok then
            t:add(frf.sum_expected, tvb(at, 2), want):set_generated()
            ok_item:add_proto_expert_info(fre.bad_sum,
                "Wrong sum check " .. printable(got) .. ", expected " .. want)
            info = info .. " [bad sum check]"
        end
    end
    t:add(frf.terminator, term == "" and "none" or term):set_generated()

    if start ~= ENQ and rec.instruction ~= nil then
        local name = fr_instruction_name(rec.instruction)
        t:add(frf.instruction, rec.instruction):set_generated()
        if name ~= nil then t:add(frf.instruction_name, name):set_generated() end
        info = info .. string.format(" (to H%02X %s)", rec.instruction, name or "?")
    end
    if kind == "request" then
        for _, response in ipairs(rec.responses) do
            t:add(frf.response_in, response):set_generated()
        end
        if #rec.responses == 0 and rec.instruction ~= 0xFD and pinfo.visited then
            t:add_proto_expert_info(fre.no_reply)
        end
    elseif kind == "reply" or kind == "host_answer" then
        if rec.request ~= nil then
            t:add(frf.request_in, rec.request):set_generated()
            if kind == "reply" then
                t:add(frf.response_time, delta_nstime(rec.time, fr_frames[rec.request].time))
                    :set_generated()
            end
        elseif kind == "reply" then
            t:add_proto_expert_info(fre.unsolicited)
        end
        if rec.reply ~= nil then t:add(frf.reply_in, rec.reply):set_generated() end
        if rec.answer ~= nil then t:add(frf.answer_in, rec.answer):set_generated() end
    end
    if problem ~= nil then t:add_proto_expert_info(fre.malformed, "Malformed: " .. problem) end
    pinfo.cols.info = info
    return len
end

register_linktype(fr, 148)
