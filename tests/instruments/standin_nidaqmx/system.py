"""``nidaqmx.system``: the local system and its devices."""

from __future__ import annotations

from typing import Any, NamedTuple

from . import card as _card
from .errors import DaqError


class DriverVersion(NamedTuple):
    major_version: int
    minor_version: int
    update_version: int


class System:
    @staticmethod
    def local() -> System:
        return System()

    @property
    def driver_version(self) -> DriverVersion:
        return DriverVersion(24, 5, 0)

    @property
    def devices(self) -> list[Device]:
        return [Device(n) for n in _card.CARD.devices]


class Device:
    """Constructing one never fails (as in nidaqmx); reading a property of an unknown device
    is DAQmx error -200220."""

    def __init__(self, name: str) -> None:
        self.name = name

    def _spec(self) -> Any:
        spec = _card.CARD.devices.get(self.name)
        if spec is None:
            raise DaqError(f"Device identifier is invalid.\nDevice Specified: {self.name}", -200220)
        return spec

    @property
    def product_type(self) -> str:
        return str(self._spec().product_type)

    @property
    def serial_num(self) -> int:
        return int(self._spec().serial_num)

    @property
    def ai_max_single_chan_rate(self) -> float:
        return float(self._spec().ai_max_single_chan_rate)

    @property
    def ai_max_multi_chan_rate(self) -> float:
        return float(self._spec().ai_max_multi_chan_rate)

    @property
    def ai_simultaneous_sampling_supported(self) -> bool:
        return False

    @property
    def ai_physical_chans(self) -> list[Any]:
        return [_PhysChan(f"{self.name}/ai{i}") for i in range(self._spec().ai_channels)]


class _PhysChan:
    def __init__(self, name: str) -> None:
        self.name = name
