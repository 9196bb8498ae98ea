"""Dialect decode rates beside our own 8-byte decode, measured in the same run (issue 15)."""

from __future__ import annotations

import random
from collections.abc import Iterator

from vstig_hw import decode
from vstig_hw.dialects.bittybuzz import BbzOp, BbzVstig, decode_bittybuzz, encode_bittybuzz
from vstig_hw.dialects.buzz import BuzzOp, BuzzVstig, decode_buzz, encode_buzz
from vstig_hw.dialects.mapping import parse_deployment
from vstig_hw.dialects.translate import BuzzTranslator

from .registry import Result, benchmark, rate

_N = 20_000


@benchmark("dialects")
def decoders() -> Iterator[Result]:
    rng = random.Random(3)
    ours = [rng.getrandbits(64).to_bytes(8, "big") for _ in range(_N)]
    buzz = [encode_buzz(BuzzVstig(BuzzOp.PUT, 1, "leader", rng.randrange(-30000, 30000), rng.randrange(1, 65536),
                                  rng.getrandbits(16))) for _ in range(_N)]
    bbz = [encode_bittybuzz(BbzVstig(BbzOp.PUT, rng.getrandbits(16), 41, 1, rng.getrandbits(16),
                                     rng.getrandbits(8))) for _ in range(_N)]
    translator = BuzzTranslator(parse_deployment('[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }'))

    def our_decode() -> int:
        for raw in ours:
            decode(raw)
        return _N

    def buzz_decode() -> int:
        for raw in buzz:
            decode_buzz(raw)
        return _N

    def buzz_to_ours() -> int:
        for raw in buzz:
            translator.to_ours(decode_buzz(raw))  # type: ignore[arg-type]
        return _N

    def bbz_decode() -> int:
        for raw in bbz:
            decode_bittybuzz(raw)
        return _N

    anchor = rate(our_decode)
    yield Result("dialects.buzz_decode", rate(buzz_decode), "msg/s", "our wire.decode", anchor)
    yield Result("dialects.buzz_to_message", rate(buzz_to_ours), "msg/s", "our wire.decode", anchor)
    yield Result("dialects.bittybuzz_decode", rate(bbz_decode), "msg/s", "our wire.decode", anchor)
