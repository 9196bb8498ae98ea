"""The reference C codec against every JSON vector, built strict and with ASan+UBSan."""

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


def test_c_sources_fit_small_targets() -> None:
    """No heap, no floating point, no 64-bit arithmetic: what an 8-bit AVR can afford."""
    for name in ("vstig_wire.c", "vstig_wire.h"):
        text = (C_DIR / name).read_text(encoding="utf-8")
        code = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
        for banned in ("malloc", "free(", "double", "float", "uint64_t", "int64_t", "long long"):
            assert banned not in code, f"{name} uses {banned}"
