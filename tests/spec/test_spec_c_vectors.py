"""libvstig against every JSON vector, built strict and with ASan+UBSan."""

from __future__ import annotations

import re

from conftest import C_DIR, Driver, load, results


def _check(driver: Driver, cases: list[tuple[str, str, str]]) -> None:
    """cases: (name, command, expected line); all run in one driver process."""
    got = driver.run(command for _, command, _ in cases)
    wrong = [(name, command, want, line) for (name, command, want), line in zip(cases, got, strict=True)
             if line != want]
    assert not wrong, "\n".join(f"{name}: `{command}` gave {line!r}, want {want!r}" for name, command, want, line
                                in wrong[:10])


def test_wire(driver: Driver) -> None:
    vectors = load("wire.json")
    cases = []
    for v in vectors["valid"]:
        f = v["fields"]
        text = f"{f['op']} {f['key']} {f['value']} {f['timestamp']} {f['robot']}"
        cases.append((v["name"], f"decode {v['hex']}", text))
        cases.append((v["name"], f"encode {text}", v["hex"]))
    for v in vectors["invalid"]:
        cases.append((v["name"], f"decode {v['hex'] or '-'}", f"{v['outcome']} {v['reason']}"))
    _check(driver, cases)


def test_timestamps(driver: Driver) -> None:
    vectors = load("timestamps.json")
    cases = [(c["why"], f"newer {c['a']} {c['b']}", str(int(c["a_is_newer"]))) for c in vectors["compare"]]
    cases += [(f"next {c['timestamp']}", f"next {c['timestamp']}", str(c["next"])) for c in vectors["next"]]
    _check(driver, cases)


def test_crc_catalogue(driver: Driver) -> None:
    cases = []
    for c in load("cobs8.json")["crc_check_values"]:
        command = {"CRC-16/MCRF4XX": "crc16", "CRC-32/ISO-HDLC": "crc32"}[c["algorithm"]]
        cases.append((f"{c['algorithm']} {c['ascii']!r}", f"{command} {c['hex'] or '-'}", c["crc"]))
    _check(driver, cases)


def test_cobs8(driver: Driver) -> None:
    vectors = load("cobs8.json")
    cases = []
    for f in vectors["frames"]:
        cases.append((f["name"], f"cobs8 {f['message']}", f["frame"]))
        cases.append((f["name"], f"crc16 {f['message']}", f["crc"]))
        cases.append((f["name"], f"cobs8_rx {f['frame']}", results([f["message"]], {})))
    for s in vectors["streams"]:
        cases.append((s["name"], f"cobs8_rx {s['stream']}", results(s["messages"], s["drops"])))
    _check(driver, cases)


def test_epuck4(driver: Driver) -> None:
    vectors = load("epuck4.json")
    cases = []
    for m in vectors["messages"]:
        cases.append((m["name"], f"epuck4 {m['message']}", " ".join(m["words"] + m["uart"])))
        cases.append((m["name"], f"crc32 {m['message']}", m["crc32"]))
        cases.append((m["name"], f"epuck4_uart_rx {''.join(m['uart'])}", results([m["message"]], {})))
    for r in vectors["reassembly"]:
        events = " ".join("t" if "tick" in e else f"w:{e['word']}" for e in r["events"])
        cases.append((r["name"], f"epuck4_rx {vectors['expiry_ticks']} {events}", results(r["messages"], r["drops"])))
    _check(driver, cases)


def test_kilobot(driver: Driver) -> None:
    vectors = load("kilobot.json")
    cases = []
    for m in vectors["messages"]:
        cases.append((m["name"], f"kilobot {m['message']} {m['type']}", f"{m['message_t']} {m['uart']}"))
        cases.append((m["name"], f"kilocrc {m['message_t'][:20]}", m["kilobot_crc"][2:] + m["kilobot_crc"][:2]))
    custom = vectors["custom_type"]
    assert driver.one(f"kilobot {custom['message']} {custom['type']}").split()[0] == custom["message_t"]
    for s in vectors["streams"]:
        cases.append((s["name"], f"kilobot_rx {vectors['default_type']} {s['stream']}",
                      results(s["messages"], s["drops"])))
    _check(driver, cases)


