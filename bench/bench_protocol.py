"""Head link benchmarks: frame stream decoding, 10-bit packing, and a windowed capture against
a full-frame readout on the firmware's host program (bytes on the wire and time).

Each case: {"us": t, "baseline_us": b, "ratio": b / t, "note": ...}, baseline measured in
the same run.
"""

from __future__ import annotations

import time

import numpy as np


def _best(fn, reps: int) -> float:
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e6


def _stream_case(reps: int) -> dict:
    from gyrostar.protocol import MsgType
    from gyrostar.protocol.framing import StreamDecoder, encode_frame

    rng = np.random.default_rng(0)
    wire = b"".join(encode_frame(MsgType.WINDOW_DATA | 0x80, i, rng.integers(0, 256, 300, np.uint8).tobytes())
                    for i in range(200))
    chunks = [wire[i:i + 512] for i in range(0, len(wire), 512)]  # what a serial read returns

    def ours():
        d = StreamDecoder()
        n = sum(len(d.feed(c)) for c in chunks)
        assert n == 200

    def per_byte():  # baseline: a reader that handles the stream one byte at a time
        d = StreamDecoder()
        n = sum(len(d.feed(wire[i:i + 1])) for i in range(len(wire)))
        assert n == 200

    t, b = _best(ours, reps), _best(per_byte, max(1, reps // 3))
    return {"us": t, "baseline_us": b, "ratio": b / t,
            "note": f"200 WINDOW_DATA frames ({len(wire)} B) in 512-B reads vs byte-at-a-time decoding"}


def _pack_case(reps: int) -> dict:
    from gyrostar.protocol.payloads import pack10

    vals = np.random.default_rng(1).integers(0, 1024, 8192)

    def loop_pack():  # baseline: plain Python bit accumulator
        acc = bits = 0
        out = bytearray()
        for v in vals.tolist():
            acc |= v << bits
            bits += 10
            while bits >= 8:
                out.append(acc & 0xFF)
                acc >>= 8
                bits -= 8
        if bits:
            out.append(acc)
        return bytes(out)

    assert loop_pack() == pack10(vals)
    t, b = _best(lambda: pack10(vals), reps), _best(loop_pack, max(1, reps // 3))
    return {"us": t, "baseline_us": b, "ratio": b / t, "note": "8192 pixels packed to 10 bits vs a Python loop"}


def _capture_case(quick: bool) -> dict:
    from gyrostar.fwtools import build, wirecount
    from gyrostar.head import HeadClient
    from gyrostar.mocks.firmware_host import FirmwareHost
    from gyrostar.protocol import PixelFormat
    from gyrostar.transport.serial_link import SerialLink

    build.build("host")
    spans, smear = wirecount.star_trajectory_windows(10, rate_dps=5.0, exposure_s=0.010, seed=4)
    with FirmwareHost(1024, 1024, planes=1) as host:
        host.pixels.write_frame(np.random.default_rng(2).integers(0, 1024, (1024, 1024)).astype(np.uint16))
        link = wirecount.CountingLink(SerialLink(host.path))
        try:
            client = HeadClient(link, timeout=2.0)
            client.set_exposure(10)  # time the link, not the exposure
            m = wirecount.measure_capture_bytes(client, link, spans, PixelFormat.PACKED10)
            reps = 3 if quick else 10
            client.set_windows(spans)
            t_win = _best(lambda: client.capture(pixel_format=PixelFormat.PACKED10), reps)
            t_full = _best(lambda: client.full_frame(pixel_format=PixelFormat.PACKED10), max(1, reps // 3))
        finally:
            link.link.close()
    return {"us": t_win, "baseline_us": t_full, "ratio": t_full / t_win,
            "windowed_bytes": m["windowed_bytes"], "full_frame_bytes": m["full_frame_bytes"],
            "byte_fraction": m["ratio"],
            "note": f"10 stars' 6x6 trajectory windows at 5 deg/s ({smear:.1f} px smear, {m['n_pixels']} px): "
                    f"{m['windowed_bytes']} B vs full frame {m['full_frame_bytes']} B on the pty "
                    f"({100 * m['ratio']:.3f} %), packed 10-bit, host program"}


def run(quick: bool) -> dict:
    reps = 5 if quick else 20
    return {"stream_decode": _stream_case(reps), "pack10": _pack_case(reps),
            "windowed_capture_vs_full_frame": _capture_case(quick)}


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=1))
