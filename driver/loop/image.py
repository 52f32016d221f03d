"""Image pipeline: a readout's window pixels → star directions at mid-exposure.

The pixels are centroided on a measuring thread (:func:`gyrostar.loop.image_kernels.
measure_windows` is nogil: background, CoG, smeared-PSF fit along the predicted
trajectory, unit direction with its σ) while the loop keeps stepping; :meth:`result`
returns them at the next step. Also lost-in-space on a full frame or on the spot windows
a head found itself (FIND_SPOTS), then the identifier, run on the head port's worker.
"""

from __future__ import annotations

import numpy as np

from .image_kernels import BRIGHT_FRACTION, measure_windows

LIS_SIGMA = 6.0        # lost-in-space spot threshold: background + 6σ (full frame or the head's FIND_SPOTS)
LIS_MAX_SPOTS = 40     # spots handed to the identifier, brightest first
LIS_HEAD_SPOTS = 64    # spot windows a head's FIND_SPOTS sends (its neighbour score ranks a little
                       # differently from the full box flux: the host re-ranks and keeps 40)
LIS_BOX = 7            # px: centroid box and suppression distance
BLIND_PIXEL_FRACTION = 0.01   # a full frame with more of its pixels near full scale is blinded (not searched)
# An extended object (the Moon's disk, the Earth's limb) makes spots along its edge that no catalog
# holds: spots are not taken within EXTENDED_MARGIN_PX of a region of EXTENDED_MIN_PX or more pixels
# near full scale (a star saturates a few), nor a head's spot window with EXTENDED_WINDOW_PX of them
EXTENDED_MIN_PX = 30
EXTENDED_MARGIN_PX = 12
EXTENDED_WINDOW_PX = 16


def off_extended(spots: np.ndarray, bright: np.ndarray) -> np.ndarray:
    """The ``spots`` ((n, 3) [u, v, flux]) not within ``EXTENDED_MARGIN_PX`` of a connected
    region of ``EXTENDED_MIN_PX`` or more ``bright`` pixels ((H, W) bool)."""
    if len(spots) == 0 or np.count_nonzero(bright) < EXTENDED_MIN_PX:
        return spots
    from scipy import ndimage

    lab, n = ndimage.label(bright)
    area = np.bincount(lab.ravel(), minlength=n + 1)
    big = area >= EXTENDED_MIN_PX
    big[0] = False
    if not big.any():
        return spots
    near = ndimage.maximum_filter(big[lab], size=2 * EXTENDED_MARGIN_PX + 1)
    r = np.clip(np.rint(spots[:, 1]).astype(int), 0, bright.shape[0] - 1)
    c = np.clip(np.rint(spots[:, 0]).astype(int), 0, bright.shape[1] - 1)
    return spots[~near[r, c]]
FIT_MAX_ITER = 10      # Gauss–Newton iterations of the smeared-PSF fit, at most
FIT_TOL_PX = 1e-2      # px (|Δu| + |Δv|): the fit stops after a step this small. It converges
                       # linearly here, each step about 0.1× the one before: on the demo the
                       # position it stops at lies 0.0002 px (median; p99 0.002) from the optimum,
                       # against centroid σ of 0.03–0.14 px (10–90 %), in 3.3 iterations per
                       # spot instead of 4.4 at 1e-3


class ImagePipeline:
    """``threaded`` False (lock-step runs, where steps take no simulated time): the readout is
    centroided at once on the caller's thread; the result is the same, it is taken at the
    same step, and no thread hand-over is paid per frame."""

    def __init__(self, params, camera, identifier, threaded: bool = True):
        self.p = params
        self.cam = camera.as_array()
        self.identifier = identifier
        self.threaded = threaded
        self._pool = None
        self._job = None           # (plan, image result, future or measured tuple)

    @property
    def busy(self) -> bool:
        return self._job is not None

    def submit(self, plan: dict, res) -> None:
        """Centroid ``res.values`` (pixels in span order) of the windows ``plan`` commanded."""
        if self.threaded:
            self._job = (plan, res, self._measure_pool().submit(self._measure, plan, res.values))
        else:
            self._job = (plan, res, self._measure(plan, res.values))

    def result(self):
        """``(plan, image result, (state, b_mid (n, 3), σ (n,) rad))`` of the submitted
        readout (waits for the measuring thread), or None."""
        if self._job is None:
            return None
        plan, res, job = self._job
        self._job = None
        return plan, res, (job.result() if self.threaded else job)

    def measure(self, plan: dict, values) -> tuple:
        """``(state, b_mid, σ)`` of a readout, on the caller's thread (a streaming head port
        measures each frame on its own worker with this)."""
        return self._measure(plan, values)

    def _measure(self, plan: dict, values) -> tuple:
        p = self.p
        vals = np.ascontiguousarray(values, dtype=np.float64)
        vmag = plan.get("vmag")
        if vmag is None:
            vmag = np.full(len(plan["wins"]), np.nan)
        return measure_windows(plan["spans"], vals, plan["wins"], plan["off"], plan["off_start"], plan["off_len"],
                               self.cam, p.psf_sigma_px, p.thresh_sigma, p.min_signal, p.e_per_dn, FIT_MAX_ITER,
                               FIT_TOL_PX, vmag, BRIGHT_FRACTION * p.adc_max_dn)

    def _measure_pool(self):
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            from ..realtime import join_realtime

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="loop-measure", initializer=join_realtime)
        return self._pool

    def lost_in_space(self, image):
        """Spots of a lost-in-space image and their identification: ``(spots, ident or None,
        blinded)``. ``image``: a full frame ((H, W) array), or a head's FIND_SPOTS result
        (:class:`gyrostar.head.SpotCapture`: its windows are centroided here). A blinded
        image — more than ``BLIND_PIXEL_FRACTION`` of a full frame's pixels, or the head's
        background, above ``BRIGHT_FRACTION`` of full scale — is not searched (its glare
        would make spots no catalog holds). Runs on the head port's worker, off the loop's
        steps; reads no loop state."""
        from .acquire import detect_spots, spots_from_windows

        bright = BRIGHT_FRACTION * self.p.adc_max_dn
        if isinstance(image, np.ndarray):
            if np.count_nonzero(image > bright) > BLIND_PIXEL_FRACTION * image.size:
                return np.zeros((0, 3)), None, True
            spots = detect_spots(image.astype(np.float64), LIS_SIGMA, LIS_MAX_SPOTS + LIS_HEAD_SPOTS, LIS_BOX)
            spots = off_extended(spots, image > bright)[:LIS_MAX_SPOTS]
        else:
            if image.background_dn > bright:
                return np.zeros((0, 3)), None, True
            wins = image.capture.windows
            # a window with many pixels near full scale sits on an extended object (the Moon's limb)
            keep = [k + 1 for k, w in enumerate(wins) if np.count_nonzero(w.pixels > bright) < EXTENDED_WINDOW_PX]
            spans = image.spans[np.isin(image.spans[:, 0], keep)] if len(keep) < len(wins) else image.spans
            values = np.concatenate([wins[k - 1].pixels for k in keep]) if keep else np.zeros(0)
            spots = spots_from_windows(spans, values, image.background_dn, image.sigma_dn, LIS_MAX_SPOTS)
        if len(spots) < 3:
            return spots, None, False
        return spots, self.identifier.identify(np.ascontiguousarray(spots[:, :2])), False

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
