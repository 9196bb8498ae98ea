"""What every link spec shares: `<scheme>:<body>[?key=value&...]`, as pyserial's URLs name a port.

The query after the last `?` is ours. A pyserial URL (`socket://h:7000`,
`rfc2217://...`) may carry its own options in the same query: keys we do not
know stay with the URL. A plain device path has no options of its own, so an
unknown key there is a typo and an error.

A bad spec raises ValueError with one line naming the bad part and a valid
example; each medium's module passes its own example to these helpers.
"""

from __future__ import annotations

import re

__all__ = ["bad", "check_port", "flag", "integer", "safe_name", "split_query"]

_NAME_UNSAFE = re.compile(r"[^A-Za-z0-9._:-]+")


def safe_name(text: str) -> str:
    """A short, space-free name for status lines and captures."""
    return _NAME_UNSAFE.sub("_", text).strip("_") or "link"


def bad(spec: str, problem: str, example: str) -> ValueError:
    return ValueError(f"bad link spec {spec!r}: {problem} (e.g. {example})")


def split_query(spec: str, body: str, example: str, ours: tuple[str, ...], is_url: bool,
                open_prefix: str | None = None) -> tuple[str, dict[str, str]]:
    """Split `body` at its last '?' into (rest, our params); foreign keys stay on a URL.

    Keys starting with `open_prefix` are ours too, whatever follows it (passed on as they are).
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
        elif is_url and item:
            foreign.append(item)
        else:
            raise bad(spec, f"unknown parameter {item!r} (known: {', '.join(ours) or 'none'})", example)
    if foreign:
        rest = f"{rest}?{'&'.join(foreign)}"
    return rest, params


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
