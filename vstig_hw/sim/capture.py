"""A simulated run's radio traffic as a CAN capture, so `vstig analyze` can be checked against the truth.

Robot i transmits under CAN node id i (11-bit IDs up to 256 robots, 29-bit
beyond), and what it broadcasts at the end of control step k is stamped
k x the run's control step (Config.control_step, `--control-step`), so the
times analyze reports are the run's. The capture format follows the file's
extension, as `vstig record` chooses it (.log is a candump log).
"""

from __future__ import annotations

import can
import numpy as np

from ..capture.canlog import CanCaptureWriter
from ..capture.records import CAN_FRAMING, Record
from ..framing.can import CanIdScheme
from ..wire import Message, encode
from .experiment import Config, RunResult, run_once

__all__ = ["CHANNEL", "capture_run", "id_scheme"]

CHANNEL = "sim"  # the link name the capture gives the simulated radio


def id_scheme(robots: int) -> CanIdScheme:
    """11-bit IDs carry senders 0..255; a larger swarm needs 29-bit IDs (16-bit sender field)."""
    return CanIdScheme(extended=robots > CanIdScheme().max_sender + 1)


def capture_run(config: Config, seed: np.random.SeedSequence, path: str, run: int = 0) -> RunResult:
    """Run once (as `run_once` would) and write every broadcast to the capture at `path`."""
    scheme = id_scheme(config.robots)
    writer = CanCaptureWriter(path)

    def record(step: int, outgoing: list[list[Message]]) -> None:
        t = step * config.control_step
        for robot, messages in enumerate(outgoing):
            for message in messages:
                frame = can.Message(timestamp=t, arbitration_id=scheme.can_id(message.op, robot),
                                    is_extended_id=scheme.extended, data=encode(message))
                writer.write(Record(t, CHANNEL, CAN_FRAMING, frame))

    try:
        return run_once(config, seed, run, on_broadcast=record)
    finally:
        writer.close()
