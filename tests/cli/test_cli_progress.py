"""Long work shows progress on a terminal: ``calibrate gyro-static --simulate`` and
``replay`` draw rich progress bars when stderr is a tty (run here on a pseudo-terminal)."""

import os
import pty
import select
import subprocess

from cli_helpers import GYROSTAR, gyrostar


def _on_a_tty(args, cwd) -> tuple[int, str]:
    """Run the console script with stdout/stderr on a pty; return (exit code, all output)."""
    main, sub = pty.openpty()
    env = dict(os.environ, COLUMNS="120", TERM="xterm")
    p = subprocess.Popen([GYROSTAR, *map(str, args)], stdin=subprocess.DEVNULL, stdout=sub, stderr=sub, cwd=cwd,
                         env=env)
    os.close(sub)
    chunks = []
    while True:
        r, _, _ = select.select([main], [], [], 120)
        if not r:
            p.kill()
            break
        try:
            data = os.read(main, 65536)
        except OSError:             # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(main)
    return p.wait(timeout=60), b"".join(chunks).decode(errors="replace")


def test_gyro_static_simulate_shows_progress(tmp_path):
    code, out = _on_a_tty(["calibrate", "gyro-static", "--simulate", "--hours", "0.05", "--no-plots",
                           "--report", tmp_path / "r"], tmp_path)
    assert code in (0, 1), out                       # 1: a 3-minute record may fail its 10 % checks
    assert "gyro-static: record, Allan deviation per axis" in out and "4/4" in out


def test_replay_shows_progress(tmp_path):
    res = gyrostar(["run", "--fast", "--duration", "1", "--no-plots", "-q", "--out", tmp_path / "r"])
    assert res.returncode == 0, res.stderr
    code, out = _on_a_tty(["replay", tmp_path / "r" / "flatsat.gslog"], tmp_path)
    assert code == 0, out
    assert "replaying" in out and "bit-exact" in out
