"""gyrostar.hil — flatsat runner, HIL scenarios, record/replay (``hil/``)."""
