"""When a zenoh gateway warns that it is open: a table of config shapes judged from the effective config, and the
auth shapes tried for real (a plain session's PUT is stored exactly where the warning is given)."""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import pytest
import zenoh
from ports import free_port

from vstig_hw.gateway import Node
from vstig_hw.links import parse
from vstig_hw.links.zenoh import exposure, zenoh_config
from vstig_hw.wire import Message, Op, encode

ANY = "tcp/0.0.0.0:7447"
OPEN = f"listens on {ANY}"


def _key_pair(folder: Path, stem: str) -> tuple[Path, Path]:
    """An RSA key pair in PKCS#1 PEM, the form Zenoh's public key authentication reads."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import rsa

    key = rsa.generate_private_key(public_exponent=65537, key_size=1024)
    public, private = folder / f"{stem}.pub.pem", folder / f"{stem}.key.pem"
    public.write_bytes(key.public_key().public_bytes(serialization.Encoding.PEM, serialization.PublicFormat.PKCS1))
    private.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.TraditionalOpenSSL,
                                          serialization.NoEncryption()))
    return public, private


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("auth")
    (folder / "users.txt").write_text("lab:secret\n")
    (folder / "empty.txt").write_text("")
    (folder / "blank.txt").write_text("\n  \n\n")
    (folder / "empty.pem").write_text("")
    public, _ = _key_pair(folder, "lab")
    (folder / "known.pem").write_bytes(public.read_bytes())
    return folder


AUTH = {  # transport/auth settings, and whether Zenoh then makes every session authenticate (Zenoh 1.10)
    "none": ("{}", False),
    "user-password": ("{ usrpwd: { user: 'lab', password: 'secret' } }", True),
    "dictionary": ("{ usrpwd: { dictionary_file: '{d}/users.txt' } }", True),
    "dictionary-empty": ("{ usrpwd: { dictionary_file: '{d}/empty.txt' } }", False),
    "dictionary-blank-lines": ("{ usrpwd: { dictionary_file: '{d}/blank.txt' } }", False),
    "known-keys-empty": ("{ pubkey: { known_keys_file: '{d}/empty.pem' } }", False),
    "known-keys-alone": ("{ pubkey: { known_keys_file: '{d}/known.pem' } }", False),  # Zenoh reads no such file
    "key-size-alone": ("{ pubkey: { key_size: 512 } }", False),
    "key-pair": ("{ pubkey: { public_key_file: '{d}/lab.pub.pem', private_key_file: '{d}/lab.key.pem' } }", True),
}


def _auth_file(files: Path, name: str) -> Path:
    file = files / f"{name}.json5"
    auth = AUTH[name][0].replace("{d}", str(files))
    file.write_text(f"{{ transport: {{ auth: {auth} }} }}")
    return file


@pytest.mark.parametrize("name", sorted(AUTH))
def test_each_auth_shape_beside_an_open_listener_is_judged_by_what_zenoh_does_with_it(files: Path, name: str) -> None:
    config = zenoh_config(parse(f"zenoh:lab?config={_auth_file(files, name)}&listen={ANY}"))
    assert exposure(config) == (None if AUTH[name][1] else OPEN)


LISTENERS = {  # listen=..., and whether only this PC can reach it
    "tcp/127.0.0.1:7447": True,
    "tcp/127.8.9.10:7447": True,
    "tcp/localhost:7447": True,
    "tcp/LOCALHOST:7447": True,
    "tcp/[::1]:7447": True,
    "tcp/[::ffff:127.0.0.1]:7447": True,
    "udp/127.0.0.1:7447": True,
    "ws/127.0.0.1:7448": True,
    "unixsock-stream//tmp/vstig-lab.sock": True,
    "vsock/VMADDR_CID_LOCAL:7447": True,
    "tcp/0.0.0.0:7447": False,
    "tcp/[::]:7447": False,
    "tcp/10.0.0.5:7447": False,
    "udp/0.0.0.0:7447": False,
    "ws/0.0.0.0:7448": False,
    "tcp/localhost.attacker.example:7447": False,  # a name is not judged by how it starts
    "tcp/127.0.0.1.attacker.example:7447": False,
    "tcp/127.attacker.example:7447": False,
    "tcp/lab-pc:7447": False,  # resolved by Zenoh, perhaps to the LAN: never resolved here
    "vsock/VMADDR_CID_ANY:7447": False,  # virtual machines on this PC
    "serial//dev/ttyUSB0": False,
}


@pytest.mark.parametrize("endpoint", list(LISTENERS))
def test_each_listener_is_local_only_if_only_this_pc_can_reach_it(endpoint: str) -> None:
    config = zenoh_config(parse(f"zenoh:lab?listen={endpoint}"))
    assert exposure(config) == (None if LISTENERS[endpoint] else f"listens on {endpoint}")


def test_a_listener_the_config_file_names_per_mode_and_mtls_and_scouting_are_judged_too(tmp_path: Path) -> None:
    def judged(text: str, query: str = "") -> str | None:
        file = tmp_path / "lab.json5"
        file.write_text(text)
        return exposure(zenoh_config(parse(f"zenoh:lab?config={file}{query}")))

    assert judged("{ listen: { endpoints: { peer: ['tcp/0.0.0.0:7447'], router: [] } } }") == OPEN
    assert judged("{ listen: { endpoints: { peer: ['tcp/127.0.0.1:7447'], router: ['tcp/0.0.0.0:7447'] } } }") is None
    mtls = "{ transport: { link: { tls: { enable_mtls: true } } } }"
    assert judged(mtls, "&listen=tls/0.0.0.0:7447") is None
    assert judged(mtls, "&listen=quic/0.0.0.0:7447") is None
    assert judged(mtls, f"&listen={ANY}") == OPEN  # mutual TLS covers TLS and QUIC links only
    assert judged(mtls, "&listen=tls/0.0.0.0:7447&scout=1") == "scouts the LAN by multicast"  # scouting is TCP too
    assert judged("{ transport: { link: { protocols: ['tls'], tls: { enable_mtls: true } } } }",
                  "&listen=tls/0.0.0.0:7447&scout=1") is None
    assert judged("{}", f"&listen={ANY}&scout=1") == f"{OPEN} and scouts the LAN by multicast"


def test_a_gateway_that_is_open_says_so_once_when_its_link_is_built(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        parse("zenoh:lab?listen=tcp/localhost.attacker.example:7447").build(robot_id=1)
    [line] = [r.getMessage() for r in caplog.records]
    assert line.startswith("zenoh-lab: WARNING: this gateway listens on tcp/localhost.attacker.example:7447 with "
                           "no authentication")


# -- the auth shapes for real: a plain session on loopback, with the gateway's settings there ------------------
def _plain_session_put_is_stored(config: Path) -> bool:
    """Whether a session with no credentials at all gets a PUT stored by a gateway with `config` on loopback."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    gateway = parse(f"zenoh:lab?config={config}&listen={endpoint}").build(robot_id=201)
    node = Node([gateway], 201)
    plain = zenoh.Config()
    plain.insert_json5("mode", '"client"')
    plain.insert_json5("connect/endpoints", json.dumps([endpoint]))
    with node:
        try:
            intruder = zenoh.open(plain)
        except zenoh.ZError as error:
            assert "Unable to connect" in str(error)  # refused during the handshake
            return False
        try:
            end = time.monotonic() + 5
            while time.monotonic() < end:
                intruder.put("vstig/lab/0/66", encode(Message(Op.PUT, 9, 42, 1, 66)))
                time.sleep(0.2)
                if node.get(9) == 42:
                    return True
            return False
        finally:
            intruder.close()  # type: ignore[no-untyped-call]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(AUTH))
def test_a_plain_session_is_stored_exactly_where_the_gateway_would_warn(files: Path, name: str) -> None:
    assert _plain_session_put_is_stored(_auth_file(files, name)) is not AUTH[name][1]


@pytest.mark.slow
def test_mutual_tls_on_a_tcp_listener_lets_a_plain_session_in(tmp_path: Path) -> None:
    file = tmp_path / "mtls.json5"
    file.write_text("{ transport: { link: { tls: { enable_mtls: true } } } }")
    assert exposure(zenoh_config(parse(f"zenoh:lab?config={file}&listen={ANY}"))) == OPEN
    assert _plain_session_put_is_stored(file)
