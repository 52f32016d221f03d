"""Transports: pyserial packet link (loop://, spy://, pty), I2C burst routing, SPI framing, errors."""

import errno
import sys
import time

import pytest
from gyrostar.errors import DeviceError, NotAvailableError
from gyrostar.mocks.fake_smbus import FakeSMBus
from gyrostar.mocks.faults import FaultyBus
from gyrostar.protocol import decode_frame, encode_frame
from gyrostar.transport import I2CBus, I2CRegisters, SerialLink, SPIRegisters, open_spidev


class Regs:
    """A 256-byte register file that records the (reg, n, autoinc) of every access."""

    def __init__(self, autoinc_bit=None):
        self.mem = bytearray(range(256))
        self.log = []
        self.autoinc_bit = autoinc_bit

    def i2c_decode(self, reg):
        if self.autoinc_bit is None:
            return reg, True
        return reg & ~self.autoinc_bit & 0xFF, bool(reg & self.autoinc_bit)

    def spi_decode(self, cmd):
        return cmd & 0x3F, bool(cmd & 0x80), bool(cmd & 0x40)

    def read(self, reg, n, inc=True):
        self.log.append(("r", reg, n, inc))
        return bytes(self.mem[(reg + i) & 0xFF] if inc else self.mem[reg] for i in range(n))

    def write(self, reg, data, inc=True):
        self.log.append(("w", reg, len(data), inc))
        for i, b in enumerate(data):
            self.mem[(reg + i) & 0xFF if inc else reg] = b


def test_i2c_block_reads_and_rdwr_bursts():
    dev = Regs()
    smbus = FakeSMBus({0x68: dev})
    calls = []
    orig = smbus.i2c_rdwr
    smbus.i2c_rdwr = lambda *m: (calls.append(len(m)), orig(*m))[1]
    regs = I2CRegisters(I2CBus(smbus, "i2c-1"), 0x68)
    assert regs.read(0x10, 32) == bytes(range(0x10, 0x30)) and not calls  # ≤ 32: SMBus block read
    assert regs.read(0x10, 200) == bytes(range(0x10, 0xD8)) and calls == [2]  # > 32: one i2c_rdwr
    regs.write(0x05, b"\xAA\xBB")
    assert dev.mem[5:7] == b"\xAA\xBB"
    with pytest.raises(ValueError):
        regs.bus.read(0x68, 0, 9000)


def _regs_on_wire(bus, wire):
    """A 256-byte register file on the fake bus ``bus`` whose transfers take time on ``wire``."""
    from gyrostar.mocks.fake_spidev import FakeSpiDev

    if bus == "i2c":
        return I2CRegisters(I2CBus(FakeSMBus({0x68: Regs()}, clock=wire, bus_hz=400e3), "i2c-1"), 0x68)
    return SPIRegisters(FakeSpiDev(Regs(), clock=wire), read_bit=0x80, multi_bit=0x40)     # 5 MHz


# a 32-byte read: I2C at 400 kHz, address, register, repeated-start address and 32 data bytes at
# 9 clocks each plus start and stop = 317 clocks; SPI at 5 MHz, command and 32 bytes = 264 clocks
WIRE_S = {"i2c": (9 * 35 + 2) / 400e3, "spi": 8 * 33 / 5e6}


@pytest.mark.parametrize("bus", ["i2c", "spi"])
def test_transfers_take_their_wire_time(bus):
    """On a simulated clock a transfer advances it by exactly its wire time; in real time
    (SleepingWire) it lasts at least that long, with the interpreter lock free for other
    threads meanwhile (as a thread blocked in i2c-dev's or spidev's ioctl)."""
    import threading

    from gyrostar.clock import SimulatedClock
    from gyrostar.mocks.fake_smbus import SleepingWire

    clock = SimulatedClock(5.0)
    assert _regs_on_wire(bus, clock).read(0x10, 32) == bytes(range(0x10, 0x30))
    assert clock.now() - 5.0 == pytest.approx(WIRE_S[bus], rel=1e-12)

    regs = _regs_on_wire(bus, SleepingWire())
    turns = [0]        # the other thread's loop turns
    stop = threading.Event()

    def other():
        while not stop.is_set():
            turns[0] += 1
            time.sleep(0)

    switch = sys.getswitchinterval()
    sys.setswitchinterval(1.0)     # a wait that held the lock would starve the other thread
    t = threading.Thread(target=other)
    t.start()
    try:
        t0 = time.monotonic()
        n_before = turns[0]
        for _ in range(20):
            regs.read(0x10, 32)
        elapsed = time.monotonic() - t0
        n_during = turns[0] - n_before
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(switch)
    assert elapsed >= 20 * WIRE_S[bus]
    assert n_during > 0


