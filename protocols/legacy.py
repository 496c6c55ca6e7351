"""Reading protocol texts stored by earlier versions of biafc-lab in their run files.

Before the schema asked every generator amplitude to say peak-to-peak or peak (``2 Vpp``,
``1 Vpk``), a bare ``2 V`` was read as volts peak-to-peak. A run file started then stores that
text; :func:`upgrade_protocol_text` rewrites such amplitudes to the ``Vpp`` they meant, so that
``--resume`` of an old, interrupted run continues it instead of refusing its own protocol.
Nothing else in the text is changed.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

__all__ = ["upgrade_protocol_text"]

# "2 V", "0.5mV", "1e-1 kV": a bare volt amplitude as the old schema accepted it
_BARE_VOLTS = re.compile(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*[pnuµμmk]?V\s*$")


def _upgraded(value: Any) -> tuple[Any, bool]:
    if isinstance(value, str) and _BARE_VOLTS.match(value):
        return value.strip() + "pp", True
    return value, False


def upgrade_protocol_text(text: str) -> str:
    """``text`` with bare-volt amplitudes (``amplitudes: [2 V]`` or a ``{start: .., stop: ..}``
    range) written as the ``Vpp`` the earlier schema took them for; ``text`` itself when there
    is none, or when it is not a mapping (the schema then says what is wrong)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    if not isinstance(data, dict):
        return text
    amps = data.get("amplitudes")
    changed = False
    if isinstance(amps, list):
        new = []
        for a in amps:
            v, c = _upgraded(a)
            new.append(v)
            changed |= c
        data["amplitudes"] = new
    elif isinstance(amps, dict):
        for key in ("start", "stop"):
            if key in amps:
                amps[key], c = _upgraded(amps[key])
                changed |= c
    if not changed:
        return text
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
