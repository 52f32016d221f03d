"""``gyrostar fw ping URL``: ping a head (pty path, /dev/tty*, socket://host:port) and show its info."""

from __future__ import annotations

HELP = "ping a camera head over a pyserial URL; print round-trip times, GET_INFO and TELEMETRY"


def configure(parser) -> None:
    from ..cli.argtypes import positive_float
    from ..cli.main import add_json

    parser.add_argument("url", help="serial port or pyserial URL (e.g. /dev/pts/3, socket://127.0.0.1:4000)")
    parser.add_argument("-n", "--count", type=int, default=20, help="pings (default 20)")
    parser.add_argument("--timeout", type=positive_float, default=1.0, help="reply timeout per request (s)")
    add_json(parser)


def run(args) -> int:
    import numpy as np

    from ..cli.output import emit
    from ..errors import ConfigError
    from ..head import HeadClient
    from ..transport.serial_link import SerialLink

    if args.count < 1:
        raise ConfigError("--count must be at least 1")
    with SerialLink(args.url) as link:
        client = HeadClient(link, timeout=args.timeout)
        rtt = np.array([client.ping(b"gyrostar") for _ in range(args.count)]) * 1e6
        info = client.get_info()
        tel = client.telemetry()
    result = {"url": args.url, "pings": args.count, "rtt_median_us": float(np.median(rtt)),
              "rtt_p99_us": float(np.percentile(rtt, 99)), "info": info, "telemetry": tel}
    port = {0: "test", 1: "posix host", 2: "mps2"}.get(info["port"], str(info["port"]))
    human = (f"{args.url}: {args.count} pings, median {result['rtt_median_us']:.0f} us, p99 "
             f"{result['rtt_p99_us']:.0f} us\nfirmware {info['fw_major']}.{info['fw_minor']}.{info['fw_patch']} "
             f"({port}), protocol {info['proto_version']}, sensor {info['width']}x{info['height']} "
             f"{info['bits']}-bit, {info['planes']} plane(s)\ntelemetry: {tel}")
    emit(args, result, human)
    return 0
