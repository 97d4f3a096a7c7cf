"""``harness view``: images sent to tev over its TCP protocol (checked by a fake tev that parses every packet), else
the viewer page written for them; bad input is one line and exit code 2."""

from __future__ import annotations

import socket
import struct
import threading
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from harness.files import tev
from harness.files.imageio import write_exr

pytestmark = pytest.mark.slow  # starts a server thread and writes pages


class FakeTev:
    """A tev stand-in on loopback: it accepts connections, reads every packet (uint32 length, type byte, fields)
    and keeps them parsed, as tev's protocol describes them (harness.files.tev)."""

    def __init__(self):
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.packets: list[dict] = []
        self.errors: list[str] = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        self.server.settimeout(10)
        try:
            connection, _ = self.server.accept()
        except OSError:
            return
        with connection:
            data = b""
            while chunk := connection.recv(1 << 16):
                data += chunk
        try:
            self._parse(data)
        except Exception as err:  # noqa: BLE001 - the test reports it
            self.errors.append(f"{type(err).__name__}: {err}")

    def _parse(self, data: bytes):
        at = 0
        while at < len(data):
            (length,) = struct.unpack_from("<I", data, at)
            assert length >= 5 and at + length <= len(data), f"packet length {length} at byte {at}"
            self.packets.append(_packet(data[at + 4:at + length]))
            at += length

    def close(self):
        self.thread.join(10)
        self.server.close()


def _packet(body: bytes) -> dict:
    kind, at = body[0], 1

    def string():
        nonlocal at
        end = body.index(b"\0", at)
        text = body[at:end].decode("utf-8")
        at = end + 1
        return text

    def ints(fmt):
        nonlocal at
        values = struct.unpack_from(fmt, body, at)
        at += struct.calcsize(fmt)
        return values

    if kind == tev.Packet.CREATE_IMAGE:
        (grab,) = ints("<?")
        name = string()
        width, height, count = ints("<iii")
        out = {"type": "create", "grab": grab, "name": name, "width": width, "height": height,
               "channels": [string() for _ in range(count)]}
    elif kind == tev.Packet.UPDATE_IMAGE:
        (grab,) = ints("<?")
        name = string()
        (count,) = ints("<i")
        channels = [string() for _ in range(count)]
        x, y, width, height = ints("<iiii")
        offsets, strides = ints(f"<{count}q"), ints(f"<{count}q")
        floats = np.frombuffer(body, "<f4", offset=at)
        at = len(body)
        pixels = np.stack([floats[o + np.arange(width * height) * s] for o, s in zip(offsets, strides)], axis=-1)
        out = {"type": "update", "grab": grab, "name": name, "channels": channels, "x": x, "y": y,
               "pixels": pixels.reshape(height, width, count)}
    elif kind == tev.Packet.OPEN_IMAGE:
        (grab,) = ints("<?")
        out = {"type": "open", "grab": grab, "path": string(), "selector": string()}
    elif kind == tev.Packet.CLOSE_IMAGE:
        out = {"type": "close", "name": string()}
    else:
        raise AssertionError(f"unknown packet type {kind}")
    assert at == len(body), f"{out['type']}: {len(body) - at} bytes left over"
    return out


def _images(tmp_path: Path):
    rng = np.random.default_rng(4)
    a = rng.random((21, 13, 3)).astype(np.float32)
    b = (a + 0.01 * rng.standard_normal(a.shape)).astype(np.float32)
    var = np.full(a.shape, 1e-4, np.float32)
    write_exr(tmp_path / "a.exr", a, var)
    write_exr(tmp_path / "b.exr", b)  # no variance channels
    return a, b, var


def _assembled(packets: list[dict], name: str) -> np.ndarray:
    create = next(p for p in packets if p["type"] == "create" and p["name"] == name)
    image = np.zeros((create["height"], create["width"], len(create["channels"])), np.float32)
    for p in packets:
        if p["type"] == "update" and p["name"] == name:
            assert p["channels"] == create["channels"]
            rows, cols = p["pixels"].shape[:2]
            image[p["y"]:p["y"] + rows, p["x"]:p["x"] + cols] = p["pixels"]
    return image


