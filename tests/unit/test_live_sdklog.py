"""The live view's handler of foxglove-sdk's log lines: safe for a terminal, rate-limited, counted."""

from __future__ import annotations

import io
import logging

from vstig_hw.counters import Counters
from vstig_hw.live.sdklog import LINES_BURST, SdkLog, safe_line


def test_a_line_keeps_what_a_terminal_shows_as_is_and_escapes_the_rest() -> None:
    assert safe_line("Invalid message from 127.0.0.1:5: unknown variant `é 中`") == \
        "Invalid message from 127.0.0.1:5: unknown variant `é 中`"
    assert safe_line("a\nb\r\x1b[31mred\x1b]0;title\x07\u202eevil\u2028") == \
        "a\\nb\\r\\x1b[31mred\\x1b]0;title\\x07\\u202eevil\\u2028"
    assert safe_line("x" * 10_000_000) == "x" * 297 + "..."


def test_a_flood_of_lines_is_written_in_a_burst_then_counted() -> None:
    counters = Counters(viewers_refused=0, log_dropped=0)
    out = io.StringIO()
    handler = SdkLog(counters, viewers=16, out=out)
    handler.install()
    try:
        logger = logging.getLogger("foxglove.websocket.connected_client")
        for i in range(1000):
            logger.error("Invalid message from 127.0.0.1:5: %s", f"\x1b[2J{i}")
    finally:
        handler.uninstall()
    lines = out.getvalue().splitlines()
    assert len(lines) <= LINES_BURST + 2  # the burst, perhaps one refilled, and the count said at the end
    assert lines[0] == "live view: Invalid message from 127.0.0.1:5: \\x1b[2J0"
    assert lines[-1] == f"live view: {counters['log_dropped']} more lines from the server held back (counted: " \
                        "log_dropped)"
    assert counters["log_dropped"] == 1000 - (len(lines) - 1)


def test_viewers_are_counted_as_the_sdk_takes_them_in_and_lets_them_go() -> None:
    handler = SdkLog(Counters(viewers_refused=0, log_dropped=0), viewers=2, out=io.StringIO())
    handler.install()
    try:
        server = logging.getLogger("foxglove.websocket.server")
        for port in (1, 2):
            server.info("Registered client 127.0.0.1:%d", port)
        server.info("Unregistered client 127.0.0.1:1")
        server.info("Registered client [::1]:3")
    finally:
        handler.uninstall()
    assert handler.viewers == {"127.0.0.1:2", "[::1]:3"}
