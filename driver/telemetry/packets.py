"""Loop outputs as CCSDS Space Packets (CCSDS 133.0-B-2), built with ``spacepackets``.

One telemetry packet per 400 Hz output, APID :data:`APID_ATTITUDE` by default, unsegmented,
its 14-bit sequence count = the output counter modulo 16384 (so a gap in the count is a lost
output). Secondary header: CCSDS Unsegmented Time Code, 4 coarse + 2 fine octets (2⁻¹⁶ s)
of TAI since 1958-01-01 (P-field implicit: agency epoch not used, level 1 TAI epoch).
User data, big-endian (:data:`PAYLOAD`): seq u32, mode u8, n_stars u8, flags u16,
q[4] f64 (ICRS → body, scalar last), ω[3] f64 rad/s, bias[3] f64 rad/s,
σθ[3] f32 rad, σb[3] f32 rad/s, latency f32 µs.

One frame packet per image update, APID :data:`APID_FRAME` by default: the attitude at the
frame's mid-exposure, as conventional star trackers report it. Its secondary header is the
CUC TAI of the mid-exposure instant; its sequence count is the frame packet counter modulo
16384 (a gap is a lost frame packet). User data, big-endian (:data:`FRAME_PAYLOAD`): seq u32
(the output counter of the first 400 Hz output holding the update), mode u8, n_stars u8,
flags u16, q_mid[4] f64 (filtered with the frame), σθ_mid[3] f32 rad; the frame before:
its mid-exposure as CUC TAI (u32 s, u16 2⁻¹⁶ s; 0, 0: none), q_mid_s[4] f64 smoothed with
this frame (NaN: none), σθ_mid_s[3] f32 rad; then the camera calibration's pointing bias,
1σ about camera x and y, f32 rad (a constant of the run, reported beside the covariance).
The XTCE definition of both layouts is :mod:`gyrostar.telemetry.xtce`.
"""

from __future__ import annotations

import struct

import numpy as np
from spacepackets.ccsds.spacepacket import PacketType, SequenceFlags, SpacePacket, SpacePacketHeader

from ..errors import ConfigError
from ..loop.record import sigma

APID_ATTITUDE = 0x0A1
SEQ_MODULO = 1 << 14
CUC = struct.Struct(">IH")
PAYLOAD = struct.Struct(">IBBH4d3d3d3f3ff")
PACKET_LEN = 6 + CUC.size + PAYLOAD.size
FIELDS = ("seq", "mode", "n_stars", "flags", "q", "omega", "bias", "sigma_theta", "sigma_bias", "latency_us")
APID_FRAME = 0x0A2
FRAME_PAYLOAD = struct.Struct(">IBBH4d3fIH4d3f2f")
FRAME_PACKET_LEN = 6 + CUC.size + FRAME_PAYLOAD.size


def cuc_fields(tai_s: float) -> tuple[int, int]:
    """CUC 4+2 of TAI seconds since 1958: (whole seconds mod 2³², 2⁻¹⁶ s)."""
    coarse = int(np.floor(tai_s))
    fine = int(round((tai_s - coarse) * 65536.0))
    if fine == 65536:
        coarse, fine = coarse + 1, 0
    return coarse & 0xFFFFFFFF, fine


def cuc(tai_s: float) -> bytes:
    return CUC.pack(*cuc_fields(tai_s))


def _packet(apid: int, count: int, sec: bytes, body: bytes) -> bytes:
    head = SpacePacketHeader(PacketType.TM, apid, count % SEQ_MODULO, len(sec) + len(body) - 1,
                             sec_header_flag=True, seq_flags=SequenceFlags.UNSEGMENTED)
    return SpacePacket(head, sec, body).pack()


def encode(records: np.ndarray, tai_s: np.ndarray, apid: int = APID_ATTITUDE) -> list[bytes]:
    """One packed Space Packet per output record."""
    d = sigma(records["cov"])
    out = []
    for i, r in enumerate(records):
        body = PAYLOAD.pack(int(r["seq"]), int(r["mode"]), int(r["n_stars"]), int(r["flags"]), *r["q"], *r["omega"],
                            *r["bias"], *d[i, :3], *d[i, 3:], float(r["latency_us"]))
        out.append(_packet(apid, int(r["seq"]), cuc(float(tai_s[i])), body))
    return out


def frame_rows(records: np.ndarray, last_t_mid: float) -> np.ndarray:
    """Indexes of the records that are the first to hold a new frame's update (their
    ``t_mid`` finite and not the one before; ``last_t_mid``: the previous batch's last)."""
    t = records["t_mid"]
    before = np.concatenate([[last_t_mid], t[:-1]])
    return np.flatnonzero(np.isfinite(t) & (t != before))


