"""``harness view --tev HOST:PORT`` where the peer is not tev: tev's protocol has no reply and tev keeps the
connection open, so a peer that answers (an HTTP server's 400) or closes the connection is not told "sent", and the
viewer page is written instead; a quiet peer that reads everything is (tev sends no acknowledgement)."""

from __future__ import annotations

import socket
import threading

import numpy as np
import pytest

from harness.cli import main
from harness.files import tev
from harness.files.imageio import write_exr


class Peer:
    """One connection on 127.0.0.1, treated as ``behaviour`` says: ``http`` reads a request's worth and answers
    400, ``close`` closes at once, ``hangup`` reads what came and closes, ``quiet`` reads until the client closes (as
    tev does)."""

    def __init__(self, behaviour: str):
        self.behaviour = behaviour
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.received = 0
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.server.settimeout(10)
        try:
            conn, _ = self.server.accept()
        except OSError:
            return
        with conn:
            if self.behaviour == "http":
                conn.recv(4096)
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
            elif self.behaviour == "hangup":
                conn.recv(4096)
            elif self.behaviour == "quiet":
                while chunk := conn.recv(1 << 16):
                    self.received += len(chunk)

    def close(self) -> None:
        self.thread.join(10)
        self.server.close()


@pytest.fixture
def peer():
    peers = []

    def start(behaviour: str) -> Peer:
        peers.append(Peer(behaviour))
        return peers[-1]

    yield start
    for p in peers:
        p.close()


@pytest.mark.parametrize("behaviour, says", [("http", "it answered b'HTTP/1.1 400 Bad Request"),
                                             ("close", "it closed the connection"),
                                             ("hangup", "it closed the connection")])
def test_confirm_refuses_a_peer_that_answers_or_closes(peer, behaviour, says):
    listener = peer(behaviour)
    with tev.TevClient(("127.0.0.1", listener.port)) as client:
        if behaviour != "close":
            client.send(tev.close_image("x"))  # what the HTTP server answers, what the other reads before closing
        with pytest.raises(tev.NotTev, match=says.removeprefix("it ")):
            client.confirm(wait=2.0)


def test_confirm_passes_a_quiet_peer(peer):
    listener = peer("quiet")
    with tev.TevClient(("127.0.0.1", listener.port)) as client:
        client.send(tev.close_image("x"))
        client.confirm(wait=0.05)  # nothing back, still open: as tev


@pytest.mark.slow  # writes the viewer page
@pytest.mark.parametrize("behaviour", ["http", "close", "hangup"])
def test_view_does_not_claim_tev_got_the_image_from_a_peer_that_is_not_tev(tmp_path, capsys, peer, behaviour):
    write_exr(tmp_path / "a.exr", np.full((6, 5, 3), 0.5, np.float32))
    listener = peer(behaviour)
    code = main(["view", str(tmp_path / "a.exr"), "--tev", f"127.0.0.1:{listener.port}",
                 "--out", str(tmp_path / "page")])
    out, err = capsys.readouterr()
    assert code == 0
    assert "sent" not in out and out.strip() == str(tmp_path / "page" / "index.html"), out
    assert (tmp_path / "page" / "index.html").is_file()  # the page instead
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("harness: "), lines
    assert f"127.0.0.1:{listener.port}" in lines[0] and "writing the page instead" in lines[0], lines


@pytest.mark.slow  # reads an EXR and talks to a listener
def test_view_says_what_is_known_to_a_quiet_peer(tmp_path, capsys, peer):
    write_exr(tmp_path / "a.exr", np.full((6, 5, 3), 0.5, np.float32))
    listener = peer("quiet")
    assert main(["view", str(tmp_path / "a.exr"), "--tev", f"127.0.0.1:{listener.port}"]) == 0
    listener.close()
    assert capsys.readouterr().out.strip() == f"sent {tmp_path / 'a.exr'} to 127.0.0.1:{listener.port} " \
                                              "(tev sends no acknowledgement)"
    assert listener.received > 6 * 5 * 3 * 4  # every pixel went
