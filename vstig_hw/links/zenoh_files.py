"""The files a zenoh: link reads or makes: its Zenoh config file, the files that config names, its unix sockets.

Each is read as every file vstig reads at an edge (`vstig_hw.inputs`): a regular file (a FIFO cannot hold the
command, /dev/zero is refused before a byte is read), bounded in size, every error naming the file and, where
there is one, the line.

Zenoh parses JSON5 recursively with no depth limit: a config nested 100,000 deep crashed the process
(SIGSEGV). `outline` reads the text first, without recursion, so nesting is bounded before Zenoh sees it; it also
keeps the line of every key, so errors name it and the link knows which keys the file sets itself.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Iterator

from ..inputs import InputFileError, read_regular

__all__ = ["CONFIG_MAX_BYTES", "MAX_DEPTH", "NAMED_FILES", "ConfigFile", "TooDeep", "check_listen_path",
           "outline", "read_config", "read_named", "users_in"]

CONFIG_MAX_BYTES = 1 << 20  # a Zenoh config is a few kB; a config file with certificates inline, still far below
NAMED_MAX_BYTES = 1 << 20  # a certificate, key, or user/password dictionary a config names
MAX_DEPTH = 32  # objects and arrays inside each other: Zenoh's own configs use 7; 100,000 crashed its parser

# The config keys that name a file Zenoh reads (Zenoh 1.10: transport/link/tls, transport/auth), and what it holds.
NAMED_FILES = {
    "transport/link/tls/root_ca_certificate": "the TLS root CA certificate",
    "transport/link/tls/listen_private_key": "the TLS listening key",
    "transport/link/tls/listen_certificate": "the TLS listening certificate",
    "transport/link/tls/connect_private_key": "the TLS connecting key",
    "transport/link/tls/connect_certificate": "the TLS connecting certificate",
    "transport/auth/usrpwd/dictionary_file": "the user/password dictionary",
    "transport/auth/pubkey/public_key_file": "the public key",
    "transport/auth/pubkey/private_key_file": "the private key",
    "transport/auth/pubkey/known_keys_file": "the known keys",
}

_ESCAPE = re.compile(r"\\(?:u([0-9a-fA-F]{4})|x([0-9a-fA-F]{2})|(\r\n|[\s\S]))")
_SIMPLE = {"b": "\b", "f": "\f", "n": "\n", "r": "\r", "t": "\t", "v": "\v", "0": "\0"}
_DELIMITERS = frozenset("{}[]:,\"'/")


class TooDeep(ValueError):
    """JSON5 nested deeper than MAX_DEPTH; `line` is where the level beyond begins."""

    def __init__(self, line: int) -> None:
        super().__init__(f"line {line}: nested deeper than {MAX_DEPTH} levels")
        self.line = line


class ConfigFile:
    """A Zenoh config file read under the file rules: its text, and the line of every key it sets."""

    def __init__(self, path: str, text: str, keys: dict[str, int]) -> None:
        self.path, self.text, self.keys = path, text, keys

    def where(self, key: str) -> str:
        """`path:line` of `key` (a/b/c) in the file, or the path alone if the file does not set it."""
        line = self.keys.get(key)
        return self.path if line is None else f"{self.path}:{line}"

    def line_of_field(self, message: str) -> str:
        """`:N` for the first key named in a Zenoh error (`unknown field \\`x\\``...), or ''."""
        for name in re.findall(r"`([^`]+)`", message):
            for key, line in self.keys.items():
                if key.rsplit("/", 1)[-1] == name:
                    return f":{line}"
        return ""


def _unescape(raw: str) -> str:
    def one(match: re.Match[str]) -> str:
        code = match.group(1) or match.group(2)
        if code:
            return chr(int(code, 16))
        char = match.group(3)
        return "" if char in ("\n", "\r\n", "\r", "\u2028", "\u2029") else _SIMPLE.get(char, char)

    return _ESCAPE.sub(one, raw)


def _tokens(text: str) -> Iterator[tuple[str, str, int]]:
    """(kind, value, line) of each JSON5 token that matters to the outline: punctuation, strings, bare words."""
    i, n, line = 0, len(text), 1
    while i < n:
        char = text[i]
        if char == "\n":
            line += 1
            i += 1
        elif char.isspace() or char == "\ufeff":
            i += 1
        elif text.startswith("//", i):
            end = text.find("\n", i)
            i = n if end < 0 else end
        elif text.startswith("/*", i):
            end = text.find("*/", i + 2)
            end = n if end < 0 else end + 2
            line += text.count("\n", i, end)
            i = end
        elif char in "\"'":
            j = i + 1
            while j < n and text[j] != char:
                j += 2 if text[j] == "\\" else 1
            yield "string", _unescape(text[i + 1:j]), line
            line += text.count("\n", i, j)
            i = j + 1
        elif char in "{}[]:,":
            yield char, char, line
            i += 1
        else:
            j = i + 1
            while j < n and text[j] not in _DELIMITERS and not text[j].isspace():
                j += 1
            yield "word", text[i:j], line
            i = j


def _join(path: str, key: str) -> str:
    return f"{path}/{key}" if path else key


def outline(text: str) -> dict[str, int]:
    """The line of every key JSON5 `text` sets in objects (as a/b/c; keys inside arrays are not config keys).

    TooDeep if objects and arrays nest deeper than MAX_DEPTH. Not a validator: what is not JSON5 is Zenoh's
    to report.
    """
    keys: dict[str, int] = {}
    stack: list[str | None] = []  # per open object its key path, None for an array or what is inside one
    last: tuple[str, int] | None = None  # the string or bare word just read: a key if a ':' follows
    key: str | None = None  # the key whose value comes next
    for kind, value, line in _tokens(text):
        if kind in ("{", "["):
            if len(stack) >= MAX_DEPTH:
                raise TooDeep(line)
            parent = stack[-1] if stack else ""
            if not stack:
                stack.append(None if kind == "[" else "")  # the file's top level
            elif kind == "[" or parent is None or key is None:
                stack.append(None)  # an array, or an object inside one
            else:
                stack.append(_join(parent, key))
            key = last = None
        elif kind in ("}", "]"):
            if stack:
                stack.pop()
            key = last = None
        elif kind == ":":
            if stack and stack[-1] is not None and last is not None:
                key = last[0]
                keys.setdefault(_join(stack[-1], key), last[1])
            last = None
        elif kind == ",":
            key = last = None
        else:
            last = (value, line)
    return keys


def read_config(path: str) -> ConfigFile:
    """The Zenoh config file at `path`, read under the file rules and outlined; InputFileError naming it."""
    what = "the Zenoh config file"
    if path.lower().endswith((".yaml", ".yml")):
        raise InputFileError(f"{path}: {what} must be JSON5 (Zenoh's own format, .json5 or .json), not YAML")
    data = read_regular(path, CONFIG_MAX_BYTES, what)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise InputFileError(f"{path}:{line}: {what} is not UTF-8 text") from None
    try:
        keys = outline(text)
    except TooDeep as error:
        raise InputFileError(f"{path}:{error.line}: {what} nests objects and arrays deeper than {MAX_DEPTH} levels "
                             "(Zenoh's parser would crash)") from None
    return ConfigFile(path, text, keys)


def read_named(path: str, what: str) -> bytes:
    """A file a Zenoh config names (a key, a certificate, a dictionary), read under the file rules."""
    return read_regular(path, NAMED_MAX_BYTES, what)


def users_in(dictionary: str) -> int:
    """How many user:password lines a Zenoh user/password dictionary holds (Zenoh skips blank lines); 0 if it
    cannot be read."""
    try:
        text = read_named(dictionary, "the user/password dictionary").decode("utf-8", "replace")
    except InputFileError:
        return 0
    return sum(1 for line in text.splitlines() if line.strip())


def check_listen_path(path: str) -> None:
    """InputFileError unless a unix socket may be made at `path`: nothing there, or a socket (a stale one that
    Zenoh replaces). Zenoh removes whatever is at the path first, so a file or link there would be lost."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as error:
        raise InputFileError(f"{path}: cannot listen there: {error.strerror}") from None
    if not stat.S_ISSOCK(mode):
        kind = "a symbolic link" if stat.S_ISLNK(mode) else "a folder" if stat.S_ISDIR(mode) else "a file"
        raise InputFileError(f"{path} exists and is {kind}, not a socket: Zenoh would replace it; name a new path")
