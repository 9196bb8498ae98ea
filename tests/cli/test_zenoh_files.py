"""The files a zenoh: link reads or makes, tried from a real `vstig` process: the config file and the files it
names follow the rules of every named input (regular file, bounded, nesting bounded, errors naming file and line),
and a unix socket listen path never replaces what is there."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest
from peers import run_vstig, start_vstig, stop, wait_for

FOR = ("--for", "1")


def _refused(spec: str) -> str:
    """The one line `vstig sniff SPEC` fails with (exit 1, quickly, no traceback)."""
    done = run_vstig("sniff", spec, *FOR, timeout=30)
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    return lines[0]


def test_a_config_that_is_a_device_or_a_fifo_is_refused_before_a_byte_is_read(tmp_path: Path) -> None:
    assert _refused("zenoh:lab?config=/dev/zero") == ("Error: cannot read the Zenoh config file: /dev/zero: the "
                                                     "Zenoh config file must be a regular file, not a device, pipe "
                                                     "or folder")
    fifo = tmp_path / "lab.json5"
    os.mkfifo(fifo)  # nobody writes it: opening it to read would wait forever
    assert _refused(f"zenoh:lab?config={fifo}").endswith(f"{fifo}: the Zenoh config file must be a regular file, "
                                                         "not a device, pipe or folder")


def test_a_deeply_nested_config_is_refused_naming_its_line_instead_of_crashing_zenohs_parser(tmp_path: Path) -> None:
    deep = tmp_path / "deep.json5"
    deep.write_text("{\n  metadata: " + "[" * 100_000 + "]" * 100_000 + "\n}\n")  # SIGSEGV (exit 139) in Zenoh
    assert _refused(f"zenoh:lab?config={deep}") == (f"Error: cannot read the Zenoh config file: {deep}:2: the Zenoh "
                                                    "config file nests objects and arrays deeper than 32 levels "
                                                    "(Zenoh's parser would crash)")


def test_a_config_that_is_too_large_not_utf8_or_not_json5_is_named_with_its_line(tmp_path: Path) -> None:
    large = tmp_path / "large.json5"
    large.write_text("{ metadata: '" + "x" * (1 << 20) + "' }")
    assert _refused(f"zenoh:lab?config={large}").endswith("the Zenoh config file is larger than the 1 MiB read at "
                                                          "most")
    latin = tmp_path / "latin.json5"
    latin.write_bytes(b"{\n  metadata: { name: '\xe9' }\n}\n")
    assert _refused(f"zenoh:lab?config={latin}").endswith(f"{latin}:2: the Zenoh config file is not UTF-8 text")
    broken = tmp_path / "broken.json5"
    broken.write_text("{\n  mode: 'peer',\n  connect: { endpoints: [ }\n}\n")
    assert _refused(f"zenoh:lab?config={broken}").startswith(f"Error: cannot read the Zenoh config file {broken}:3:")
    unknown = tmp_path / "unknown.json5"
    unknown.write_text("{\n  mode: 'peer',\n  transprot: {}\n}\n")
    assert _refused(f"zenoh:lab?config={unknown}").startswith(
        f"Error: cannot read the Zenoh config file {unknown}:3: unknown field `transprot`")
    yaml = tmp_path / "lab.yaml"
    yaml.write_text("mode: peer\n")
    assert _refused(f"zenoh:lab?config={yaml}").endswith("must be JSON5 (Zenoh's own format, .json5 or .json), not "
                                                         "YAML")


def test_every_file_the_config_names_follows_the_same_rules_and_is_named_with_the_configs_line(tmp_path: Path) -> None:
    config = tmp_path / "lab.json5"
    config.write_text("{\n  transport: {\n    link: {\n      tls: {\n        listen_private_key: '/dev/zero',\n"
                      "      },\n    },\n  },\n}\n")  # Zenoh read it until 2.3 GB
    assert _refused(f"zenoh:lab?config={config}") == (
        f"Error: {config}:5: transport/link/tls/listen_private_key: /dev/zero: the TLS listening key must be a "
        "regular file, not a device, pipe or folder")
    fifo = tmp_path / "users.txt"
    os.mkfifo(fifo)
    config.write_text(f"{{ transport: {{ auth: {{ usrpwd: {{ dictionary_file: '{fifo}' }} }} }} }}")
    assert _refused(f"zenoh:lab?config={config}").endswith(f"{fifo}: the user/password dictionary must be a regular "
                                                           "file, not a device, pipe or folder")
    assert _refused("zenoh:lab?listen=tls/127.0.0.1:7447#listen_private_key_file=/dev/zero") == (
        "Error: listen=tls/127.0.0.1:7447#listen_private_key_file=/dev/zero: /dev/zero: the listen_private_key_file "
        "of tls/127.0.0.1:7447 must be a regular file, not a device, pipe or folder")


@pytest.mark.parametrize("kind", ["file", "symbolic link"])
def test_a_unix_socket_listen_path_never_replaces_a_file_or_link_there(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "lab.sock"
    precious = tmp_path / "precious.txt"
    precious.write_text("robot logs\n")
    if kind == "file":
        path.write_text("robot logs\n")
    else:
        path.symlink_to(precious)
    line = _refused(f"zenoh:lab?listen=unixsock-stream/{path}")
    assert line == (f"Error: listen=unixsock-stream/{path}: {path} exists and is a {kind}, not a socket: Zenoh "
                    "would replace it; name a new path")
    assert path.is_symlink() == (kind == "symbolic link") and path.read_text() == "robot logs\n"  # untouched


def test_a_stale_socket_at_the_listen_path_is_replaced_as_zenoh_does(tmp_path: Path) -> None:
    path = tmp_path / "lab.sock"
    stale = socket.socket(socket.AF_UNIX)
    stale.bind(str(path))
    stale.close()  # a socket file left by a gateway that was killed
    sniffer = start_vstig("sniff", f"zenoh:lab?listen=unixsock-stream/{path}", "--jsonl")
    try:
        wait_for(lambda: _listening(path), 20)  # Zenoh's own socket, where the stale one was
    finally:
        _, err = stop(sniffer)
    assert "Traceback" not in err and "Error" not in err


def _listening(path: Path) -> bool:
    with socket.socket(socket.AF_UNIX) as probe:
        try:
            probe.connect(str(path))
        except OSError:
            return False
        return True
