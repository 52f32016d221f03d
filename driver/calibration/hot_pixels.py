"""The dark calibration's hot-pixel map applied to every readout the loop gets.

:class:`HotPixelRepair` wraps the loop's head port: each windows readout (pixels in span
order, spans as submitted; on the streaming head each pushed frame before the loop's
``post`` measures it) and each lost-in-space image (before the job's ``post`` detects its
spots: a full frame, or the windows of the head's FIND_SPOTS spots) has its hot pixels
replaced by the mean of their non-hot neighbours on the same row (one numba call per
readout). A hot pixel inside a star's window would otherwise pull its centroid by up to its
excess signal / the star's flux.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numba import njit


@njit(cache=True)
def repair_spans(spans, values, keys, width):
    """Replace, in place, the values of hot pixels (sorted ``keys`` = row·width + column)
    inside ``spans`` [id, row, c0, c1) by the mean of their non-hot row neighbours in the span.
    Returns the number of pixels repaired."""
    k = 0
    fixed = 0
    for i in range(spans.shape[0]):
        row, c0, c1 = spans[i, 1], spans[i, 2], spans[i, 3]
        lo = np.searchsorted(keys, row * width + c0)
        hi = np.searchsorted(keys, row * width + c1)
        for j in range(lo, hi):
            c = keys[j] - row * width
            p = k + (c - c0)
            s = 0.0
            n = 0
            for d in (-1, 1):
                cc = c + d
                if c0 <= cc < c1:
                    kk = row * width + cc
                    m = np.searchsorted(keys, kk)
                    if m >= keys.shape[0] or keys[m] != kk:
                        s += values[p + d]
                        n += 1
            if n:
                values[p] = s / n
                fixed += 1
        k += c1 - c0
    return fixed


def repair_frame(image: np.ndarray, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """A copy of the full frame with the hot pixels replaced by their row neighbours' mean."""
    h, w = image.shape
    out = np.array(image, dtype=np.float64 if image.dtype.kind == "f" else image.dtype, copy=True)
    left = np.clip(cols - 1, 0, w - 1)
    right = np.clip(cols + 1, 0, w - 1)
    out[rows, cols] = (image[rows, left].astype(np.float64) + image[rows, right]) / 2.0
    return out


def repair_spot_capture(sc, keys: np.ndarray, width: int):
    """A copy of the FIND_SPOTS result ``sc`` whose spot windows (pixels in span order, window
    ids 1..n) have the hot pixels ``keys`` (sorted row·width + column) repaired; ``sc``
    itself when none of them falls in a window."""
    import dataclasses

    windows = sc.capture.windows or []
    if not windows or not len(keys):
        return sc
    values = np.concatenate([np.asarray(w.pixels, np.float64) for w in windows])
    if not repair_spans(np.ascontiguousarray(sc.spans, np.int32), values, keys, int(width)):
        return sc
    fixed = []
    k = 0
    for w in windows:
        n = len(w.pixels)
        px = np.rint(values[k:k + n]).astype(np.asarray(w.pixels).dtype)
        fixed.append(dataclasses.replace(w, pixels=px, sum=int(px.sum(dtype=np.int64))))
        k += n
    return dataclasses.replace(sc, capture=dataclasses.replace(sc.capture, windows=fixed))


class HotPixelRepair:
    """The loop's head port with the hot pixels ``hot`` ((n, 2) [column, row]) repaired."""

    _own = ("head", "width", "keys", "cols", "rows", "pending", "repaired")

    def __init__(self, head, hot: np.ndarray, width: int):
        hot = np.asarray(hot, np.int64).reshape(-1, 2)
        object.__setattr__(self, "head", head)
        object.__setattr__(self, "width", int(width))
        object.__setattr__(self, "keys", np.unique(hot[:, 1] * int(width) + hot[:, 0]))
        object.__setattr__(self, "cols", hot[:, 0])
        object.__setattr__(self, "rows", hot[:, 1])
        object.__setattr__(self, "pending", deque())
        object.__setattr__(self, "repaired", 0)

    def submit_windows(self, spans, *stream, post=None):
        """Request mode ``(spans)``: the readout is repaired when :meth:`poll` returns it.
        Streaming ``(spans, frame, post)``: the frame's pixels are repaired before ``post``
        measures them."""
        spans = np.ascontiguousarray(spans, np.int32)
        if len(stream) > 1:
            stream, post = stream[:1], stream[1]
        if not stream and post is None:
            self.pending.append(spans)
            return self.head.submit_windows(spans)
        if post is None:
            return self.head.submit_windows(spans, *stream)
        return self.head.submit_windows(spans, *stream, lambda values: post(self._repaired(spans, values)))

    def _repaired(self, spans, values):
        vals = np.array(values, dtype=np.float64)
        n = repair_spans(spans, vals, self.keys, self.width)
        object.__setattr__(self, "repaired", self.repaired + int(n))
        return vals.astype(np.asarray(values).dtype) if n else values

    def submit_frame(self, post=None):
        if post is None:
            return self.head.submit_frame(None)
        return self.head.submit_frame(lambda image: post(self._repaired_image(image)))

    def _repaired_image(self, image):
        """A lost-in-space image with its hot pixels repaired: a full frame ((H, W) array), or
        a head's FIND_SPOTS result (:class:`gyrostar.head.SpotCapture`), whose spot windows
        are repaired like any windows readout (a spot the head found on a hot pixel then has
        no signal left, and the spot finder leaves its window out)."""
        if isinstance(image, np.ndarray):
            return repair_frame(image, self.cols, self.rows)
        return repair_spot_capture(image, self.keys, self.width)

    def poll(self):
        res = self.head.poll()
        if res is not None and res.kind == "windows" and self.pending:
            spans = self.pending.popleft()
            if res.error is None and res.values is not None:
                res.values = self._repaired(spans, res.values)
        return res

    def __getattr__(self, name):
        return getattr(self.head, name)

    def __setattr__(self, name, value):
        if name in self._own:
            object.__setattr__(self, name, value)
        else:
            setattr(self.head, name, value)
