"""Telemetry a ground station reads as it is: time scales, the output column schema, CCSDS
Space Packets of the loop outputs (``spacepackets``), their XTCE definition (``yamcs-pymdb``)
and CCSDS Attitude Ephemeris Messages."""
