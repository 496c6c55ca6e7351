"""Protocol text for the engine tests."""

from __future__ import annotations

from protocols.schema import ProtocolFile, parse_protocol

PROTOCOL = """\
name: fake_scan
directions: both
burst:
  ltr: {f_center: 8 kHz, cycles: 5}
  rtl: {f_center: 6 kHz, cycles: 5}
amplitudes: [1 Vpp, 2 Vpp]
cylinders: [1, 2, 3]
averages: 2
acquisition: {rate: 100 kS/s, duration: 2 ms, pre_trigger: 0.2 ms}
settle: 5 ms
order: [direction, amplitude, cylinder]
on_point_failure: continue
retries: 2
"""


def make_protocol(text: str = PROTOCOL, **replace: str) -> ProtocolFile:
    for old, new in replace.items():
        text = text.replace(old, new)
    return parse_protocol(text, "test_protocol.yaml")
