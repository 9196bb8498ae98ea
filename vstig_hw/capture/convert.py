"""Convert captures into any format `vstig record` writes, chosen by the output's extension.

The inputs' records are merged by time and written through record's own writers
(`RotatingCapture`), so a converted file is the file a recording would have made:
CAN frames keep their timestamps and link names (capture.channel_names for ASC
and BLF), serial chunks and zenoh samples stay as they were heard. An .mcap output
takes any records (decoded messages); a CAN capture takes CAN frames only, and a
serial or zenoh capture the units of its own medium.

The file is written under a temporary name beside the output and renamed at the
end, so a conversion that fails half way leaves no half file.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import os
import tempfile
from collections.abc import Iterator, Sequence

from ..counters import Counters
from ..framing.zenoh import ZenohFraming
from .decoded import Decoder, RecordFilter, default_framings
from .files import RotatingCapture
from .filters import Filter
from .records import (
    CAN_EXTENSIONS,
    CAN_FRAMING,
    MCAP_EXTENSION,
    MESSAGE_FRAMING,
    STRICT,
    CaptureError,
    Damage,
    Record,
    capture_suffix,
    read_capture,
)

__all__ = ["convert", "output_medium"]

_MEDIUM_NAMES = {"can": "CAN frames", "zenoh": "zenoh samples", "serial": "serial chunks",
                 "mcap": "decoded messages (MCAP)"}


def output_medium(path: str) -> str | None:
    """The medium an output name asks for: can, mcap, or None for our line formats (serial or zenoh, by input)."""
    lowered = path.lower()
    if lowered.endswith(MCAP_EXTENSION):
        return "mcap"
    return "can" if lowered.endswith(CAN_EXTENSIONS) else None


def _medium_of(record: Record) -> str:
    if record.framing == CAN_FRAMING:
        return "can"
    if record.framing == MESSAGE_FRAMING:
        return "mcap"
    return "zenoh" if record.framing == ZenohFraming.name else "serial"


def convert(paths: Sequence[str], output: str, *, damage: Damage = STRICT, id_base: int | None = None,
            extended: bool = False, keep: Filter | None = None,
            deployment: str | None = None) -> tuple[int, Counters]:
    """Write the records of `paths` (merged by time) that `keep` passes into `output`.

    Returns (units written, messages dropped while decoding); damage in a file goes to `damage`
    (raised, or counted and skipped). A record the output's
    format cannot hold (a serial chunk into a CAN log) is a CaptureError naming both files.
    """
    decoder = Decoder(default_framings(id_base, extended, deployment))
    passing = RecordFilter(keep or Filter(), decoder)
    sources = [((record, path) for record in read_capture(path, damage)) for path in paths]
    merged = heapq.merge(*sources, key=lambda pair: pair[0].t)
    first = next(merged, None)
    wanted = output_medium(output)
    medium = wanted or (_medium_of(first[0]) if first is not None else "serial")
    if wanted is None and medium in ("can", "mcap"):  # our line formats hold serial chunks and zenoh samples
        named = f"{' '.join(CAN_EXTENSIONS)} or {MCAP_EXTENSION}" if medium == "can" else MCAP_EXTENSION
        raise CaptureError(output, None, f"{_MEDIUM_NAMES[medium]} go into a capture named by extension: {named}")
    records = itertools.chain([first] if first is not None else [], merged)
    writing = Decoder(default_framings(id_base, extended, deployment))  # an .mcap writer's own: framings keep state
    with _written_in_place_of(output) as partial:
        capture = RotatingCapture(partial, medium, decoder=writing)
        try:
            for record, path in records:
                if medium != "mcap" and _medium_of(record) != medium:
                    raise CaptureError(path, None, f"link {record.link} holds {_MEDIUM_NAMES[_medium_of(record)]}: "
                                       f"{output} can hold only {_MEDIUM_NAMES[medium]} (write a {MCAP_EXTENSION} "
                                       "file to join them)")
                for kept in passing.units(record) if keep else (record,):
                    capture.write(kept)
        except CaptureError as error:
            raise (CaptureError(output, error.line, error.problem) if error.path == partial else error) from None
        finally:
            capture.close()
    return capture.records, (writing if medium == "mcap" else decoder).drops()


@contextlib.contextmanager
def _written_in_place_of(output: str) -> Iterator[str]:
    """A new file's name beside `output` (same extension), renamed to `output` if the body succeeds.

    A device or a link (-o /dev/stdout) is written through, as it is: renaming onto it would replace it.
    """
    if os.path.lexists(output) and (os.path.islink(output) or not os.path.isfile(output)):
        yield output
        return
    folder = os.path.dirname(os.path.abspath(output))
    descriptor, partial = tempfile.mkstemp(prefix=".vstig-convert-", suffix=capture_suffix(output), dir=folder)
    os.close(descriptor)
    os.chmod(partial, _mode_for(output))  # mkstemp's 0600 would hide the capture from the rest of the lab
    try:
        yield partial
        os.replace(partial, output)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.remove(partial)


def _mode_for(output: str) -> int:
    """The replaced file's permissions, or those a new file gets under the umask."""
    if os.path.isfile(output):
        return os.stat(output).st_mode & 0o7777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask
