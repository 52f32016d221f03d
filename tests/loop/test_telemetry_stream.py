"""Telemetry a ground station reads as it is: TAI/UTC from host time, CCSDS Space Packets of
a 10 s run decoded by ``spacepackets`` with no sequence gap at 400 Hz and one mid-exposure
packet per image update, and the XTCE definition (yamcs-pymdb) matching both packet layouts
with a unit on every parameter."""

import calendar
import socket
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.hil import config as hc
from gyrostar.hil.replay import load_log
from gyrostar.hil.runner import run_flatsat
from gyrostar.telemetry import packets, timescale, xtce
from spacepackets.ccsds.spacepacket import PacketId, PacketType, parse_space_packets

NS = {"x": "http://www.omg.org/spec/XTCE/20180204"}


def test_tai_utc_leap_seconds_from_erfa():
    # POSIX seconds of two UTC instants either side of the 2016-12-31 leap second
    before = calendar.timegm((2016, 6, 1, 0, 0, 0))
    after = calendar.timegm((2017, 6, 1, 0, 0, 0))
    assert timescale.from_pair(100.0, before).tai_minus_utc_s == 36.0
    tm = timescale.from_pair(100.0, after)
    assert tm.tai_minus_utc_s == 37.0
    # TAI seconds since 1958-01-01 TAI: days × 86400 + leap-second count (+ the 1958–1972
    # offset of 10 s at 1972-01-01 included in the 37 s); hand count of days 1958-01-01 → 2017-06-01
    days = (calendar.timegm((2017, 6, 1, 0, 0, 0)) - calendar.timegm((1958, 1, 1, 0, 0, 0))) // 86400
    assert tm.tai(100.0) == pytest.approx(days * 86400 + 37.0, abs=1e-6)
    assert tm.tai(101.5) - tm.tai(100.0) == pytest.approx(1.5)
    assert tm.utc_iso(102.25) == ["2017-06-01T00:00:02.250000"]
    # against astropy.time (an independent route to the same table) at an arbitrary instant
    from astropy.time import Time

    u = 1795578551.554203
    ref = Time(u, format="unix", scale="utc")
    got = timescale.from_pair(5.0, u)
    assert got.tai(5.0) == pytest.approx((ref.tai - Time("1958-01-01T00:00:00", scale="tai")).sec, abs=1e-6)
    ref.precision = 6
    assert got.utc_iso(5.0) == [ref.isot]


def test_xtce_matches_the_packet_layout_and_every_parameter_has_a_unit(repo):
    text = xtce.xml()
    assert (repo / "docs" / "telemetry.xtce.xml").read_text() == text, "run make xtce"
    root = ET.fromstring(text)
    types = {t.get("name"): t for t in root.find("x:TelemetryMetaData/x:ParameterTypeSet", NS)}
    params = root.findall("x:TelemetryMetaData/x:ParameterSet/x:Parameter", NS)
    assert len(params) == 7 + (2 + 5 + 4 + 3 + 3 + 3 + 3 + 1) + (2 + 5 + 4 + 3 + 2 + 4 + 3 + 2)
    for p in params:
        unit = types[p.get("parameterTypeRef")].find("x:UnitSet/x:Unit", NS)
        assert unit is not None and unit.text, p.get("name")
    bits = {t.get("name"): int(t.find("*[@sizeInBits]", NS).get("sizeInBits")) for t in types.values()}
    containers = {c.get("name"): c for c in root.findall("x:TelemetryMetaData/x:ContainerSet/x:SequenceContainer",
                                                          NS)}
    for body, size in (("attitude", packets.PACKET_LEN), ("frame_attitude", packets.FRAME_PACKET_LEN)):
        total = 0
        for name in ("ccsds_space_packet", body):
            for e in containers[name].find("x:EntryList", NS):
                total += bits[e.get("parameterRef")]
        assert total == 8 * size, body
    # the flags word: its top 4 bits (big-endian: sent first) are the reason code, then 12 flag bits
    for body, reason, flags in (("attitude", "reason", "flags"), ("frame_attitude", "frame_reason", "frame_flags")):
        names = [e.get("parameterRef") for e in containers[body].find("x:EntryList", NS)]
        i = names.index(reason)
        assert names[i + 1] == flags and bits[reason] == 4 and bits[flags] == 12


