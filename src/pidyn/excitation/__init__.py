"""Excitations: PEER AT2 records, shipped ground motions and their transformations."""

from pidyn.excitation.at2 import AT2FormatError, AT2Record, G, read_at2
from pidyn.excitation.ground_motion import SHIPPED, GroundMotion, load_record, prepare, record_index

__all__ = [
    "G",
    "AT2FormatError",
    "AT2Record",
    "read_at2",
    "SHIPPED",
    "GroundMotion",
    "load_record",
    "prepare",
    "record_index",
]