def test_ohc(driver: Driver) -> None:
    vectors = load("ohc.json")
    cases = [(p["name"], f"ohc {p['message']} {vectors['packet_types'][p['packet_type']]} {p['type']}", p["packet"])
             for p in vectors["packets"]]
    _check(driver, cases)


def test_receive_rules(driver: Driver) -> None:
    vectors = load("receive.json")
    key = vectors["key"]
    cases = []
    for case in vectors["cases"]:
        local = case["local"]
        held = "-" if local is None else f"{key:04x}{local['value']:04x}{local['timestamp']:04x}{local['robot']:04x}"
        after, lost = case["entry_after"], case["conflict_lost"]
        want = (f"{case['outcome']} entry={_entry(after)} queued={','.join(case['queued']) or '-'} "
                f"lost={_entry(lost)}")
        before = "get" if case["before"] == ["get"] else "-"
        assert case["before"] in ([], ["get"]), case["name"]
        cases.append((case["name"], f"engine_case {case['self']} {case['resolver']} {held} {before} "
                                    f"{case['incoming']}", want))
    _check(driver, cases)


def _entry(entry: dict[str, int] | None) -> str:
    return "-" if entry is None else f"{entry['value']},{entry['timestamp']},{entry['robot']}"


def test_can_frames(driver: Driver) -> None:
    """Every frame of can.json decodes as listed, and every one that carries messages is what its sender's
    encoder makes of them (SPEC.md 9)."""
    vectors = load("can.json")
    cases = []
    for v in vectors["frames"]:
        scheme = vectors["schemes"][v["scheme"]]
        setup = f"{int(scheme['extended'])} {scheme['base']} {scheme['stigmergy']}"
        messages = [_hex(m) for m in v["messages"]]
        drops = {v["drop"]: 1} if v["drop"] else {}
        sender = v["sender"] if messages else 0
        frame = f"{v['id']} {int(v['extended'])} {int(v['fd'])} {int(v.get('remote', False))} {v['data'] or '-'}"
        cases.append((v["name"], f"can_rx {setup} {frame}", f"sender={sender} " + results(messages, drops)))
        if v["drop"] is None:
            cases.append((v["name"], f"can_tx {setup} {v['sender']} {int(v['fd'])} {''.join(messages)}",
                          v["cansend"].upper()))
    _check(driver, cases)


def _hex(m: dict[str, object]) -> str:
    words = [(0x8000 if m["op"] == "GET" else 0) | int(str(m["key"]))] + [int(str(m[f]))
                                                                      for f in ("value", "timestamp", "robot")]
    return "".join(f"{word:04x}" for word in words)


def test_a_node_id_above_255_is_refused_on_11_bits(driver: Driver) -> None:
    assert driver.one("can_tx 0 - 0 256 0 0001002A00030005") == "refused"
    assert driver.one("can_tx 1 - 0 256 0 0001002A00030005").startswith("18000100#")
    assert driver.one("can_tx 0 0x100 0 1 0 0001002A00030005") == "refused"  # not a base of the scheme
    assert driver.one("can_tx 0 - 1 1 0 0001002A00030005") == "refused"  # 11 bits have no stigmergy field


def test_buffers_fed_in_pieces_give_what_bytes_one_at_a_time_give(driver: Driver) -> None:
    """vstig_serial_receive with an output of one or two messages a call, over chunks cut anywhere."""
    framings = {"cobs8": 0, "epuck4": 1, "kilobot": 2}
    cases = []
    for name, stream in [("cobs8", s["stream"]) for s in load("cobs8.json")["streams"]] + [
            ("kilobot", s["stream"]) for s in load("kilobot.json")["streams"]] + [
            ("epuck4", "".join(m["uart"])) for m in load("epuck4.json")["messages"]]:
        whole = {"cobs8": f"cobs8_rx {stream}", "kilobot": f"kilobot_rx 86 {stream}",
                 "epuck4": f"epuck4_uart_rx {stream}"}[name]
        want = driver.one(whole)
        for cut, most in ((3, 1), (7, 2)):
            chunks = [stream[i:i + 2 * cut] for i in range(0, len(stream), 2 * cut)] or ["-"]
            cases.append((f"{name} {stream[:24]}", f"serial_rx {framings[name]} {most} {' '.join(chunks)}", want))
    _check(driver, cases)