def test_frame_packet_round_trip_by_hand():
    """One record through encode_frames/decode against hand-set values: the header, the CUC
    times (none for the frame before), the covariances' 1σ and the pointing bias."""
    from gyrostar.loop.record import empty

    r = empty(1)
    r["seq"], r["mode"], r["n_stars"], r["flags"] = 70001, 1, 9, 0x0004
    r["t_mid"] = 12.5
    r["q_mid"] = [0.1, -0.2, 0.3, np.sqrt(1 - 0.14)]
    r["cov_mid"] = np.diag([4e-10, 9e-10, 1e-8])
    r["q_mid_s"] = np.nan
    r["cov_mid_s"] = np.nan
    tai = 2.1e9 + 0.25                      # CUC: exact in 2⁻¹⁶ s
    (pkt,) = packets.encode_frames(r, np.array([tai]), np.array([np.nan]), 16385, (5e-6, -1e-6), apid=0x0A2)
    assert len(pkt) == packets.FRAME_PACKET_LEN
    d = packets.decode(pkt)
    assert d["kind"] == "frame" and d["apid"] == 0x0A2 and d["seq_count"] == 1 and d["tai_s"] == tai
    assert (d["seq"], d["mode"], d["n_stars"], d["flags"]) == (70001, 1, 9, 4)
    assert np.allclose(d["q_mid"], r["q_mid"][0], rtol=0, atol=0)
    assert np.allclose(d["sigma_theta_mid"], [2e-5, 3e-5, 1e-4], rtol=1e-6)
    assert np.isnan(d["tai_mid_s"]) and np.all(np.isnan(d["q_mid_s"]))
    assert np.allclose(d["pointing_bias"], [5e-6, -1e-6], rtol=1e-6)
    for bad in (pkt[:3], pkt[:-1], b"\x18" + pkt[1:]):      # cut in its header, cut short, a TC
        with pytest.raises(ConfigError):
            packets.decode(bad)
    # the rows that open a frame: a finite t_mid unlike the one before (the previous batch's last too)
    t = empty(5)
    t["t_mid"] = [np.nan, 1.0, 1.0, 1.01, 1.01]
    assert list(packets.frame_rows(t, np.nan)) == [1, 3] and list(packets.frame_rows(t[2:], 1.0)) == [1]


@pytest.fixture(scope="module")
def packet_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tm")
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 23)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    cfg = hc.load_flatsat()
    cfg.outputs.space_packets = True
    cfg.outputs.tm_port = rx.getsockname()[1]
    got = bytearray()

    def drain(_records):
        while True:
            try:
                got.extend(rx.recv(65535))
            except BlockingIOError:
                return

    # fast mode: 10 s of flatsat time on the simulated clock, the packets sent as the outputs are made
    res = run_flatsat(cfg, hc.load_scenario("sim2"), duration=10.0, seed=2, folder=folder, plots=False, status=False,
                      on_output=drain, fast=True)
    drain(None)
    rx.close()
    return res, folder, bytes(got)


def test_space_packets_decode_without_gaps(packet_run):
    res, folder, stream = packet_run
    parsed = parse_space_packets(stream, [PacketId(PacketType.TM, True, packets.APID_ATTITUDE),
                                          PacketId(PacketType.TM, True, packets.APID_FRAME)])
    assert not parsed.skipped_ranges
    every = [packets.decode(bytes(p)) for p in parsed.tm_list]
    pk = [p for p, d in zip(parsed.tm_list, every) if d["kind"] == "attitude"]
    out = load_log(folder / "flatsat.gslog")["outputs"]
    assert res["space_packets"]["dropped"] == 0 and len(pk) == res["space_packets"]["sent"] == len(out)
    assert len(pk) >= 0.98 * 10.0 * 400 and res["samples_lost"] == 0
    dec = [packets.decode(bytes(p)) for p in pk]
    count = np.array([d["seq_count"] for d in dec])
    assert np.all(np.diff(count) % packets.SEQ_MODULO == 1)            # no sequence gap
    tai = np.array([d["tai_s"] for d in dec])
    assert np.all(np.diff(tai) > 0) and np.median(np.diff(tai)) == pytest.approx(0.0025, abs=1e-4)
    tm = timescale.from_meta(load_log(folder / "flatsat.gslog")["meta"]["time"])
    assert np.allclose(tai, tm.tai(out["t"]), atol=2.0 ** -16)
    assert np.allclose([d["q"] for d in dec], out["q"]) and [d["seq"] for d in dec] == list(out["seq"])
    # one frame packet per image update, at the first output holding it, stamped at mid-exposure
    frames = [d for d in every if d["kind"] == "frame"]
    first = np.flatnonzero(np.isfinite(out["t_mid"]) & (out["t_mid"] != np.concatenate([[np.nan], out["t_mid"][:-1]])))
    assert len(frames) == len(first) == res["space_packets"]["frames_sent"] >= 0.95 * 10.0 * 100
    assert all(d["apid"] == packets.APID_FRAME for d in frames)
    assert np.all(np.diff([d["seq_count"] for d in frames]) % packets.SEQ_MODULO == 1)
    o = out[first]
    assert [d["seq"] for d in frames] == list(o["seq"])
    assert np.allclose([d["tai_s"] for d in frames], tm.tai(o["t_mid"]), atol=2.0 ** -16)
    assert np.allclose([d["q_mid"] for d in frames], o["q_mid"], rtol=0, atol=0)
    sig = np.sqrt(np.diagonal(o["cov_mid"], axis1=1, axis2=2))
    assert np.allclose([d["sigma_theta_mid"] for d in frames], sig, rtol=1e-6)
    smoothed = np.isfinite(o["t_mid_s"])
    assert smoothed.mean() > 0.95
    assert np.allclose(np.array([d["tai_mid_s"] for d in frames])[smoothed], tm.tai(o["t_mid_s"][smoothed]),
                       atol=2.0 ** -16)
    assert np.allclose(np.array([d["q_mid_s"] for d in frames])[smoothed], o["q_mid_s"][smoothed], rtol=0, atol=0)
    assert all(d["pointing_bias"] == (0.0, 0.0) for d in frames)      # no camera calibration in this run
