"""Log records → what the live view shows (no rerun here: :mod:`.rrlog` draws it).

The view reads the same records the run's log receives (:class:`gyrostar.recording.logfile.LogWriter`
hands each drained run of whole records to its ``tee``), so it sees what the recorder sees and
nothing more: the head link's frames both ways (window sets, FRAME and FULL_FRAME replies, the
head's spot list), the streaming port's poll answers (the frames the loop used, with their
mid-exposure in host time and their pixels), the loop's outputs, events and, at the end of a
simulated run, the truth. ``ViewDecoder.feed(record)`` turns them into calls on a sink with
the methods of :class:`ViewSink`; times are host seconds (monotonic clock, or the simulated
one of a fast run), the time line of the log.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from collections.abc import Iterator

import numpy as np

from ...loop.record import FLAG_GYRO_GAP, FLAG_OVERRUN, MODE_NAMES, OUTPUT_DTYPE, TRUTH_DTYPE, flag_names
from ...protocol import MsgType, decode_frame
from ...protocol.defs import REPLY_FLAG
from ...protocol.payloads import decode_reply, decode_request
from ...recording import logfile as lf
from ..headport import POLL
from ..streamport import CH_STREAM_POLL, unpack_result

_LINK_STATUS_OK = 0          # first byte of a TX/RX record: the frame went / a packet came
_LINK_PREFIX = 9             # u8 status + f8 host time (recording.taps)
LINK_BIN_S = 0.5             # link throughput is shown per this many seconds
SETS_KEPT = 16               # window sets remembered by the frame number they are for
# the flags that explain a mode change, in the order they are named
_REASON_FLAGS = ("few_stars", "link_error", "head_lost", "gyro_gap", "gyro_saturated", "gyro_stuck", "overrun",
                 "id_verified", "attitude_valid")


def records_in(chunk) -> Iterator[lf.Record]:
    """The records in a run of whole records (a drained log buffer; the file's MAGIC skipped)."""
    view = memoryview(chunk)
    pos = len(lf.MAGIC) if bytes(view[:len(lf.MAGIC)]) == lf.MAGIC else 0
    end = len(view)
    while pos + lf.HEADER.size + lf.CRC.size <= end:
        sync, kind, channel, length, t_ns = lf.HEADER.unpack_from(view, pos)
        if sync != lf.SYNC:
            raise ValueError(f"view feed out of step at byte {pos}: not a record")
        start = pos + lf.HEADER.size
        yield lf.Record(kind, channel, t_ns, bytes(view[start:start + length]))
        pos = start + length + lf.CRC.size


class ViewSink:
    """What a view draws (every method optional to act on; times in host seconds)."""

    def meta(self, meta: dict) -> None: ...
    def sensor(self, width: int, height: int) -> None: ...
    def full_frame(self, t: float, image: np.ndarray) -> None: ...
    def spots(self, t: float, spots: np.ndarray) -> None: ...
    def frame(self, t_mid: float, frame: int, spans: np.ndarray, values: np.ndarray) -> None: ...
    def outputs(self, rows: np.ndarray) -> None: ...
    def truth(self, rows: np.ndarray) -> None: ...
    def text(self, t: float, text: str, level: str) -> None: ...
    def link(self, t: float, down_bytes_per_s: float, up_bytes_per_s: float) -> None: ...


class ViewDecoder:
    """Feeds one sink from log records (:meth:`feed`), keeping the little state that needs:
    the window sets by the stream frame they were sent for, a full frame being assembled,
    the last mode, and the link's bytes in the current :data:`LINK_BIN_S` bin."""

    def __init__(self, sink: ViewSink):
        self.sink = sink
        self.sets: OrderedDict[int, np.ndarray] = OrderedDict()
        self.width = self.height = 0
        self._full: np.ndarray | None = None
        self._mode: int | None = None
        self._bin_t = math.nan
        self._bin = [0, 0]          # bytes down (head → host), up
        self.frames = 0             # windows entries handed to the sink
        self.undecodable = 0        # link frames the view could not read (corrupt on the wire)

    def feed(self, rec: lf.Record) -> None:
        kind = rec.kind
        if kind == lf.OUTPUT:
            rows = np.frombuffer(rec.payload, OUTPUT_DTYPE)
            self._modes(rows)
            self.sink.outputs(rows)
        elif kind in (lf.TX, lf.RX) and rec.channel == lf.CH_HEAD:
            self._link(kind, rec.payload)
        elif kind == POLL and rec.channel == CH_STREAM_POLL and rec.payload[:1] == b"\x01":
            self._poll(rec.payload)
        elif kind == lf.TRUTH:
            self.sink.truth(np.frombuffer(rec.payload, TRUTH_DTYPE))
        elif kind == lf.EVENT:
            self._event(json.loads(rec.payload), rec.t_ns * 1e-9)
        elif kind == lf.META:
            self.sink.meta(json.loads(rec.payload))

    def _event(self, ev: dict, t: float) -> None:
        if "scenario_t0" in ev:
            self.sink.text(float(ev["scenario_t0"]), "scenario starts", "INFO")
        elif "aborted" in ev:
            self.sink.text(t, f"run aborted: {ev['aborted']}", "ERROR")
        elif "summary" in ev:
            s = ev["summary"]
            self.sink.text(self._bin_t if self._bin_t == self._bin_t else t,
                           f"run ends: {s.get('frames')} frames, {s.get('samples_lost')} samples lost, "
                           f"{s.get('overruns')} overruns", "INFO")

    def _modes(self, rows: np.ndarray) -> None:
        """A text line at each mode change, with the flags of the output that changed it."""
        modes = rows["mode"].astype(np.int64)
        prev = np.concatenate([[modes[0] if self._mode is None else self._mode], modes[:-1]])
        for i in np.flatnonzero(modes != prev):
            names = set(flag_names(int(rows["flags"][i])))
            why = [n for n in _REASON_FLAGS if n in names]
            text = (f"{MODE_NAMES.get(int(prev[i]), '?')} → {MODE_NAMES.get(int(modes[i]), '?')}: "
                    f"{int(rows['n_stars'][i])} stars" + (f", {', '.join(why)}" if why else ""))
            self.sink.text(float(rows["t"][i]), text, "WARN" if modes[i] != 1 else "INFO")
        if self._mode is None and len(modes):
            self.sink.text(float(rows["t"][0]), f"first output in {MODE_NAMES.get(int(modes[0]), '?')}", "INFO")
        if len(modes):
            self._mode = int(modes[-1])

    def _link(self, kind: int, payload: bytes) -> None:
        if len(payload) <= _LINK_PREFIX or payload[0] != _LINK_STATUS_OK:
            return
        t = float(np.frombuffer(payload, "<f8", 1, 1)[0])
        self._count_bytes(t, len(payload) - _LINK_PREFIX + 1, up=kind == lf.TX)
        try:
            frame = decode_frame(payload[_LINK_PREFIX:].rstrip(b"\x00"))
            if kind == lf.TX:
                if frame.type == MsgType.SET_WINDOWS:
                    fields = decode_request(frame)
                    if "spans" in fields:
                        self.sets[int(fields["frame"])] = fields["spans"]
                        self.sets.move_to_end(int(fields["frame"]))
                        while len(self.sets) > SETS_KEPT:
                            self.sets.popitem(last=False)
                return
            rtype = frame.type & ~REPLY_FLAG
            if rtype == MsgType.GET_INFO:
                f = decode_reply(frame)
                self.width, self.height = int(f["width"]), int(f["height"])
                self.sink.sensor(self.width, self.height)
            elif rtype == MsgType.FIND_SPOTS:
                self.sink.spots(t, decode_reply(frame)["spots"])
            elif rtype == MsgType.FULL_FRAME and self.width:
                f = decode_reply(frame)
                n = self.width * self.height
                if f["offset"] == 0 or self._full is None:
                    self._full = np.zeros(n, np.uint16)
                off, cnt = int(f["offset"]), int(f["count"])
                self._full[off:off + cnt] = f["pixels"][: max(0, n - off)]
                if off + cnt >= n:
                    self.sink.full_frame(t, self._full.reshape(self.height, self.width))
                    self._full = None
        except Exception:     # noqa: BLE001 - a corrupt link frame is the loop's business, not the view's
            self.undecodable += 1

    def _count_bytes(self, t: float, n: int, up: bool) -> None:
        if self._bin_t != self._bin_t:
            self._bin_t = t
        if t - self._bin_t >= LINK_BIN_S:
            span = t - self._bin_t
            self.sink.link(t, self._bin[0] / span, self._bin[1] / span)
            self._bin_t, self._bin = t, [0, 0]
        self._bin[1 if up else 0] += n

    def _poll(self, payload: bytes) -> None:
        res = unpack_result(payload)
        if res.kind != "windows" or res.error is not None or res.values is None:
            return
        spans = self.sets.get(int(getattr(res, "set_frame", 0)))
        if spans is None or int((spans[:, 3] - spans[:, 2]).sum()) != len(res.values):
            return
        self.frames += 1
        self.sink.frame(float(res.t_mid), int(getattr(res, "frame", 0)), spans, res.values)


def overruns_and_gaps(rows: np.ndarray) -> tuple[int, int]:
    """Outputs flagged after a missed deadline, and after lost gyro samples, in ``rows``."""
    f = rows["flags"]
    return int(np.count_nonzero(f & FLAG_OVERRUN)), int(np.count_nonzero(f & FLAG_GYRO_GAP))