def test_random_traffic_keeps_every_invariant(driver: Driver) -> None:
    """Random messages, keys beyond the table's capacity, noise on the serial links and mangled CAN frames,
    through every part (under ASan+UBSan in the sanitized build): bounded, one message per key, PUTs first."""
    assert driver.run(f"traffic {seed} 40" for seed in range(1, 6)) == ["ok"] * 5


def test_c_sources_fit_small_targets() -> None:
    """No heap, no floating point, no 64-bit arithmetic, no I/O: what an 8-bit AVR can afford."""
    names = sorted(C_DIR.glob("vstig*.[ch]"))
    assert len(names) >= 14, names
    for path in names:
        code = re.sub(r"/\*.*?\*/", "", path.read_text(encoding="utf-8"), flags=re.S)
        for banned in ("malloc", "free(", "double", "float", "uint64_t", "int64_t", "long long", "stdio", "printf",
                       "time("):
            assert banned not in code, f"{path.name} uses {banned}"


def _xbee_frames(frames: list[dict[str, object]]) -> str:
    return ";".join(f"{frame['sender']}={','.join(frame['messages'])}" for frame in frames) or "-"  # type: ignore[arg-type]


def test_xbee_streams(driver: Driver) -> None:
    """Every stream of xbee.json, whole and byte by byte (the line goes quiet at its end), in its API mode."""
    cases = []
    for v in load("xbee.json")["streams"]:
        want = f"{_xbee_frames(v['frames'])} {results([], v['drops'])}"
        stream = v["stream"]
        for chunks in ([stream], [stream[i:i + 2] for i in range(0, len(stream), 2)]):
            cases.append((f"api{v['api']}: {v['name']}", f"xbee_rx {v['api']} {' '.join(chunks)}", want))
    for v in load("xbee.json")["checksums"]:  # Digi's examples are whole frames: an AT command, a Transmit Request
        data = v["frame_data"]                 # (8 bytes of RF data: one message, sent by us), a frame type 0x23
        want = f"-={data[28:]} {results([], {})}" if data[:2] == "10" else f"- {results([], {'unknown_type': 1})}"
        cases += [(v["source"], f"xbee_rx {api} {v[f'api{api}']}", want) for api in (1, 2) if f"api{api}" in v]
    _check(driver, cases)


def test_xbee_transmit_requests(driver: Driver) -> None:
    """xbee.json's Transmit Requests (frame id 1, broadcast) in both modes, and NP -> messages per frame."""
    vectors = load("xbee.json")
    cases = [(case["name"], f"xbee_tx {api} 64 0 {','.join(case['messages'])}", case[f"api{api}"])
             for api in (1, 2) for case in vectors["transmit"]]
    _check(driver, cases)
    for case in vectors["messages_per_frame"]:  # one message more than a frame holds: two frames, the first full
        sent = ",".join(f"{key:016x}" for key in range(case["messages"] + 1))
        frames = driver.one(f"xbee_tx 1 {case['np']} 0 {sent}")
        first = int(frames[2:6], 16) - 14  # the first frame's RF data, from its length
        assert first == case["messages"] * 8 and frames.count("7e") >= 2, case


def test_xbee_frame_ids_follow_the_ticks(driver: Driver) -> None:
    """The first frame of a control period asks for a report (frame ids 1, 2, ... 255, 1), the others carry 0."""
    batches = " ".join(["0001002a00030005"] * 3)
    ids = [frame[8:10] for frame in driver.one(f"xbee_tx 1 64 1 {batches}").split()]
    assert ids == ["01", "02", "03"]
    ids = [frame[8:10] for frame in driver.one(f"xbee_tx 1 64 0 {batches}").split()]
    assert ids == ["01", "00", "00"]
    wrapped = driver.one(f"xbee_tx 2 64 1 {' '.join(['0001002a00030005'] * 256)}").split()
    assert [frame[8:10] for frame in wrapped[253:]] == ["fe", "ff", "01"]