def encode_frames(records: np.ndarray, tai_mid: np.ndarray, tai_mid_s: np.ndarray, first_count: int,
                  pointing_bias_rad=(0.0, 0.0), apid: int = APID_FRAME) -> list[bytes]:
    """One frame packet per record given (each the first output holding its frame's update),
    sequence counts from ``first_count``; ``tai_mid``/``tai_mid_s`` the TAI of their
    ``t_mid``/``t_mid_s`` (NaN: none)."""
    d, ds = sigma(records["cov_mid"]), sigma(records["cov_mid_s"])
    bx, by = (float(v) for v in pointing_bias_rad)
    out = []
    for i, r in enumerate(records):
        prev = cuc_fields(float(tai_mid_s[i])) if np.isfinite(tai_mid_s[i]) else (0, 0)
        body = FRAME_PAYLOAD.pack(int(r["seq"]), int(r["mode"]), int(r["n_stars"]), int(r["flags"]), *r["q_mid"],
                                  *d[i], *prev, *r["q_mid_s"], *ds[i], bx, by)
        out.append(_packet(apid, first_count + i, cuc(float(tai_mid[i])), body))
    return out


def decode(packet: bytes) -> dict:
    """One packet → its header fields, TAI time (s since 1958) and payload fields; ``kind``
    "attitude" (400 Hz output) or "frame" (mid-exposure product), told apart by length."""
    if len(packet) < 6 + CUC.size:
        raise ConfigError(f"space packet of {len(packet)} bytes, shorter than its headers")
    head = SpacePacketHeader.unpack(packet)
    if head.packet_type != PacketType.TM or not head.sec_header_flag:
        raise ConfigError("not a gyrostar telemetry packet")
    if len(packet) != 6 + head.data_len + 1 or len(packet) not in (PACKET_LEN, FRAME_PACKET_LEN):
        raise ConfigError(f"space packet of {len(packet)} bytes, expected {PACKET_LEN} or {FRAME_PACKET_LEN}")
    coarse, fine = CUC.unpack_from(packet, 6)
    out = {"apid": head.apid, "seq_count": head.seq_count, "tai_s": coarse + fine / 65536.0}
    if len(packet) == PACKET_LEN:
        v = PAYLOAD.unpack_from(packet, 6 + CUC.size)
        out.update(kind="attitude", seq=v[0], mode=v[1], n_stars=v[2], flags=v[3], q=v[4:8], omega=v[8:11],
                   bias=v[11:14], sigma_theta=v[14:17], sigma_bias=v[17:20], latency_us=v[20])
        return out
    v = FRAME_PAYLOAD.unpack_from(packet, 6 + CUC.size)
    out.update(kind="frame", seq=v[0], mode=v[1], n_stars=v[2], flags=v[3], q_mid=v[4:8], sigma_theta_mid=v[8:11],
               tai_mid_s=(v[11] + v[12] / 65536.0) if (v[11] or v[12]) else float("nan"), q_mid_s=v[13:17],
               sigma_theta_mid_s=v[17:20], pointing_bias=v[20:22])
    return out


class SpacePacketSink:
    """Send every output as a Space Packet in its own UDP datagram to ``host:port``, and
    with the first output holding each frame's update that frame's mid-exposure packet
    (``frame_apid``; ``pointing_bias_rad``: the camera calibration's 1σ about camera x, y).

    A host other than the loopback needs ``allow_remote`` (config ``outputs.allow_remote``).
    Datagrams the kernel refuses are counted (``dropped``), never waited for."""

    def __init__(self, host: str, port: int, timemap, apid: int = APID_ATTITUDE, allow_remote: bool = False,
                 frame_apid: int = APID_FRAME, pointing_bias_rad=(0.0, 0.0), host_key: str = "outputs.tm_host"):
        from .udp import open_udp

        self.sock, self.addr = open_udp(host, port, allow_remote, "space-packet output", host_key)
        self.timemap = timemap
        self.apid = apid
        self.frame_apid = frame_apid
        self.pointing_bias_rad = tuple(float(v) for v in pointing_bias_rad)
        self.sent = 0
        self.frames_sent = 0
        self.dropped = 0
        self._frames = 0              # frame packets made (their sequence count)
        self._last_t_mid = np.nan

    def put(self, records: np.ndarray, t_ns: int = 0) -> None:
        if not len(records):
            return
        rows = frame_rows(records, self._last_t_mid)
        self._last_t_mid = float(records["t_mid"][-1])
        self.sent += self._send(encode(records, self.timemap.tai(records["t"]), self.apid))
        if rows.size:
            f = records[rows]
            pkts = encode_frames(f, self.timemap.tai(f["t_mid"]), self.timemap.tai(f["t_mid_s"]), self._frames,
                                 self.pointing_bias_rad, self.frame_apid)
            self._frames += len(pkts)
            self.frames_sent += self._send(pkts)

    def _send(self, pkts: list[bytes]) -> int:
        """Send each packet in its own datagram; how many the kernel took."""
        n = 0
        for pkt in pkts:
            try:
                self.sock.sendto(pkt, self.addr)
                n += 1
            except OSError:
                self.dropped += 1
        return n

    def close(self) -> None:
        self.sock.close()
