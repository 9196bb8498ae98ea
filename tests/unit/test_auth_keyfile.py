"""The swarm key file: 64 hex digits only its owner may read; every refusal names the file."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from vstig_hw.auth import KEY_SIZE, new_swarm_key_text, read_swarm_key
from vstig_hw.inputs import InputFileError


def _key_file(tmp_path: Path, text: str, mode: int = 0o600) -> Path:
    path = tmp_path / "swarm.key"
    path.write_text(text, encoding="ascii")
    path.chmod(mode)
    return path


def test_a_fresh_key_reads_back(tmp_path: Path) -> None:
    text = new_swarm_key_text()
    assert read_swarm_key(_key_file(tmp_path, text)) == bytes.fromhex(text.strip())
    assert len(bytes.fromhex(text)) == KEY_SIZE and text != new_swarm_key_text()


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o620, 0o666])
def test_group_or_others_access_is_refused(tmp_path: Path, mode: int) -> None:
    path = _key_file(tmp_path, new_swarm_key_text(), mode)
    with pytest.raises(InputFileError, match=rf"{path}: the swarm key file is readable or writable by others .*"
                                             rf"chmod 600"):
        read_swarm_key(path)


@pytest.mark.parametrize("text", ["", "ab" * 31, "ab" * 33, "zz" * 32, "correct horse battery staple"])
def test_anything_but_64_hex_digits_is_refused(tmp_path: Path, text: str) -> None:
    path = _key_file(tmp_path, text)
    with pytest.raises(InputFileError, match=rf"{path}: the swarm key file must hold 64 hex digits"):
        read_swarm_key(path)


def test_a_fifo_or_a_missing_file_is_refused_without_waiting(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    with pytest.raises(InputFileError, match="must be a regular file"):
        read_swarm_key(fifo)
    with pytest.raises(InputFileError, match="cannot read the swarm key file"):
        read_swarm_key(tmp_path / "absent")
