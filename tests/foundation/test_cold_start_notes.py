"""A cold start says what it is doing: progress lines while the kernels compile (with the time
left), a line before the star index is built, shown by default and hidden by -q."""

import logging
import time

from gyrostar import logs
from gyrostar.loop import warmup


def _slow(seconds):
    time.sleep(seconds)


def test_compiling_kernels_prints_progress_with_time_left(monkeypatch, caplog):
    monkeypatch.setattr(warmup, "COMPILE_SEEN_S", 0.01)
    monkeypatch.setattr(warmup, "NOTE_EVERY_S", 0.0)
    with caplog.at_level(logs.NOTICE, logger="gyrostar"):
        res = warmup.warm([(_slow, (0.02,))] * 4)       # plain functions: no numba cache hit, each "compiles"
    notes = [r.getMessage() for r in caplog.records if r.levelno == logs.NOTICE]
    assert res["compiled"] == 4 and res["cache_hits"] == 0
    assert notes[0].startswith("compiling the numba kernels (an empty or outdated cache")
    assert "about 80 s on an idle 2-core host" in notes[0]
    assert any("2 of 4" in n and "s left" in n for n in notes[1:-1]), notes
    assert notes[-1].startswith("numba kernels compiled in") and "4 compiled, 0 from the cache" in notes[-1]


def test_loaded_kernels_print_nothing(monkeypatch, caplog):
    with caplog.at_level(logs.NOTICE, logger="gyrostar"):
        warmup.warm([(_slow, (0.0,))] * 3)              # each returns at once: nothing compiled worth a note
    assert not [r for r in caplog.records if r.levelno == logs.NOTICE]


def test_cold_cache_is_told_before_the_start(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    with caplog.at_level(logs.NOTICE, logger="gyrostar"):
        warmup.note_cold_start()
        (tmp_path / "sub").mkdir()
        (tmp_path / "sub" / "kernels.predict_batch-30.py312.nbi").write_bytes(b"")
        warmup.note_cold_start()
    notes = [r.getMessage() for r in caplog.records if r.levelno == logs.NOTICE]
    assert len(notes) == 1 and "first start with this gyrostar" in notes[0] and "s on an idle 2-core host" in notes[0]


def test_notes_are_shown_by_default_and_hidden_by_quiet():
    try:
        logs.setup(0)
        assert logging.getLogger("gyrostar").isEnabledFor(logs.NOTICE)
        assert not logging.getLogger("gyrostar").isEnabledFor(logging.INFO)
        logs.setup(-1)
        assert not logging.getLogger("gyrostar").isEnabledFor(logs.NOTICE)
    finally:
        logging.basicConfig(level=logging.WARNING, force=True)


def test_a_stage_says_what_it_does_and_how_long_it_took(caplog):
    with caplog.at_level(logs.NOTICE, logger="gyrostar"):
        with logs.stage("building the star index (hip2 to V 6.5): once per catalog and camera"):
            time.sleep(0.01)
        with logs.stage("compiling the head emulator's kernels", told=False):
            pass
    notes = [r.getMessage() for r in caplog.records]
    assert notes == ["building the star index (hip2 to V 6.5): once per catalog and camera",
                     "done in 0 s: building the star index"]
