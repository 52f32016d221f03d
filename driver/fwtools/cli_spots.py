"""``gyrostar fw spots URL``: ask a head for its lost-in-space spot list (FIND_SPOTS) and show it.

Bench check of the head's own spot finder: the spots (row, col px; flux DN, the firmware's
neighbour score), the head's background and noise, how many candidates it saw, the spot
centroids the host computes from the windows, and the bytes and time the exchange took.
"""

from __future__ import annotations

HELP = "ask a camera head for its lost-in-space spot list (FIND_SPOTS); print spots, background and bytes"


def configure(parser) -> None:
    from ..cli.argtypes import positive_float
    from ..cli.main import add_json

    parser.add_argument("url", help="serial port or pyserial URL (e.g. /dev/pts/3, socket://127.0.0.1:4000)")
    parser.add_argument("--sigma", type=float, default=6.0, help="threshold above the background, in σ (default 6)")
    parser.add_argument("--max-spots", type=int, default=64, help="spots the head sends, 1..64 (default 64)")
    parser.add_argument("--box", type=int, default=7, help="window side around each spot, odd px 3..15 (default 7)")
    parser.add_argument("--timeout", type=positive_float, default=2.0, help="reply timeout per request (s)")
    add_json(parser)


def run(args) -> int:
    import time

    import numpy as np

    from ..cli.output import emit
    from ..errors import ConfigError
    from ..head import HeadClient
    from ..loop.acquire import spots_from_windows
    from ..protocol.defs import LIMITS
    from ..transport.serial_link import SerialLink

    if not 0 < args.sigma < 4096:
        raise ConfigError(f"--sigma {args.sigma} outside (0, 4096)")
    if not 1 <= args.max_spots <= LIMITS["max_windows"]:
        raise ConfigError(f"--max-spots {args.max_spots} outside 1..{LIMITS['max_windows']}")
    if args.box % 2 == 0 or not 3 <= args.box <= LIMITS["spot_box_max"]:
        raise ConfigError(f"--box {args.box}: an odd side from 3 to {LIMITS['spot_box_max']} px")
    with SerialLink(args.url) as link:
        client = HeadClient(link, timeout=args.timeout)
        client.get_info()
        rx0 = client.stats["rx_bytes"]
        t0 = time.monotonic()
        sc = client.find_spots(args.sigma, args.max_spots, args.box)
        seconds = time.monotonic() - t0
        rx = client.stats["rx_bytes"] - rx0
    values = np.concatenate([w.pixels for w in sc.capture.windows]) if sc.capture.windows else np.zeros(0)
    cents = spots_from_windows(sc.spans, values, sc.background_dn, sc.sigma_dn, len(sc.spots))
    result = {"url": args.url, "spots": sc.spots.tolist(), "centroids_uv_flux": cents.tolist(),
              "candidates": sc.candidates, "background_dn": sc.background_dn, "sigma_dn": sc.sigma_dn,
              "threshold_dn": sc.threshold_dn, "sensor_frame": sc.capture.sensor_frame,
              "exposure_us": sc.capture.exposure_us, "bytes_from_head": rx, "seconds": seconds}
    lines = [f"{args.url}: {len(sc.spots)} spots of {sc.candidates} candidates (sensor frame "
             f"{sc.capture.sensor_frame}, exposure {sc.capture.exposure_us} us); background "
             f"{sc.background_dn:.2f} DN, σ {sc.sigma_dn:.2f} DN, threshold {sc.threshold_dn:.2f} DN; "
             f"{rx} B from the head in {seconds * 1e3:.0f} ms"]
    lines += [f"  {i + 1:3d}  row {r:5d}  col {c:5d}  flux {f:6d} DN" for i, (r, c, f) in enumerate(sc.spots.tolist())]
    emit(args, result, "\n".join(lines))
    return 0