def test_st_autoincrement_bit_on_i2c_and_spi():
    dev = Regs(autoinc_bit=0x80)
    regs = I2CRegisters(I2CBus(FakeSMBus({0x6A: dev})), 0x6A, autoincrement=0x80)
    regs.read(0x28, 6)
    regs.read(0x0F, 1)
    assert dev.log[-2:] == [("r", 0x28, 6, True), ("r", 0x0F, 1, False)]
    from gyrostar.mocks.fake_spidev import FakeSpiDev

    spi_dev = Regs()
    spi = SPIRegisters(FakeSpiDev(spi_dev), read_bit=0x80, multi_bit=0x40)
    assert spi.read(0x28, 6) == bytes(range(0x28, 0x2E))
    spi.write(0x20, b"\x8F")
    assert spi_dev.log == [("r", 0x28, 6, True), ("w", 0x20, 1, False)] and spi_dev.mem[0x20] == 0x8F


def test_bus_errors_are_device_errors_with_context():
    bus = FaultyBus(FakeSMBus({0x68: Regs()}))
    regs = I2CRegisters(I2CBus(bus, "i2c-7"), 0x68)
    bus.nack_next(1)
    with pytest.raises(DeviceError, match=r"i2c-7 addr 0x68: read of 6 byte\(s\) at reg 0x02 failed: NACK") as e:
        regs.read(0x02, 6)
    assert e.value.errno == errno.EREMOTEIO
    with pytest.raises(DeviceError, match="no ACK|NACK"):
        I2CRegisters(I2CBus(FakeSMBus({})), 0x69).read(0, 1)
    bus.corrupt(1.0)
    assert regs.read(0x00, 8) != bytes(range(8))
    assert bus.injected["corrupt"] >= 8


def test_spidev_missing_is_not_available():
    if "spidev" in sys.modules or _has_spidev():
        pytest.skip("spidev is installed here")
    with pytest.raises(NotAvailableError, match="spidev"):
        open_spidev(0, 0)


def _has_spidev():
    try:
        import spidev  # noqa: F401
    except ImportError:
        return False
    return True


def test_serial_link_packets_over_loop_url():
    link = SerialLink("loop://")
    try:
        frames = [encode_frame(1, i, bytes(range(i * 3))) for i in range(5)]
        link.send(b"".join(frames[:3]) + frames[3][:4])
        link.send(frames[3][4:] + b"\x00\x00" + frames[4])  # split frame and an empty packet
        got = [link.recv(1.0) for _ in range(5)]
        assert [decode_frame(p).seq for _, p in got] == list(range(5))
        assert all(t <= time.monotonic() for t, _ in got)
        assert link.recv(0.05) is None
    finally:
        link.close()


def test_serial_link_spy_url_taps_bytes(tmp_path):
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    tap = tmp_path / "tap.txt"
    link = SerialLink(f"spy://{os.ttyname(slave)}?file={tap}")
    try:
        os.write(master, encode_frame(1, 7, b"hi"))
        assert decode_frame(link.recv(1.0)[1]).payload == b"hi"
        link.send(b"\x01\x02\x00")
        assert os.read(master, 16) == b"\x01\x02\x00"
    finally:
        link.close()
        os.close(master)
        os.close(slave)
    text = tap.read_text()
    assert "RX" in text and "TX" in text  # the hex tap saw both directions


def test_serial_link_bad_url_and_closed_pty():
    with pytest.raises(DeviceError, match="cannot open serial link"):
        SerialLink("/dev/does-not-exist-gyrostar")
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    link = SerialLink(os.ttyname(slave))
    os.write(master, encode_frame(1, 1, b""))
    assert link.recv(1.0) is not None
    os.close(master)
    os.close(slave)
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match="closed"):  # the reader thread reports the hang-up
        link.recv(5.0)
    assert time.monotonic() - t0 < 2.0
    with pytest.raises(DeviceError, match="down"):
        link.send(b"\x01\x00")
    link.close()
