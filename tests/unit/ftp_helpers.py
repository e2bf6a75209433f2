"""A scripted FTP client for the pure server core: builds request payloads, feeds them to
`FtpServer.handle` with a float `now`, and decodes what comes back."""

from __future__ import annotations

from gcsd.vehicle.ftp.fs import ConfinedFs
from gcsd.vehicle.ftp.protocol import Nak, Op, Payload
from gcsd.vehicle.ftp.server import FtpServer
from gcsd.vehicle.ftp.virtual import VirtualFiles


def make_server(root, max_file_bytes: int = 1 << 20, params=None) -> FtpServer:
    return FtpServer(ConfinedFs(root, max_file_bytes), VirtualFiles(params))


class Gcs:
    """One ground station: (sysid, compid) on a channel, with its own session number and seq."""

    def __init__(self, server: FtpServer, sysid: int = 255, compid: int = 190, channel: int = 0,
                 session: int = 1) -> None:
        self.server = server
        self.sysid, self.compid, self.channel, self.session = sysid, compid, channel, session
        self.seq = 0
        self.last_raw: bytes | None = None

    def request(self, opcode: int, data: bytes = b"", *, size: int | None = None, offset: int = 0,
                now: float = 0.0, seq: int | None = None, session: int | None = None) -> list[Payload]:
        if seq is None:
            seq, self.seq = self.seq, (self.seq + 1) % 65536
        payload = Payload(seq, self.session if session is None else session, opcode,
                          len(data) if size is None else size, 0, 0, offset, data)
        self.last_raw = payload.pack()
        return self._decode(self.server.handle(self.last_raw, (self.sysid, self.compid), self.channel, now))

    def resend(self, now: float = 0.0) -> list[Payload]:
        """The last request again, byte for byte (a client's retry)."""
        return self._decode(self.server.handle(self.last_raw, (self.sysid, self.compid), self.channel, now))

    def one(self, opcode: int, data: bytes = b"", **kw) -> Payload:
        replies = self.request(opcode, data, **kw)
        assert len(replies) == 1, replies
        return replies[0]

    def pump(self, now: float = 0.0, max_packets: int = 100_000) -> list[Payload]:
        """What the server sends from `now` on, the clock following its deadlines, until the
        running bursts and CRCs are done or max_packets are out."""
        out = []
        while len(out) < max_packets:
            out += self.server.pump(self.channel, now, max_packets - len(out))
            if not self.server.has_work(self.channel):
                break
            now = max(now, self.server.next_deadline(now, self.channel))
        return self._decode(out)

    def burst(self, offset: int = 0, block: int = 0, now: float = 0.0) -> list[Payload]:
        assert self.request(Op.BURST_READ_FILE, size=block, offset=offset, now=now) == []
        return self.pump(now)

    def download(self, block: int = 0, now: float = 0.0) -> bytes:
        """The open file, read with as many bursts as it takes (each packet placed at its offset)."""
        data = bytearray()
        offset = 0
        while True:
            packets = self.burst(offset=offset, block=block, now=now)
            for p in packets:
                if p.opcode == Op.ACK:
                    data[p.offset:p.offset + p.size] = p.data[:p.size]
                elif Nak(p.data[0]) == Nak.EOF:
                    return bytes(data)
                else:
                    raise AssertionError(f"burst failed: {p}")
            offset = len(data)

    def _decode(self, outgoing) -> list[Payload]:
        for out in outgoing:
            assert out.channel == self.channel and out.target == (self.sysid, self.compid), out
        return [Payload.unpack(out.payload) for out in outgoing]


def is_ack(p: Payload) -> bool:
    return p.opcode == Op.ACK


def nak_code(p: Payload) -> Nak | None:
    return Nak(p.data[0]) if p.opcode == Op.NAK else None


def errno_of(p: Payload) -> int | None:
    return p.data[1] if p.opcode == Op.NAK and p.data[0] == Nak.FAIL_ERRNO else None
