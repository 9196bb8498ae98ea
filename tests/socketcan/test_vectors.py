"""The hand-worked CAN vectors against our framing (offline: no bus needed)."""

from __future__ import annotations

import pytest
from can_vectors import FrameVector, load

from vstig_hw.framing.can import CanFraming

VECTORS = load()


def _ids(vector: FrameVector) -> str:
    return vector.name


def test_vector_file_covers_every_drop_reason_and_both_widths() -> None:
    assert {v.drop for v in VECTORS} == {None, "unknown_id", "bad_dlc", "op_mismatch", "remote_frame"}
    assert {v.scheme.extended for v in VECTORS if v.drop is None} == {False, True}
    assert any(v.frame.is_fd for v in VECTORS if v.drop is None)


@pytest.mark.parametrize("vector", VECTORS, ids=_ids)
def test_cansend_string_names_the_same_frame(vector: FrameVector) -> None:
    ident, _, payload = vector.cansend.partition("#")
    assert int(ident, 16) == vector.frame.arbitration_id
    assert (len(ident) == 8) == vector.frame.is_extended_id
    if payload == "R":
        assert vector.frame.is_remote_frame
    elif payload.startswith("#"):  # CAN FD: a flags nibble, then data
        assert vector.frame.is_fd and payload[1] == "1"
        assert bytes.fromhex(payload[2:]) == vector.frame.data
    else:
        assert not vector.frame.is_fd and bytes.fromhex(payload) == vector.frame.data


@pytest.mark.parametrize("vector", VECTORS, ids=_ids)
def test_vector_decodes_to_its_messages_or_its_drop(vector: FrameVector) -> None:
    framing = CanFraming(vector.scheme, sender=1, fd=True)
    assert framing.feed(vector.frame) == vector.messages
    assert dict(framing.drops) == ({} if vector.drop is None else {vector.drop: 1})
    assert framing.sender_of(vector.frame) == vector.sender


@pytest.mark.parametrize("vector", [v for v in VECTORS if v.drop is None], ids=_ids)
def test_encoder_produces_exactly_the_vector_frame(vector: FrameVector) -> None:
    assert vector.sender is not None
    framing = CanFraming(vector.scheme, sender=vector.sender, fd=vector.frame.is_fd)
    (frame,) = framing.encode_batch(vector.messages)
    assert frame.arbitration_id == vector.frame.arbitration_id
    assert frame.is_extended_id == vector.frame.is_extended_id
    assert frame.is_fd == vector.frame.is_fd
    assert bytes(frame.data) == bytes(vector.frame.data)
    assert vector.scheme.parse(frame.arbitration_id, frame.is_extended_id) == (vector.messages[0].op, vector.sender)
    assert all(m.op is vector.messages[0].op for m in vector.messages)
