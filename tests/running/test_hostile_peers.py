"""``harness run --executor tcp://HOST:PORT`` where the peer is not a Dask scheduler: garbage, an HTTP server, a
listener that says nothing, one that closes at once, one whose first 8 bytes claim 2^60 bytes. Each is one line
naming ``--executor`` and the address, exit code 2, within the connection's timeout; SIGTERM while the harness
waits for a silent peer ends the run at once with the usual interrupted line and exit code 143."""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import pytest

from harness.cli import main
from harness.core.errors import HarnessError
from harness.running import executors

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT = 0.5  # seconds: the connection's timeout in these tests (CONNECT_TIMEOUT, 10 s, otherwise)


def _dask_message(message) -> bytes:
    """``message`` framed as Dask writes it on TCP: total length, frame count, frame length, msgpack."""
    frame = msgpack.packb(message)
    body = struct.pack("=QQ", 1, len(frame)) + frame
    return struct.pack("=Q", len(body)) + body


HANDSHAKE = _dask_message({"compression": None, "python": (3, 11, 7), "pickle-protocol": 5})


class Peer:
    """A listener on 127.0.0.1 that treats each connection as ``behaviour`` says, in a thread; connections it
    keeps open are closed after ``hold`` seconds (so that a harness without a timeout would not wait forever)."""

    def __init__(self, behaviour: str, hold: float = 5.0):
        self.behaviour, self.hold = behaviour, hold
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.accepted = threading.Event()
        self.connections = 0
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        kept = []
        self.server.settimeout(0.05)
        end = None
        while end is None or time.monotonic() < end:
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                continue
            except OSError:  # closed by the test
                break
            self.connections += 1
            self.accepted.set()
            end = end or time.monotonic() + self.hold
            if self._answer(conn):
                kept.append(conn)
            else:
                conn.close()
        for conn in kept:
            conn.close()

    def _answer(self, conn: socket.socket) -> bool:
        """Answer one connection; True to keep it open (until ``hold`` runs out)."""
        kind = self.behaviour
        if kind == "garbage":
            conn.sendall(b"\xde\xad\xbe\xef" * 16)
        elif kind == "http":
            conn.recv(4096)
            conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
            return False
        elif kind == "close":
            return False
        elif kind == "huge":  # a frame header claiming 2^60 bytes
            conn.sendall(struct.pack("=Q", 2**60) + b"\0" * 8)
        elif kind == "frames":  # a message whose frames do not add up to its length
            conn.sendall(struct.pack("=QQQ", 16, 1, 1000))
        elif kind == "not-handshake":  # well framed msgpack, but a list, not Dask's handshake
            conn.sendall(_dask_message([1, 2, 3]))
        elif kind == "handshake-once":  # a handshake to the first connection only: Dask's own then hangs
            if self.connections == 1:
                conn.sendall(HANDSHAKE)
        return True  # silent (and the rest): kept open, saying nothing more

    def close(self) -> None:
        self.server.close()
        self.thread.join(10)


@pytest.fixture
def peer():
    peers = []

    def start(behaviour: str, hold: float = 5.0) -> Peer:
        peers.append(Peer(behaviour, hold))
        return peers[-1]

    yield start
    for p in peers:
        p.close()


def _suite(tmp_path: Path) -> Path:
    path = tmp_path / "peers.toml"
    path.write_text(f'name = "peers"\n[[cases]]\nscene = "{ROOT / "scenes" / "furnace.toml"}"\nspp = 4\n'
                    'film = { width = 8, height = 8 }\n')
    return path


