"""Open pages in headless Chromium over the DevTools protocol and collect what a reader would see go wrong.

Light and real: Debian's `chromium`, started with a throwaway profile and a debugging port on loopback,
driven through one websocket (websocket-client). For each page: did it load (a missing file is
net::ERR_FILE_NOT_FOUND), which console errors, uncaught exceptions and failed resource loads did it log,
and what does the DOM say (a JavaScript expression evaluated once it loaded).
"""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import websocket


def chromium_path() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass
class Visit:
    url: str
    load_error: str | None = None
    errors: list[str] = field(default_factory=list)
    value: Any = None


class Browser:
    def __init__(self, profile: Path, timeout: float = 30.0) -> None:
        chromium = chromium_path()
        if chromium is None:
            raise FileNotFoundError("chromium is not installed (Debian package chromium; tests/sysdeps.sh)")
        self.timeout = timeout
        self.process = subprocess.Popen(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-extensions",
             "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0", "--remote-allow-origins=*",
             f"--user-data-dir={profile}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port = self._port(profile / "DevToolsActivePort")
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=timeout) as answer:
            targets = json.load(answer)
        page = next(t for t in targets if t["type"] == "page")
        self.socket = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=timeout)
        self.ids = itertools.count(1)
        self.events: list[dict[str, Any]] = []
        for method in ("Page.enable", "Runtime.enable", "Log.enable"):
            self.call(method)

    def _port(self, active_port: Path) -> int:
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"chromium exited with status {self.process.returncode} at start")
            if active_port.exists() and (lines := active_port.read_text().splitlines()):
                return int(lines[0])
            time.sleep(0.05)
        raise TimeoutError(f"chromium wrote no {active_port.name} within {self.timeout} s")

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        call_id = next(self.ids)
        self.socket.send(json.dumps({"id": call_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.socket.recv())
            if reply.get("id") == call_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                result: dict[str, Any] = reply.get("result", {})
                return result
            self.events.append(reply)

    def _wait_for(self, method: str) -> None:
        deadline = time.monotonic() + self.timeout
        while not any(e.get("method") == method for e in self.events):
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {method} within {self.timeout} s")
            self.events.append(json.loads(self.socket.recv()))

    def _drain(self, seconds: float) -> None:
        """Keep listening a moment after load: scripts that run late report here."""
        self.socket.settimeout(seconds)
        try:
            while True:
                self.events.append(json.loads(self.socket.recv()))
        except websocket.WebSocketTimeoutException:
            pass
        finally:
            self.socket.settimeout(self.timeout)

    def visit(self, url: str, expression: str = "document.title", settle: float = 1.0) -> Visit:
        self.events.clear()
        visit = Visit(url)
        navigated = self.call("Page.navigate", url=url)
        if navigated.get("errorText"):
            visit.load_error = navigated["errorText"]
            return visit
        self._wait_for("Page.loadEventFired")
        self._drain(settle)
        visit.errors = [text for event in self.events if (text := _error(event))]
        visit.value = self.call("Runtime.evaluate", expression=expression, returnByValue=True)["result"].get("value")
        return visit

    def close(self) -> None:
        self.socket.close()
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def _error(event: dict[str, Any]) -> str | None:
    method, params = event.get("method"), event.get("params", {})
    if method == "Runtime.exceptionThrown":
        details = params["exceptionDetails"]
        return f"uncaught: {details.get('exception', {}).get('description') or details.get('text')}"
    if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
        return "console.error: " + " ".join(str(a.get("value", a.get("description", ""))) for a in params["args"])
    if method == "Log.entryAdded" and params["entry"]["level"] == "error":
        entry = params["entry"]
        return f"{entry.get('source')}: {entry.get('text')} {entry.get('url', '')}".strip()
    return None
