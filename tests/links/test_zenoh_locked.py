"""The locked deployments, through the Zenoh config file, with certificates made here.

Mutual TLS (every gateway's certificate signed by the lab CA), or TLS plus
user/password. Two lab gateways exchange batches; an intruder (a certificate
from another CA, or a wrong password) can neither read (its sniffer hears
nothing while a lab member's sniffer hears the lab) nor inject (its put never
reaches the lab, and it is told so in one line).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from certs import Authority, mtls_config, password_config
from ports import free_port

from vstig_hw.links import parse
from vstig_hw.wire import Message, Op

VSTIG = str(Path(sys.executable).with_name("vstig"))
pytestmark = pytest.mark.slow


def _configs(folder: Path, deployment: str) -> dict[str, Path]:
    lab = Authority(folder, "lab-ca")
    users = folder / "users.txt"
    users.write_text("gw-a:pw-a\ngw-b:pw-b\ngw-c:pw-c\n")
    if deployment == "mtls":
        texts = {name: mtls_config(lab, name) for name in ("gw-a", "gw-b", "gw-c")}
        texts["intruder"] = mtls_config(Authority(folder, "other-ca"), "intruder")  # a certificate the lab never signed
    else:
        texts = {name: password_config(lab, name, f"pw-{name[-1]}", users) for name in ("gw-a", "gw-b", "gw-c")}
        texts["intruder"] = password_config(lab, "gw-b", "a-guess", users)  # trusts the lab CA, guesses a password
    configs = {}
    for name, text in texts.items():
        configs[name] = folder / f"{name}.json5"
        configs[name].write_text(text)
    return configs


@pytest.mark.parametrize("deployment", ["mtls", "tls+password"])
def test_only_gateways_with_the_labs_credentials_join(tmp_path: Path, deployment: str) -> None:
    configs = _configs(tmp_path, deployment)
    port = free_port()
    listener = parse(f"zenoh:lab?listen=tls/localhost:{port}&config={configs['gw-a']}").build(robot_id=1)
    member = parse(f"zenoh:lab?connect=tls/localhost:{port}&config={configs['gw-b']}").build(robot_id=2)
    intruder = f"zenoh:lab?connect=tls/localhost:{port}&config={configs['intruder']}"
    listener.open()
    member.open()
    sniffer = subprocess.Popen([VSTIG, "sniff", intruder, "--jsonl", "--for", "6"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    colleague = subprocess.Popen([VSTIG, "sniff", intruder.replace("intruder", "gw-c"), "--jsonl", "--for", "6"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        heard = []
        end = time.monotonic() + 20
        while not heard and time.monotonic() < end:
            listener.send(Message(Op.PUT, 1, 42, 1, 1))
            heard = member.receive(0.3)
        assert heard and heard[0].message == Message(Op.PUT, 1, 42, 1, 1)  # the lab works

        end = time.monotonic() + 7
        while sniffer.poll() is None and time.monotonic() < end:
            listener.send(Message(Op.PUT, 1, 42, 1, 1))  # the lab keeps talking while the intruder listens
            time.sleep(0.2)
        out, err = sniffer.communicate(timeout=20)
        assert out == ""  # it read nothing
        rows = [json.loads(line) for line in colleague.communicate(timeout=20)[0].splitlines()]
        assert rows and rows[0]["value"] == 42 and rows[0]["sender"] == 1  # where a lab member reads it all
        assert "zenoh-lab: reached nobody at connect=tls/" in err and "Traceback" not in err

        put = subprocess.run([VSTIG, "put", "9", "666", "--learn", "0", "--wait", "2", "--on",
                              intruder.replace("zenoh:lab?", "zenoh:lab?mode=client&")],
                             capture_output=True, text=True, timeout=60, check=False)
        assert put.returncode == 1
        lines = put.stderr.splitlines()
        assert lines[0].startswith("zenoh-lab: no Zenoh router reachable")  # why, in one line
        assert lines[-1].startswith("Error: key 9: no neighbour on zenoh-lab took our write")
        assert "Traceback" not in put.stderr
        late = [h for _ in range(5) for h in member.receive(0.2)]
        assert all(h.message.key != 9 for h in late)  # it injected nothing
    finally:
        for process in (sniffer, colleague):
            if process.poll() is None:
                process.kill()
        listener.close()
        member.close()
