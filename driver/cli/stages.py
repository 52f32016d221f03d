"""What ``gyrostar run`` does while the coupled loop is not in this build: say so plainly,
list which pipeline stages exist, and run the most complete end-to-end path there is."""

from __future__ import annotations

import importlib

from .output import emit

STAGES = [
    ("simulator (sky, optics, detector, gyro truth)", "gyrostar.mocks.render"),
    ("head link protocol (shared definition)", "gyrostar.protocol"),
    ("head client + emulator", "gyrostar.head.client"),
    ("BMI088 gyro driver", "gyrostar.gyro.bmi088"),
    ("estimation core (windows, centroid, EKF)", "gyrostar.core.spot_ekf"),
    ("star identification", "gyrostar.starid.pyramid"),
    ("coupled loop / flatsat runner", "gyrostar.hil.runner"),
]


def report_missing_loop(args, exc: Exception) -> int:
    present = {}
    for label, module in STAGES:
        try:
            importlib.import_module(module)
            present[label] = True
        except ImportError:
            present[label] = False
    lines = ["The coupled loop (gyrostar.hil.runner) is not in this build yet: "
             f"{exc}.", "Pipeline stages present:"]
    lines += [f"  [{'x' if ok else ' '}] {label}" for label, ok in present.items()]
    emit(args, {"loop_available": False, "stages": present}, "\n".join(lines))
    return 4
