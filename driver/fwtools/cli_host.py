"""``gyrostar fw host``: build and run the firmware host program on a pseudo-terminal."""

from __future__ import annotations

HELP = "run the head firmware host program: UART on a pty, sensor pixels from an mmap'd GSPX file"


def configure(parser) -> None:
    parser.add_argument("--sensor", required=True, help="pixel file (created zero-filled if missing)")
    parser.add_argument("--width", type=int, default=1024, help="sensor columns (default 1024)")
    parser.add_argument("--height", type=int, default=1024, help="sensor rows (default 1024)")
    parser.add_argument("--planes", type=int, choices=(1, 2), default=2, help="1 = light, 2 = light + dark")
    parser.add_argument("--link", help="also make this path a symlink to the pty")


def run(args) -> int:
    import subprocess

    from . import build

    build.build("host")
    cmd = [str(build.host_binary_path()), "--sensor", args.sensor, "--width", str(args.width),
           "--height", str(args.height), "--planes", str(args.planes)]
    if args.link:
        cmd += ["--link", args.link]
    try:
        return subprocess.call(cmd)
    except KeyboardInterrupt:
        return 130
