"""Images sent to a running tev (Thomas Müller's HDR image viewer, https://github.com/Tom94/tev) over its TCP
protocol, written here from the protocol's description (tev's own Python client is GPL-licensed; nothing of it is
used).

The protocol: a client connects to tev's IPC address (``127.0.0.1:14158`` unless tev was started with another
``--hostname``) and writes packets. A packet is its length in bytes (a little-endian uint32 that counts the whole
packet, these four bytes included), then a type byte, then the type's fields: integers little-endian, booleans one
byte, strings UTF-8 ended by a NUL byte, floats little-endian IEEE float32. tev answers nothing and keeps the
connection open until the client closes it, so a peer that sends bytes back or closes first is not tev
(:meth:`TevClient.confirm`); a quiet peer may be tev, and that is all a client can know. The types used here
(:class:`Packet`):

* ``OpenImage`` (7, tev's "OpenImageV2"): grab focus (bool), the image's path (tev reads the file itself, so only
  where tev runs on the same machine), a channel selector (string, empty for all);
* ``CreateImage`` (4): grab focus, name, width and height (int32), the number of channels (int32), their names;
  a black image of that size;
* ``UpdateImage`` (6, tev's "UpdateImageV3"): grab focus, name, the number of channels (int32), their names, the
  rectangle x, y, width, height (int32), per channel an offset and a stride (int64, in floats), then the floats:
  channel c of the rectangle's pixel i (row by row) is ``data[offset_c + i * stride_c]``;
* ``CloseImage`` (2): name.

:func:`send_image` creates an image and fills it with :data:`UPDATE_BYTES`-sized updates of whole rows (channels
interleaved: offset c, stride C), so that an image of any size goes in packets of bounded size.
"""

from __future__ import annotations

import enum
import socket
import struct
from collections.abc import Sequence

import numpy as np

from harness.core.text import short

__all__ = ["DEFAULT_ADDRESS", "NotTev", "Packet", "TevClient", "close_image", "create_image", "open_image",
           "send_image", "update_image"]

#: where tev listens unless told otherwise (its --hostname option's default)
DEFAULT_ADDRESS = ("127.0.0.1", 14158)
#: the largest float payload of one UpdateImage packet (whole rows; at least one row)
UPDATE_BYTES = 8 * 2**20
#: seconds :meth:`TevClient.confirm` waits for a peer that is not tev to answer or close the connection
REPLY_WAIT = 0.2


class Packet(enum.IntEnum):
    """The type byte of each packet this client writes."""

    CLOSE_IMAGE = 2
    CREATE_IMAGE = 4
    UPDATE_IMAGE = 6  # tev's UpdateImageV3
    OPEN_IMAGE = 7  # tev's OpenImageV2


def _string(text: str) -> bytes:
    data = str(text).encode("utf-8")
    if b"\0" in data:
        raise ValueError(f"tev strings end at a NUL byte: {text!r} holds one")
    return data + b"\0"


def _packet(kind: Packet, *fields: bytes) -> bytes:
    body = bytes([int(kind)]) + b"".join(fields)
    return struct.pack("<I", 4 + len(body)) + body


def open_image(path: str, *, grab_focus: bool = True, channel_selector: str = "") -> bytes:
    """An OpenImage packet: tev opens the file ``path`` itself."""
    return _packet(Packet.OPEN_IMAGE, struct.pack("<?", grab_focus), _string(path), _string(channel_selector))


def close_image(name: str) -> bytes:
    """A CloseImage packet."""
    return _packet(Packet.CLOSE_IMAGE, _string(name))


def create_image(name: str, width: int, height: int, channels: Sequence[str], *, grab_focus: bool = True) -> bytes:
    """A CreateImage packet: a black ``width`` x ``height`` image named ``name`` with ``channels``."""
    return _packet(Packet.CREATE_IMAGE, struct.pack("<?", grab_focus), _string(name),
                   struct.pack("<iii", int(width), int(height), len(channels)), *map(_string, channels))


def update_image(name: str, channels: Sequence[str], x: int, y: int, pixels: np.ndarray, *,
                 grab_focus: bool = False) -> bytes:
    """An UpdateImage packet: ``pixels`` (rows, columns, len(channels)) written at (x, y), channels interleaved
    (channel c's offset c, every channel's stride len(channels))."""
    data = np.ascontiguousarray(pixels, dtype="<f4")
    if data.ndim != 3 or data.shape[2] != len(channels):
        raise ValueError(f"pixels of shape (rows, columns, {len(channels)}) expected, got {data.shape}")
    count = len(channels)
    return _packet(Packet.UPDATE_IMAGE, struct.pack("<?", grab_focus), _string(name), struct.pack("<i", count),
                   *map(_string, channels), struct.pack("<iiii", int(x), int(y), data.shape[1], data.shape[0]),
                   struct.pack(f"<{count}q", *range(count)), struct.pack(f"<{count}q", *[count] * count),
                   data.tobytes())


class NotTev(OSError):
    """The peer sent bytes back or closed the connection: tev does neither."""


class TevClient:
    """A connection to a tev instance at ``address`` (host, port); :meth:`send` writes packets, :meth:`confirm`
    checks that the peer behaved as tev does. Opening it raises ``OSError`` where nothing listens there (within
    ``timeout`` seconds)."""

    def __init__(self, address: tuple[str, int] = DEFAULT_ADDRESS, timeout: float = 1.0):
        self.address = address
        self.socket = socket.create_connection(address, timeout=timeout)

    def send(self, packet: bytes) -> None:
        self.socket.sendall(packet)

    def confirm(self, wait: float = REPLY_WAIT) -> None:
        """Raise :class:`NotTev` where the peer, within ``wait`` seconds, sends anything (an HTTP server's "400 Bad
        Request") or closes the connection: tev does neither. Nothing more can be known: tev sends no
        acknowledgement."""
        self.socket.settimeout(wait)
        try:
            data = self.socket.recv(64)
        except TimeoutError:
            return  # quiet and open: as tev
        except OSError as err:
            raise NotTev(f"closed the connection ({err.strerror or err})") from None
        if not data:
            raise NotTev("closed the connection")
        raise NotTev(f"answered {short(data)}")

    def close(self) -> None:
        self.socket.close()

    def __enter__(self) -> TevClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def send_image(client: TevClient, name: str, image: np.ndarray, channels: Sequence[str], *,
               grab_focus: bool = True) -> int:
    """Create the image ``name`` in tev and fill it with ``image`` (H, W, len(channels)), in updates of whole rows
    of at most :data:`UPDATE_BYTES` of floats; returns the number of packets sent."""
    image = np.asarray(image, dtype=np.float32)
    height, width = image.shape[:2]
    client.send(create_image(name, width, height, channels, grab_focus=grab_focus))
    rows = max(1, UPDATE_BYTES // max(1, 4 * width * len(channels)))
    sent = 1
    for top in range(0, height, rows):
        client.send(update_image(name, channels, 0, top, image[top:top + rows]))
        sent += 1
    return sent
