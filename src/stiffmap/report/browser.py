"""Open a page in headless Chromium and collect what a person would see go wrong.

Used by the browser test and by ``stiffmap report --check``: the page is loaded
from a ``file://`` URL in a fresh profile, through the Chrome DevTools Protocol
(CDP), spoken with a small WebSocket client from the standard library (no
Selenium, no driver download). Collected: console messages, uncaught
exceptions, browser log entries (such as a failed resource load) and every
network request the page made, so a test can assert "no console error" and
"no request left the machine". An optional script runs in the page after it
is ready (to drive a selector), and a PNG screenshot can be taken.

The browser is Debian's ``chromium`` (``apt-get install chromium``), found on
``PATH`` or named by the ``STIFFMAP_CHROMIUM`` environment variable. It is
started with the flags this machine needs (no sandbox as root, no GPU, no
background networking in a closed network) and a new empty profile, and is
always stopped, even when a check fails.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import socket
import struct
import subprocess
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from ..io import atomic_write_bytes

__all__ = [
    "BrowserError",
    "ConsoleEntry",
    "PageCheck",
    "find_chromium",
    "check_page",
    "check_report",
    "CHROMIUM_FLAGS",
]

#: Flags for a headless run on a machine with no GPU and no network but the loopback.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--disable-dev-shm-usage",
    "--hide-scrollbars",
    "--mute-audio",
    # Software WebGL (SwiftShader), so that 3D plots render without a GPU.
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)

_LOCAL_SCHEMES = ("file:", "data:", "blob:", "about:", "chrome:", "devtools:")


class BrowserError(RuntimeError):
    """The browser could not be started or driven (not a problem of the page)."""


@dataclass(frozen=True)
class ConsoleEntry:
    """One message from the page or the browser log.

    Attributes
    ----------
    level : str
        ``error``, ``warning``, ``info``, ``log``, ``debug``, ``verbose``.
    text : str
    source : str
        ``console``, ``exception`` or the log source (``network``, ``javascript``, ...).
    url : str
        Where it came from, when known.
    """

    level: str
    text: str
    source: str
    url: str = ""


@dataclass(frozen=True)
class PageCheck:
    """What happened when a page was opened.

    Attributes
    ----------
    url : str
    ready : bool
        The page signalled it finished rendering (``window.stiffmapReady``), or
        loaded when it has no such signal.
    entries : tuple of ConsoleEntry
        Console messages, exceptions and log entries, in order.
    requests : tuple of str
        URL of every request the page made.
    result : Any
        JSON value returned by the script run after the page was ready (or None).
    screenshot : bytes or None
        PNG, when asked for.
    shots : tuple of bytes or None
        PNG of each element asked for (``elements``), whole even where taller than the
        window; None for a selector that matched nothing.
    """

    url: str
    ready: bool
    entries: tuple[ConsoleEntry, ...]
    requests: tuple[str, ...]
    result: Any = None
    screenshot: bytes | None = None
    shots: tuple[bytes | None, ...] = ()

    @property
    def errors(self) -> tuple[ConsoleEntry, ...]:
        """Console errors, uncaught exceptions and error log entries."""
        return tuple(e for e in self.entries if e.level == "error")

    @property
    def external_requests(self) -> tuple[str, ...]:
        """Requests that would leave the machine (anything but file:, data:, blob:, about:)."""
        return tuple(u for u in self.requests if not u.startswith(_LOCAL_SCHEMES))

    @property
    def ok(self) -> bool:
        """Rendered, with no console error and no request leaving the machine."""
        return self.ready and not self.errors and not self.external_requests

    def summary(self) -> dict:
        """``ready``, the ``errors`` (level, source, text) and the ``external_requests``, as JSON values."""
        return {
            "ready": self.ready,
            "errors": [{"level": e.level, "source": e.source, "text": e.text} for e in self.errors],
            "external_requests": list(self.external_requests),
        }


def find_chromium() -> str | None:
    """Path of a Chromium executable: ``$STIFFMAP_CHROMIUM`` or chromium on PATH, else None."""
    env = os.environ.get("STIFFMAP_CHROMIUM")
    if env:
        return env if Path(env).exists() else shutil.which(env)
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome"):
        p = shutil.which(name)
        if p:
            return p
    return None


# --------------------------------------------------------------------------- WebSocket (RFC 6455)
class _WebSocket:
    """Just enough of a WebSocket client for CDP on the loopback: text frames, ping, close."""

    def __init__(self, url: str, timeout: float) -> None:
        u = urlsplit(url)
        if u.scheme != "ws" or u.hostname not in ("127.0.0.1", "localhost", "::1"):
            raise BrowserError(f"refusing a DevTools address that is not on the loopback: {url}")
        self.sock = socket.create_connection((u.hostname, u.port or 80), timeout=timeout)
        self.buf = b""
        key = base64.b64encode(os.urandom(16)).decode()
        path = u.path + (f"?{u.query}" if u.query else "")
        req = (
            f"GET {path} HTTP/1.1\r\nHost: {u.hostname}:{u.port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        self.sock.sendall(req.encode())
        while b"\r\n\r\n" not in self.buf:
            self._fill()
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        status = head.split(b"\r\n", 1)[0]
        if b" 101 " not in status + b" ":
            raise BrowserError(f"DevTools refused the WebSocket upgrade: {status.decode(errors='replace')}")

    def _fill(self) -> None:
        chunk = self.sock.recv(1 << 20)
        if not chunk:
            raise BrowserError("the browser closed the DevTools connection")
        self.buf += chunk

    def _read(self, n: int) -> bytes:
        while len(self.buf) < n:
            self._fill()
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def _send_frame(self, opcode: int, payload: bytes) -> None:
        n = len(payload)
        head = bytes([0x80 | opcode])
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(head + mask + masked)

    def send(self, text: str) -> None:
        self._send_frame(0x1, text.encode())

    def recv(self) -> str:
        parts: list[bytes] = []
        while True:
            b0, b1 = self._read(2)
            fin, opcode, n = b0 & 0x80, b0 & 0x0F, b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack(">H", self._read(2))
            elif n == 127:
                (n,) = struct.unpack(">Q", self._read(8))
            mask = self._read(4) if b1 & 0x80 else None
            payload = self._read(n)
            if mask:
                payload = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
            if opcode == 0x9:  # ping
                self._send_frame(0xA, payload)
                continue
            if opcode == 0xA:  # pong
                continue
            if opcode == 0x8:
                raise BrowserError("the browser closed the DevTools connection")
            parts.append(payload)
            if fin:
                return b"".join(parts).decode("utf-8", errors="replace")

    def close(self) -> None:
        try:
            self._send_frame(0x8, b"")
        except OSError:
            pass
        self.sock.close()


class _CDP:
    """Commands and events of the DevTools protocol over one WebSocket."""

    def __init__(self, ws: _WebSocket, deadline: float) -> None:
        self.ws = ws
        self.deadline = deadline
        self.next_id = 0
        self.events: list[dict] = []

    def _recv(self) -> dict:
        if time.monotonic() > self.deadline:
            raise BrowserError("timed out waiting for the browser")
        try:
            return json.loads(self.ws.recv())
        except TimeoutError:
            raise BrowserError("timed out waiting for the browser") from None

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        self.next_id += 1
        msg: dict[str, Any] = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        self.ws.send(json.dumps(msg))
        while True:
            m = self._recv()
            if m.get("id") == self.next_id:
                if "error" in m:
                    raise BrowserError(f"{method}: {m['error'].get('message', m['error'])}")
                return m.get("result", {})
            if "method" in m:
                self.events.append(m)

    def wait_event(self, method: str) -> dict:
        for i, e in enumerate(self.events):
            if e["method"] == method:
                return self.events.pop(i)
        while True:
            m = self._recv()
            if m.get("method") == method:
                return m
            if "method" in m:
                self.events.append(m)

    def pump(self, seconds: float) -> None:
        """Collect events for a while (messages logged after the last command)."""
        end = min(time.monotonic() + seconds, self.deadline)
        old = self.ws.sock.gettimeout()
        try:
            while time.monotonic() < end:
                self.ws.sock.settimeout(max(end - time.monotonic(), 0.01))
                try:
                    m = json.loads(self.ws.recv())
                except TimeoutError:
                    break
                if "method" in m:
                    self.events.append(m)
        finally:
            self.ws.sock.settimeout(old)


def _remote_text(obj: dict) -> str:
    if "value" in obj:
        v = obj["value"]
        return v if isinstance(v, str) else json.dumps(v)
    return str(obj.get("description", obj.get("type", "")))


def _entries(events: list[dict]) -> tuple[list[ConsoleEntry], list[str]]:
    entries: list[ConsoleEntry] = []
    requests: list[str] = []
    for e in events:
        p = e.get("params", {})
        m = e["method"]
        if m == "Runtime.consoleAPICalled":
            level = {"warning": "warning", "error": "error", "assert": "error"}.get(
                p.get("type"), p.get("type")
            )
            text = " ".join(_remote_text(a) for a in p.get("args", []))
            frames = (p.get("stackTrace") or {}).get("callFrames") or [{}]
            entries.append(ConsoleEntry(level, text, "console", frames[0].get("url", "")))
        elif m == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            text = d.get("exception", {}).get("description") or d.get("text", "exception")
            entries.append(ConsoleEntry("error", text, "exception", d.get("url", "")))
        elif m == "Log.entryAdded":
            en = p.get("entry", {})
            entries.append(
                ConsoleEntry(
                    en.get("level", "info"), en.get("text", ""), en.get("source", "log"), en.get("url", "")
                )
            )
        elif m == "Network.requestWillBeSent":
            requests.append(p.get("request", {}).get("url", ""))
    return entries, requests


def check_page(
    path: str | os.PathLike,
    *,
    script: str | None = None,
    screenshot: bool = False,
    elements: Sequence[str] = (),
    width: int = 1280,
    height: int = 900,
    timeout: float = 60.0,
    settle: float = 0.5,
    chromium: str | None = None,
) -> PageCheck:
    """Open a local HTML file in headless Chromium and report what happened.

    Parameters
    ----------
    path : path-like
        The HTML file (opened as ``file://``).
    script : str, optional
        A JavaScript expression evaluated after the page is ready; a Promise is
        awaited. Its JSON value is :attr:`PageCheck.result`.
    screenshot : bool
        Take a PNG of the viewport (``width`` x ``height`` CSS px).
    elements : sequence of str
        CSS selectors: a PNG of each (the first element it matches), after the script
        (:attr:`PageCheck.shots`).
    timeout : float
        Seconds for the whole check.
    settle : float
        Seconds to keep listening after the last step, for late messages.
    chromium : str, optional
        Browser executable (default :func:`find_chromium`).

    Raises
    ------
    BrowserError
        No browser, or it could not be started or driven in time.
    """
    exe = chromium or find_chromium()
    if not exe:
        raise BrowserError("no Chromium found (apt-get install chromium, or set STIFFMAP_CHROMIUM)")
    url = Path(path).resolve().as_uri()
    deadline = time.monotonic() + timeout
    profile = tempfile.mkdtemp(prefix="stiffmap-chromium-")
    log = open(os.path.join(profile, "stderr.log"), "wb")  # noqa: SIM115 (closed below)
    proc = _start_chromium(exe, profile, width, height, log)
    ws = None
    try:
        ws = _WebSocket(_devtools_url(proc, exe, profile, deadline), timeout=timeout)
        cdp = _CDP(ws, deadline)
        sid = _open_page(cdp, url, width, height)
        ready = _wait_ready(cdp, sid, deadline)
        result = _run_script(cdp, sid, script) if script else None
        cdp.pump(settle)
        shot = None
        if screenshot:
            shot = base64.b64decode(
                cdp.call("Page.captureScreenshot", {"format": "png"}, session=sid)["data"]
            )
        shots = tuple(_element_png(cdp, sid, sel) for sel in elements)
        entries, requests = _entries(cdp.events)
        try:
            cdp.call("Browser.close")
        except (BrowserError, OSError):
            pass
        return PageCheck(url, ready, tuple(entries), tuple(requests), result, shot, shots)
    except OSError as e:
        raise BrowserError(f"talking to {exe}: {e}") from None
    finally:
        if ws is not None:
            ws.close()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        log.close()
        shutil.rmtree(profile, ignore_errors=True)


def _start_chromium(exe: str, profile: str, width: int, height: int, log) -> subprocess.Popen:
    """Headless Chromium on a blank page, its DevTools on a free local port, stderr to ``log``."""
    return subprocess.Popen(
        [
            exe,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={profile}",
            "--remote-debugging-port=0",
            "--remote-debugging-address=127.0.0.1",
            f"--window-size={width},{height}",
            "about:blank",
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=log,
    )


def _devtools_url(proc: subprocess.Popen, exe: str, profile: str, deadline: float) -> str:
    """The browser's DevTools WebSocket address, once it has written its port file."""
    port_file = Path(profile) / "DevToolsActivePort"
    while True:
        if proc.poll() is not None:
            tail = Path(profile, "stderr.log").read_bytes()[-2000:].decode(errors="replace")
            raise BrowserError(f"{exe} exited with status {proc.returncode}: {tail}")
        if port_file.exists():
            lines = port_file.read_text().split("\n")
            if len(lines) >= 2 and lines[0].strip().isdigit() and lines[1].strip():
                return f"ws://127.0.0.1:{lines[0].strip()}{lines[1].strip()}"
        if time.monotonic() > deadline:
            raise BrowserError(f"{exe} did not open its DevTools port in time")
        time.sleep(0.05)


def _open_page(cdp: _CDP, url: str, width: int, height: int) -> str:
    """Open ``url`` in a new target of ``width`` x ``height`` CSS px, wait for its load event;
    the session id."""
    target = cdp.call("Target.createTarget", {"url": "about:blank"})["targetId"]
    sid = cdp.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    for domain in ("Runtime", "Log", "Network", "Page"):
        cdp.call(f"{domain}.enable", session=sid)
    cdp.call(
        "Emulation.setDeviceMetricsOverride",
        {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
        session=sid,
    )
    cdp.call("Page.navigate", {"url": url}, session=sid)
    cdp.wait_event("Page.loadEventFired")
    return sid


def _wait_ready(cdp: _CDP, sid: str, deadline: float) -> bool:
    """Wait for the page's own "rendered" signal when it has one: whether it said so."""
    limit_ms = int(max(deadline - time.monotonic() - 2, 1) * 1000)
    wait = (
        "new Promise(r => { const t0 = Date.now(); (function f() {"
        " const s = window.stiffmapReady;"
        " if (s === true || (s === undefined && Date.now() - t0 > 200)) r(true);"
        " else if (s === false) r(false);"
        f" else if (Date.now() - t0 > {limit_ms}) r(false); else setTimeout(f, 50); }})(); }})"
    )
    return bool(
        cdp.call("Runtime.evaluate", {"expression": wait, "awaitPromise": True, "returnByValue": True}, sid)
        .get("result", {})
        .get("value", False)
    )


def _run_script(cdp: _CDP, sid: str, script: str):
    """The JSON value of ``script`` (a Promise awaited); an exception it throws goes to the
    console entries."""
    r = cdp.call(
        "Runtime.evaluate",
        {"expression": script, "awaitPromise": True, "returnByValue": True},
        session=sid,
    )
    if "exceptionDetails" in r:
        d = r["exceptionDetails"]
        text = d.get("exception", {}).get("description") or d.get("text", "exception")
        cdp.events.append(
            {"method": "Runtime.exceptionThrown", "params": {"exceptionDetails": {**d, "text": text}}}
        )
    return r.get("result", {}).get("value")


def _element_png(cdp: _CDP, sid: str, selector: str) -> bytes | None:
    """PNG of the first element matching ``selector`` (in page coordinates), None without one."""
    where = (
        f"(() => {{ const e = document.querySelector({json.dumps(selector)}); if (!e) return null;"
        " const r = e.getBoundingClientRect();"
        " return [r.left + scrollX, r.top + scrollY, r.width, r.height]; })()"
    )
    box = cdp.call("Runtime.evaluate", {"expression": where, "returnByValue": True}, sid)
    box = box.get("result", {}).get("value")
    if not box or box[2] < 1 or box[3] < 1:
        return None
    clip = dict(zip(("x", "y", "width", "height"), box, strict=True), scale=1)
    shot = cdp.call(
        "Page.captureScreenshot", {"format": "png", "clip": clip, "captureBeyondViewport": True}, sid
    )
    return base64.b64decode(shot["data"])


def check_report(
    index: str | os.PathLike,
    *,
    screenshot: str | os.PathLike | None = None,
    width: int = 1280,
    height: int = 1800,
) -> PageCheck:
    """:func:`check_page` of a report's ``index.html``; with ``screenshot``, save the PNG there.

    Raises
    ------
    BrowserError
        As :func:`check_page`.
    """
    pc = check_page(index, screenshot=screenshot is not None, width=width, height=height)
    if screenshot is not None:
        atomic_write_bytes(screenshot, pc.screenshot)
    return pc
