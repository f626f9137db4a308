"""Robotiq FT300 driver: the pure stream protocol (:mod:`.protocol`) and the pyserial reader."""

from drivers.ft300.protocol import FrameParser, crc16_modbus, decode_frame, encode_frame
from drivers.ft300.sensor import FT300

__all__ = ["FT300", "FrameParser", "crc16_modbus", "decode_frame", "encode_frame"]
