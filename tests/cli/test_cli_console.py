"""The console script leaves right after the last exit handler, with the command's code,
its output flushed, and every other exit handler run first."""

import json
import subprocess
import sys

SCRIPT = """
import atexit, sys
import gyrostar.cli.console as console
import gyrostar.cli.main as cli_main

def main():
    atexit.register(lambda: open({mark!r}, "w").write("ran"))   # a command's own exit handler
    for _ in range(100_000):                                     # buffered, never flushed here
        sys.stdout.write("0123456789")
    return 5

cli_main.main = main
console.console()
"""


def test_exit_code_output_and_other_exit_handlers_survive_the_quick_exit(tmp_path):
    mark = tmp_path / "handler-ran"
    proc = subprocess.run([sys.executable, "-c", SCRIPT.format(mark=str(mark))], capture_output=True, timeout=60)
    assert proc.returncode == 5
    assert len(proc.stdout) == 1_000_000
    assert mark.read_text() == "ran"


def test_a_failing_command_keeps_its_exit_code_and_one_json_error():
    proc = subprocess.run([sys.executable, "-m", "gyrostar", "run", "--scenario", "no-such-scenario", "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert json.loads(proc.stdout.strip().splitlines()[-1])["exit_code"] == 2
    assert "Traceback" not in proc.stderr and "unknown scenario" in proc.stderr
