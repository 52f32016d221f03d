"""XTCE 1.2 definition of the telemetry packets (attitude and frame), generated with yamcs-pymdb.

The layout is the one :mod:`gyrostar.telemetry.packets` packs (one definition: the payload
struct there and the parameter list here are checked against each other by the tests).
Every parameter carries a unit ("1" for dimensionless values, identifiers and flags).
``python -m gyrostar.telemetry.xtce OUT.xml`` (``make xtce``) writes ``docs/telemetry.xtce.xml``.
"""

from __future__ import annotations

import sys

from ..loop.record import REASON_NAMES
from . import packets

SYSTEM = "gyrostar"
# the top 4 bits of the flags word (gyrostar.loop.record.REASON_*)
REASON_DOC = "reason code (flags bits 12-15): " + ", ".join(f"{k} {v}" for k, v in REASON_NAMES.items())


def build(apid: int = packets.APID_ATTITUDE, frame_apid: int = packets.APID_FRAME):
    """The yamcs-pymdb ``System`` of the packets (attitude and frame)."""
    import yamcs.pymdb as y

    sysm = y.System(SYSTEM, short_description="gyrostar star tracker: attitude telemetry (CCSDS Space Packets)")

    def uint(name, bits, unit, desc):
        return y.IntegerParameter(sysm, name, signed=False, bits=bits, units=unit, short_description=desc,
                                  encoding=y.IntegerEncoding(bits=bits))

    def f64(name, unit, desc):
        return y.FloatParameter(sysm, name, bits=64, units=unit, short_description=desc, encoding=y.FloatEncoding(64))

    def f32(name, unit, desc):
        return y.FloatParameter(sysm, name, bits=32, units=unit, short_description=desc, encoding=y.FloatEncoding(32))

    head = [uint("ccsds_version", 3, "1", "CCSDS packet version number (0)"),
            uint("ccsds_type", 1, "1", "packet type: 0 telemetry"),
            uint("ccsds_sec_header", 1, "1", "secondary header flag (1: CUC time present)"),
            uint("ccsds_apid", 11, "1", "application process identifier"),
            uint("ccsds_seq_flags", 2, "1", "sequence flags (3: unsegmented)"),
            uint("ccsds_seq_count", 14, "count", "packet sequence count = output counter mod 16384"),
            uint("ccsds_length", 16, "octets", "packet data length − 1")]
    base = y.Container(sysm, "ccsds_space_packet", entries=[y.ParameterEntry(p) for p in head], abstract=True)
    time_coarse = uint("tai_coarse", 32, "s", "CUC coarse time: whole TAI seconds since 1958-01-01")
    time_fine = uint("tai_fine", 16, "s/65536", "CUC fine time: 2^-16 s")
    body = [time_coarse, time_fine,
            uint("seq", 32, "count", "output counter"),
            uint("mode", 8, "1", "0 ACQUIRE, 1 TRACK, 2 COAST"),
            uint("n_stars", 8, "count", "stars tracked"),
            uint("reason", 4, "1", REASON_DOC),
            uint("flags", 12, "1", "quality flags (gyrostar.loop.record FLAG_*; bit 0: attitude valid)")]
    body += [f64(f"q_{a}", "1", f"attitude quaternion ICRS → body, {a} (scalar last)") for a in "xyzw"]
    body += [f64(f"omega_{a}", "rad/s", f"body rate, bias-corrected, {a}") for a in "xyz"]
    body += [f64(f"bias_{a}", "rad/s", f"gyro bias estimate, {a}") for a in "xyz"]
    body += [f32(f"sigma_theta_{a}", "rad", f"1-sigma attitude error about body {a}") for a in "xyz"]
    body += [f32(f"sigma_bias_{a}", "rad/s", f"1-sigma gyro bias error, {a}") for a in "xyz"]
    body += [f32("latency_us", "us", "host time from the gyro FIFO read to this output")]
    y.Container(sysm, "attitude", base=base, entries=[y.ParameterEntry(p) for p in body],
                condition=y.EqExpression(head[3], apid), rate=400.0,
                short_description="one 400 Hz loop output (gyrostar.telemetry.packets)")
    frame = [uint("tai_mid_coarse", 32, "s", "CUC coarse time of the frame's mid-exposure: whole TAI s since 1958"),
             uint("tai_mid_fine", 16, "s/65536", "CUC fine time of the frame's mid-exposure: 2^-16 s"),
             uint("frame_seq", 32, "count", "output counter of the first output holding this frame's update"),
             uint("frame_mode", 8, "1", "0 ACQUIRE, 1 TRACK, 2 COAST"),
             uint("frame_n_stars", 8, "count", "stars tracked"),
             uint("frame_reason", 4, "1", REASON_DOC),
             uint("frame_flags", 12, "1", "quality flags (gyrostar.loop.record FLAG_*; bit 0: attitude valid)")]
    frame += [f64(f"q_mid_{a}", "1", f"attitude at mid-exposure, filtered with the frame, ICRS → body, {a}")
              for a in "xyzw"]
    frame += [f32(f"sigma_theta_mid_{a}", "rad", f"1-sigma error of q_mid about body {a}") for a in "xyz"]
    frame += [uint("tai_mid_s_coarse", 32, "s", "mid-exposure of the frame before: whole TAI seconds (0: none)"),
              uint("tai_mid_s_fine", 16, "s/65536", "mid-exposure of the frame before: 2^-16 s")]
    frame += [f64(f"q_mid_s_{a}", "1", f"attitude of the frame before, smoothed with this one, ICRS → body, {a}")
              for a in "xyzw"]
    frame += [f32(f"sigma_theta_mid_s_{a}", "rad", f"1-sigma error of q_mid_s about body {a}") for a in "xyz"]
    frame += [f32(f"pointing_bias_{a}", "rad", f"camera calibration's pointing bias, 1-sigma about camera {a}")
              for a in "xy"]
    y.Container(sysm, "frame_attitude", base=base, entries=[y.ParameterEntry(p) for p in frame],
                condition=y.EqExpression(head[3], frame_apid),
                short_description="one per image update: the attitude at its mid-exposure (gyrostar.telemetry.packets)")
    return sysm


def xml(apid: int = packets.APID_ATTITUDE, frame_apid: int = packets.APID_FRAME) -> str:
    return build(apid, frame_apid).dumps()


def main(argv=None) -> int:
    from ..cli.output import write_or_print

    return write_or_print(xml(), sys.argv[1:] if argv is None else argv)


if __name__ == "__main__":
    sys.exit(main())
