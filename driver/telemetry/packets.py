"""Loop outputs as CCSDS Space Packets (CCSDS 133.0-B-2), built with ``spacepackets``.

One telemetry packet per 400 Hz output, APID :data:`APID_ATTITUDE` by default, unsegmented,
its 14-bit sequence count = the output counter modulo 16384 (so a gap in the count is a lost
output). Secondary header: CCSDS Unsegmented Time Code, 4 coarse + 2 fine octets (2⁻¹⁶ s)
of TAI since 1958-01-01 (P-field implicit: agency epoch not used, level 1 TAI epoch).
User data, big-endian (:data:`PAYLOAD`): seq u32, mode u8, n_stars u8, flags u16,
q[4] f64 (ICRS → body, scalar last), ω[3] f64 rad/s, bias[3] f64 rad/s,
σθ[3] f32 rad, σb[3] f32 rad/s, latency f32 µs. The XTCE definition of the same layout is
:mod:`gyrostar.telemetry.xtce`.
"""

from __future__ import annotations

import struct

import numpy as np
from spacepackets.ccsds.spacepacket import PacketType, SequenceFlags, SpacePacket, SpacePacketHeader

from ..errors import ConfigError

APID_ATTITUDE = 0x0A1
SEQ_MODULO = 1 << 14
CUC = struct.Struct(">IH")
PAYLOAD = struct.Struct(">IBBH4d3d3d3f3ff")
PACKET_LEN = 6 + CUC.size + PAYLOAD.size
FIELDS = ("seq", "mode", "n_stars", "flags", "q", "omega", "bias", "sigma_theta", "sigma_bias", "latency_us")


def cuc(tai_s: float) -> bytes:
    coarse = int(np.floor(tai_s))
    fine = int(round((tai_s - coarse) * 65536.0))
    if fine == 65536:
        coarse, fine = coarse + 1, 0
    return CUC.pack(coarse & 0xFFFFFFFF, fine)


def encode(records: np.ndarray, tai_s: np.ndarray, apid: int = APID_ATTITUDE) -> list[bytes]:
    """One packed Space Packet per output record."""
    d = np.sqrt(np.maximum(np.diagonal(records["cov"], axis1=1, axis2=2), 0.0))
    out = []
    for i, r in enumerate(records):
        body = PAYLOAD.pack(int(r["seq"]), int(r["mode"]), int(r["n_stars"]), int(r["flags"]), *r["q"], *r["omega"],
                            *r["bias"], *d[i, :3], *d[i, 3:], float(r["latency_us"]))
        sec = cuc(float(tai_s[i]))
        head = SpacePacketHeader(PacketType.TM, apid, int(r["seq"]) % SEQ_MODULO, len(sec) + len(body) - 1,
                                 sec_header_flag=True, seq_flags=SequenceFlags.UNSEGMENTED)
        out.append(SpacePacket(head, sec, body).pack())
    return out


def decode(packet: bytes) -> dict:
    """One packet → its header fields, TAI time (s since 1958) and payload fields."""
    head = SpacePacketHeader.unpack(packet)
    if head.packet_type != PacketType.TM or not head.sec_header_flag:
        raise ConfigError("not a gyrostar attitude telemetry packet")
    if len(packet) != 6 + head.data_len + 1 or len(packet) != PACKET_LEN:
        raise ConfigError(f"space packet of {len(packet)} bytes, expected {PACKET_LEN}")
    coarse, fine = CUC.unpack_from(packet, 6)
    v = PAYLOAD.unpack_from(packet, 6 + CUC.size)
    return {"apid": head.apid, "seq_count": head.seq_count, "tai_s": coarse + fine / 65536.0,
            "seq": v[0], "mode": v[1], "n_stars": v[2], "flags": v[3], "q": v[4:8], "omega": v[8:11],
            "bias": v[11:14], "sigma_theta": v[14:17], "sigma_bias": v[17:20], "latency_us": v[20]}


class SpacePacketSink:
    """Send every output as a Space Packet in its own UDP datagram to ``host:port``.

    A host other than the loopback needs ``allow_remote`` (config ``outputs.allow_remote``).
    Datagrams the kernel refuses are counted (``dropped``), never waited for."""

    def __init__(self, host: str, port: int, timemap, apid: int = APID_ATTITUDE, allow_remote: bool = False):
        from .udp import open_udp

        self.sock, self.addr = open_udp(host, port, allow_remote, "space-packet output")
        self.timemap = timemap
        self.apid = apid
        self.sent = 0
        self.dropped = 0

    def put(self, records: np.ndarray, t_ns: int = 0) -> None:
        if not len(records):
            return
        for pkt in encode(records, self.timemap.tai(records["t"]), self.apid):
            try:
                self.sock.sendto(pkt, self.addr)
                self.sent += 1
            except OSError:
                self.dropped += 1

    def close(self) -> None:
        self.sock.close()
