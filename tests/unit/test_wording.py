"""Counts read as English, and senders as --sender takes them back."""

from __future__ import annotations

from vstig_hw.wording import counted, shown_sender


def test_a_count_of_one_takes_the_singular_and_every_other_count_the_plural() -> None:
    assert [counted(n, "message") for n in (0, 1, 2)] == ["0 messages", "1 message", "2 messages"]
    assert counted(1, "entry", "entries") == "1 entry"
    assert counted(3, "entry", "entries") == "3 entries"


def test_a_node_id_shows_in_decimal_and_an_xbee_address_in_hex() -> None:
    assert shown_sender(7) == "7"
    assert shown_sender(0xFFFF) == "65535"
    assert shown_sender(0x0013A20040A1B2C3) == "0x0013A20040A1B2C3"
    assert int(shown_sender(0x0013A20040A1B2C3), 0) == 0x0013A20040A1B2C3  # as --sender reads it
