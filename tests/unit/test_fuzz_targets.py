"""The fuzz targets of `make fuzz`, run briefly on their seeds and random mutations of them (no atheris needed)."""

from __future__ import annotations

import random
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fuzz"))
from targets import TARGETS, seeds


def mutations(seed: bytes, rng: random.Random, count: int) -> list[bytes]:
    """Bit flips, byte changes, cuts and splices of `seed`: cheap cousins of libFuzzer's mutators."""
    out = []
    for _ in range(count):
        data = bytearray(seed)
        for _ in range(rng.randint(1, 4)):
            choice = rng.randrange(4)
            at = rng.randrange(len(data) + 1)
            if choice == 0 and data:
                data[at % len(data)] ^= 1 << rng.randrange(8)
            elif choice == 1 and data:
                data[at % len(data)] = rng.randrange(256)
            elif choice == 2:
                del data[at:at + rng.randint(1, 8)]
            else:
                data[at:at] = rng.randbytes(rng.randint(1, 8))
        out.append(bytes(data))
    return out


def test_every_target_has_seeds() -> None:
    assert set(seeds()) == set(TARGETS)


@pytest.mark.parametrize("name", list(TARGETS))
def test_target_takes_its_seeds_their_mutations_and_noise(name: str) -> None:
    rng = random.Random(name)
    target = TARGETS[name]
    for seed in seeds()[name]:
        target(seed)
        for data in mutations(seed, rng, 300):
            target(data)
    for _ in range(300):
        target(rng.randbytes(rng.randint(0, 200)))
