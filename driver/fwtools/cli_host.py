"""``gyrostar fw host``: build and run the firmware host program on a pseudo-terminal."""

from __future__ import annotations

HELP = "run the head firmware host program: UART on a pty, sensor pixels from an mmap'd GSPX file"


def configure(parser) -> None:
    parser.add_argument("--sensor", required=True, help="pixel file (created zero-filled if missing)")
    parser.add_argument("--width", type=int, default=1024, help="sensor columns (default 1024)")
    parser.add_argument("--height", type=int, default=1024, help="sensor rows (default 1024)")
    parser.add_argument("--planes", type=int, choices=(1, 2), default=2, help="1 = light, 2 = light + dark")
    parser.add_argument("--link", help="also make this path a symlink to the pty (a new path, or a stale link of an "
                                       "earlier run; removed on exit)")


def run(args) -> int:
    """Run the host program until it ends, Ctrl-C or SIGTERM; on either signal it is stopped
    (SIGTERM, then SIGKILL after 2 s) before this returns, and ``--exit-with-parent`` makes it
    follow a launcher that was killed outright (SIGKILL)."""
    import subprocess
    from pathlib import Path

    from ..cli.interrupt import release_held_signals, signals_held
    from ..errors import ConfigError
    from . import build
    from .interrupt import sigterm_as_interrupt, stop_child

    sensor = Path(args.sensor)
    if sensor.is_dir() or not sensor.parent.is_dir():
        raise ConfigError(f"--sensor {sensor}: " + ("is a folder: give the pixel file's path" if sensor.is_dir()
                                                     else f"folder {sensor.parent} does not exist"))
    if args.link:
        link = Path(args.link)
        if link.exists() and not link.is_symlink():
            raise ConfigError(f"--link {link} exists and is not a symlink: not replaced (give a new path)")
        if not link.parent.is_dir():
            raise ConfigError(f"--link {link}: folder {link.parent} does not exist")
    for flag, value in (("--width", args.width), ("--height", args.height)):
        if not 1 <= value <= 65535:       # what the host program takes (u16)
            raise ConfigError(f"{flag} must be 1 … 65535 pixels, got {value}")
    build.build("host")
    cmd = [str(build.host_binary_path()), "--sensor", args.sensor, "--width", str(args.width),
           "--height", str(args.height), "--planes", str(args.planes), "--exit-with-parent"]
    if args.link:
        cmd += ["--link", args.link]
    with sigterm_as_interrupt():
        proc = None
        try:
            # a signal while Popen runs (the program may already be up) would leave no handle to
            # stop it: held until ``proc`` exists, then delivered here, inside the try
            with signals_held():
                proc = subprocess.Popen(cmd, preexec_fn=release_held_signals)
            return proc.wait()
        finally:   # Ctrl-C or SIGTERM (KeyboardInterrupt): the CLI reports it, exit 130
            if proc is not None:
                stop_child(proc)
