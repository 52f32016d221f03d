"""The AEM export read back by an independent reader: Orekit's CCSDS AEM parser
(orekit-jpype, the ``aem-check`` extra; skipped without it or without a JVM).

Orekit needs the UTC–TAI history to read any CCSDS message (CREATION_DATE is UTC): the test
gives it a ``tai-utc.dat`` (USNO format) written from astropy's leap-second table."""

import shutil

import numpy as np
import pytest
from gyrostar.loop.record import FLAG_ATTITUDE_VALID, empty
from gyrostar.telemetry import aem, timescale

MON = ["JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC"]


@pytest.fixture(scope="module")
def orekit(tmp_path_factory):
    if shutil.which("java") is None:
        pytest.skip("no JVM")
    orekit_jpype = pytest.importorskip("orekit_jpype")
    from astropy.utils.iers import LeapSeconds

    orekit_jpype.initVM()
    folder = tmp_path_factory.mktemp("orekit-data")
    from astropy.time import Time

    with open(folder / "tai-utc.dat", "w") as f:
        for r in LeapSeconds.auto_open():
            d = Time(float(r["mjd"]), format="mjd").datetime
            f.write(f" {d.year} {MON[d.month - 1]} {d.day:2d} =JD {float(r['mjd']) + 2400000.5:.1f}"
                    f"  TAI-UTC= {float(r['tai_utc']):5.1f}       S + (MJD - 41317.) X 0.0      S\n")
    from java.io import File
    from org.orekit.data import DataContext, DirectoryCrawler

    DataContext.getDefault().getDataProvidersManager().addProvider(DirectoryCrawler(File(str(folder))))
    return orekit_jpype


def test_aem_read_back_by_orekit(orekit, tmp_path):
    import calendar

    from org.orekit.data import DataSource
    from org.orekit.files.ccsds.ndm import ParserBuilder
    from org.orekit.time import AbsoluteDate, TimeScalesFactory

    rng = np.random.default_rng(7)
    rec = empty(900)
    rec["t"] = 5000.0 + np.arange(900) * 0.0025
    rec["t"][600:] += 1.0                                   # a 1 s gap: a second segment
    rec["flags"] = FLAG_ATTITUDE_VALID
    rec["flags"][300:310] = 0                               # attitude invalid for 10 outputs: no gap > 0.1 s
    q = rng.normal(size=(900, 4))
    rec["q"] = q / np.linalg.norm(q, axis=1)[:, None]
    tm = timescale.from_pair(5000.0, calendar.timegm((2026, 3, 1, 12, 0, 0)) + 0.25)
    counts = aem.write(tmp_path / "run.aem", rec, tm)
    assert counts == {"segments": 2, "lines": 890}
    msg = ParserBuilder().buildAemParser().parseMessage(DataSource(str(tmp_path / "run.aem")))
    segs = msg.getSatellites().values().iterator().next().getSegments()
    assert segs.size() == 2
    tai = TimeScalesFactory.getTAI()
    t0 = AbsoluteDate(2026, 3, 1, 12, 0, 37.25, tai)      # UTC 12:00:00.25 + 37 s
    valid = np.flatnonzero(rec["flags"])
    got_t, got_q = [], []
    for s in range(2):
        seg = segs.get(s)
        assert str(seg.getMetadata().getEndpoints().getFrameA().getName()) == "EME2000"
        for c in seg.getData().getAngularCoordinates():
            got_t.append(c.getDate().durationFrom(t0))
            r = c.getRotation()
            got_q.append([r.getQ1(), r.getQ2(), r.getQ3(), r.getQ0()])
    got_q = np.array(got_q)
    assert len(got_t) == len(valid)
    assert np.allclose(got_t, rec["t"][valid] - 5000.0, atol=2e-6)
    sign = np.sign(np.sum(got_q * rec["q"][valid], axis=1))[:, None]
    assert np.allclose(got_q * sign, rec["q"][valid], atol=1e-12)
