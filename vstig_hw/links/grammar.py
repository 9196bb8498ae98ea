"""What every link spec shares: `<scheme>:<body>[?key=value&...]`, as pyserial's URLs name a port.

The query after the last `?` is ours. A pyserial URL (`socket://h:7000`,
`rfc2217://...`) may carry its own options in the same query: the keys its
handler reads (`theirs`) stay with the URL. Any other key is a typo and an
error naming it, the known keys and the closest one, on every kind of link.

A bad spec raises ValueError with one line naming the bad part and a valid
example; each medium's module passes its own example to these helpers.
"""

from __future__ import annotations

import re
from difflib import get_close_matches
from urllib.parse import unquote_plus

from ..tagged import AuthPolicy

__all__ = ["AUTH_KEY", "bad", "check_port", "flag", "integer", "safe_name", "split_query", "take_auth", "unknown_key"]

AUTH_KEY = "auth"  # every kind's: auth=require|prefer|off (SPEC.md 10.6), taken off before the medium's parser

_NAME_UNSAFE = re.compile(r"[^A-Za-z0-9._:-]+")


def safe_name(text: str) -> str:
    """A short, space-free name for status lines and captures."""
    return _NAME_UNSAFE.sub("_", text).strip("_") or "link"


def bad(spec: str, problem: str, example: str) -> ValueError:
    return ValueError(f"bad link spec {spec!r}: {problem} (e.g. {example})")


def unknown_key(spec: str, item: str, example: str, ours: tuple[str, ...], theirs: tuple[str, ...] = (),
                whose: str = "") -> ValueError:
    """The error for a key nobody reads: `item` (key=value) named, the known keys listed (ours, then `whose`
    `theirs`: a pyserial URL's), the closest one suggested."""
    key = item.partition("=")[0]
    closest = get_close_matches(key, (*ours, *theirs), n=1, cutoff=0.6)
    hint = f"did you mean {closest[0]}? " if closest else ""
    also = f"; {whose} takes {', '.join(theirs)}" if theirs else ""
    return bad(spec, f"unknown parameter {item!r} ({hint}known: {', '.join(ours) or 'none'}{also})", example)


def split_query(spec: str, body: str, example: str, ours: tuple[str, ...], theirs: tuple[str, ...] = (),
                open_prefix: str | None = None, whose: str = "") -> tuple[str, dict[str, str]]:
    """Split `body` at its last '?' into (rest, our params); `theirs` (a pyserial URL's own keys) stay on the rest.

    Keys starting with `open_prefix` are ours too, whatever follows it (passed on as they are).
    `whose` names the owner of `theirs` in the error for an unknown key ("pyserial's loop://").
    """
    if "?" not in body:
        return body, {}
    rest, query = body.rsplit("?", 1)
    params: dict[str, str] = {}
    foreign: list[str] = []
    for item in query.split("&"):
        key, sep, value = item.partition("=")
        if key in ours or (open_prefix and key.startswith(open_prefix) and len(key) > len(open_prefix)):
            if not sep or not value:
                raise bad(spec, f"parameter {key!r} needs a value ({key}=...)", example)
            if key in params:
                raise bad(spec, f"parameter {key!r} given twice", example)
            params[key] = value
        elif not item:
            raise bad(spec, "an empty parameter (a stray '&' or '?')", example)
        elif unquote_plus(key) in theirs:  # read as the URL's handler reads it, percent-decoded
            foreign.append(item)
        else:
            known = (*ours, f"{open_prefix}KEY") if open_prefix else ours
            raise unknown_key(spec, item, example, (*known, AUTH_KEY), theirs, whose)
    if foreign:
        rest = f"{rest}{'&' if '?' in rest else '?'}{'&'.join(foreign)}"  # one query, as pyserial reads it
    return rest, params


def take_auth(spec: str, body: str, example: str) -> tuple[str, AuthPolicy | None]:
    """`body` without its `auth=` parameter, and the policy it names (None: not given); a bad or repeated one
    raises the one-line error naming it."""
    if "?" not in body:
        return body, None
    rest, query = body.rsplit("?", 1)
    items = query.split("&")
    given = [item.partition("=")[2] for item in items if item.partition("=")[0] == AUTH_KEY]
    if not given:
        return body, None
    if len(given) > 1:
        raise bad(spec, f"parameter {AUTH_KEY!r} given twice", example)
    try:
        policy = AuthPolicy.parse(given[0])
    except ValueError as error:
        raise bad(spec, str(error), example) from None
    kept = [item for item in items if item.partition("=")[0] != AUTH_KEY]
    return (f"{rest}?{'&'.join(kept)}" if kept else rest), policy


def integer(spec: str, example: str, key: str, text: str, low: int, high: int) -> int:
    try:
        number = int(text, 0)
    except ValueError:
        raise bad(spec, f"{key}={text!r} is not an integer", example) from None
    if not low <= number <= high:
        raise bad(spec, f"{key}={text} is outside {low}..{high:#x}" if key == "id_base"
                  else f"{key}={text} is outside {low}..{high}", example)
    return number


def flag(spec: str, example: str, key: str, text: str) -> bool:
    if text not in ("0", "1"):
        raise bad(spec, f"{key}={text!r} must be 0 or 1", example)
    return text == "1"


def check_port(spec: str, example: str, port: str) -> str:
    """A device path or pyserial URL: present, and free of control characters."""
    if not port or port.isspace():
        raise bad(spec, "the port is missing", example)
    if any(ch in port for ch in "\0\n\r"):
        raise bad(spec, "the port contains a control character", example)
    return port