def test_the_images_go_to_a_listening_tev(tmp_path, capsys, monkeypatch):
    a, b, var = _images(tmp_path)
    monkeypatch.setattr(tev, "UPDATE_BYTES", 13 * 6 * 4 * 5)  # five rows a packet: the updates must add up
    fake = FakeTev()
    code = main(["view", str(tmp_path / "a.exr"), str(tmp_path / "b.exr"), "--tev", f"127.0.0.1:{fake.port}"])
    fake.close()
    assert code == 0 and not fake.errors, fake.errors
    assert capsys.readouterr().out.strip() == f"sent {tmp_path / 'a.exr'} and {tmp_path / 'b.exr'} to " \
                                              f"127.0.0.1:{fake.port} (tev sends no acknowledgement)"
    kinds = [p["type"] for p in fake.packets]
    assert kinds == ["create"] + ["update"] * 5 + ["create"] + ["update"] * 3
    first, second = (p for p in fake.packets if p["type"] == "create")
    assert first["channels"] == ["R", "G", "B", "variance.R", "variance.G", "variance.B"] and first["grab"]
    assert second["channels"] == ["R", "G", "B"] and not second["grab"]
    assert (first["width"], first["height"]) == (13, 21)
    assert np.array_equal(_assembled(fake.packets, str(tmp_path / "a.exr")), np.concatenate([a, var], axis=-1))
    assert np.array_equal(_assembled(fake.packets, str(tmp_path / "b.exr")), b)


def test_the_other_packets_are_what_tev_reads():
    fake = FakeTev()
    with tev.TevClient(("127.0.0.1", fake.port)) as client:
        client.send(tev.open_image("/some/dir/ü.exr", grab_focus=False, channel_selector="R,G,B"))
        client.send(tev.close_image("x"))
    fake.close()
    assert fake.packets == [{"type": "open", "grab": False, "path": "/some/dir/ü.exr", "selector": "R,G,B"},
                            {"type": "close", "name": "x"}]
    with pytest.raises(ValueError):
        tev.close_image("a\0b")


def _free_port() -> int:
    with socket.socket() as s:  # bound, then closed: nothing listens there
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_without_tev_the_viewer_page_is_written(tmp_path, capsys):
    _images(tmp_path)
    out = tmp_path / "page"
    code = main(["view", str(tmp_path / "a.exr"), str(tmp_path / "b.exr"), "--tev", f"127.0.0.1:{_free_port()}",
                 "--out", str(out)])
    assert code == 0
    assert capsys.readouterr().out.strip() == str(out / "index.html")
    page = (out / "index.html").read_text()
    assert 'data-viewer-src="view/viewer.js"' in page and "data-autoopen" in page
    assert "No verdict" in page and "b.exr has no variance channels" in page  # no tiles without both variances
    assert (out / "view" / "viewer.js").is_file() and (out / "view" / "thumbnail.png").is_file()
    # one image alone; the default folder is a new temporary one
    code = main(["view", str(tmp_path / "a.exr"), "--no-tev"])
    shown = Path(capsys.readouterr().out.strip())
    assert code == 0 and shown.name == "index.html" and shown.parent.name.startswith("harness-view-")
    assert (shown.parent / "view" / "viewer.js").is_file()


@pytest.mark.parametrize("argv, where", [
    (["view", "MISSING.exr"], "MISSING.exr: no such file"),
    (["view", "NOT.exr"], "NOT.exr: not an OpenEXR file"),
    (["view", "A.exr", "--tev", "localhost"], "--tev: expected HOST:PORT"),
    (["view", "A.exr", "--tev", "127.0.0.1:70000"], "--tev: expected HOST:PORT"),
    (["view", "A.exr", "SMALL.exr"], "SMALL.exr: size 4x4 differs from"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, where):
    _images(tmp_path)
    (tmp_path / "NOT.exr").write_text("not an image")
    write_exr(tmp_path / "SMALL.exr", np.zeros((4, 4, 3), np.float32))
    argv = [str(tmp_path / a) if a.endswith(".exr") and a != "A.exr" else
            (str(tmp_path / "a.exr") if a == "A.exr" else a) for a in argv]
    code = main(argv + ["--no-tev", "--out", str(tmp_path / "page")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and where in err and "Traceback" not in err
    assert not (tmp_path / "page").exists()  # nothing half-written


def test_host_port():
    from harness.core.options import host_port

    assert host_port("127.0.0.1:14158") == ("127.0.0.1", 14158)
    assert host_port("[::1]:9") == ("::1", 9) and host_port("tev.local:1") == ("tev.local", 1)
    for bad in ("", ":1", "h:0", "h:65536", "h", "h:1:2", "h :1"):
        with pytest.raises(Exception):
            host_port(bad)