# raising=False: the test also runs (and fails, as it should) against a harness without the constant
@pytest.mark.parametrize("behaviour, says", [
    ("garbage", "answered b'\\xde\\xad\\xbe\\xef"),
    ("http", "answered b'HTTP/1.1 400 Bad Request"),
    ("silent", "sent nothing within 0.5 s"),
    ("close", "closed the connection"),
    ("huge", f"claim a message of {2**60} bytes"),
    ("frames", "whose frame lengths add up to 1016"),
    ("not-handshake", "answered msgpack (list), not a handshake"),
])
def test_a_peer_that_is_not_a_dask_scheduler_is_one_line(tmp_path, capsys, monkeypatch, peer, behaviour, says):
    monkeypatch.setattr(executors, "CONNECT_TIMEOUT", TIMEOUT, raising=False)
    listener = peer(behaviour)
    out = tmp_path / "out"
    start = time.monotonic()
    code = main(["run", str(_suite(tmp_path)), "--out", str(out), "--no-report", "--quiet",
                 "--executor", listener.address])
    elapsed = time.monotonic() - start
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert len(err) == 1 and err[0].startswith(f"harness: error: --executor: {listener.address} "), err
    assert says in err[0] and err[0].endswith("expected a Dask scheduler's handshake"), err
    assert elapsed < TIMEOUT + 2.0  # the run's own start (loading the suite) is well under the margin
    assert not out.exists()  # the folder made for the run is removed again


def test_a_refused_peer_writes_nothing_even_where_the_results_cache_answers(tmp_path, capsys, monkeypatch, peer):
    """Cases the results cache answers are written before any is handed to the executor: the peer is checked
    before that, so a run refused for its peer leaves no case files (and no folder) behind."""
    monkeypatch.setattr(executors, "CONNECT_TIMEOUT", TIMEOUT, raising=False)
    monkeypatch.setenv("HARNESS_RESULTS_CACHE", "on")
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "cache"))
    suite = _suite(tmp_path)
    assert main(["run", str(suite), "--out", str(tmp_path / "first"), "--no-report", "--quiet",
                 "--executor", "serial"]) == 0  # fills the results cache
    out = tmp_path / "out"
    code = main(["run", str(suite), "--out", str(out), "--no-report", "--quiet", "--executor",
                 peer("garbage").address])
    assert code == 2, capsys.readouterr().err
    assert not out.exists()


def test_the_handshake_check_passes_dask_and_reads_at_most_its_limit(peer):
    """A peer that answers Dask's handshake passes; one that streams a claimed 2^60 bytes is refused on the 8 bytes
    of its header (nothing allocated, nothing more read)."""
    executors.check_scheduler(peer("handshake-once").address, TIMEOUT)
    with pytest.raises(HarnessError, match="claim a message of 1152921504606846976 bytes"):
        executors.check_scheduler(peer("huge").address, TIMEOUT)


@pytest.mark.slow  # imports Dask
def test_a_peer_that_answers_the_check_then_hangs_dask_is_bounded_too(tmp_path, capsys, monkeypatch, peer):
    """A peer that answers the check's connection and then withholds the handshake from Dask's (which Dask would
    wait for without limit) is one line within the timeout as well."""
    monkeypatch.setattr(executors, "CONNECT_TIMEOUT", TIMEOUT)
    listener = peer("handshake-once")
    start = time.monotonic()
    code = main(["run", str(_suite(tmp_path)), "--out", str(tmp_path / "out"), "--no-report", "--quiet",
                 "--executor", listener.address])
    elapsed = time.monotonic() - start
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == [f"harness: error: --executor: cannot reach the Dask scheduler {listener.address}: "
                                 f"it answered the handshake but Dask did not connect within 0.5 s"], err
    assert listener.connections == 2 and elapsed < 2 * TIMEOUT + 5.0  # Dask's import is in there


@pytest.mark.slow  # starts a harness process
def test_sigterm_while_waiting_for_a_silent_peer_stops_the_run_at_once(tmp_path, peer):
    listener = peer("silent", hold=60.0)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "harness", "run", str(_suite(tmp_path)), "--out",
                             str(tmp_path / "out"), "--no-report", "--quiet", "--executor", listener.address],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert listener.accepted.wait(60), "the harness never connected"
        time.sleep(0.2)  # into the wait for the handshake (10 s by default)
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
        elapsed = time.monotonic() - sent
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 143, err
    assert err.strip().splitlines() == ["harness: interrupted after 0 of 1 cases; run again to resume"], err
    assert elapsed < 3.0, elapsed
