"""Append-only, crash-safe flatsat logs and the taps that fill and replay them.

* :mod:`.logfile` — the on-disk format (records with a CRC-32C each), writer and reader.
* :mod:`.taps`    — wrappers around a serial port, a register bus (smbus2 / spidev) and a
  clock that record every call, and their replay twins that answer from a log.

A log holds the raw link bytes in both directions, every gyro bus transaction, every
clock reading the loop made, and the loop's output records. Replay builds the same
driver and loop on the replay taps, so the same code sees the same bytes in the same
order and must produce the same outputs bit for bit (see ``gyrostar replay --check``).
"""
