"""NI-DAQ digitiser: driver detection here; real acquisitions on hardware only."""

from __future__ import annotations

import pytest

from instruments.errors import DriverNotInstalledError
from instruments.interfaces import AcquisitionConfig


def _driver_present() -> bool:
    from daq.digitiser_nidaq import _load_nidaqmx

    try:
        _load_nidaqmx()
    except DriverNotInstalledError:
        return False
    return True


def test_missing_driver_is_one_clear_error() -> None:
    if _driver_present():
        pytest.skip("NI-DAQmx driver installed on this machine")
    from daq.digitiser_nidaq import NidaqDigitiser

    with pytest.raises(DriverNotInstalledError, match="NI-DAQmx driver not installed"):
        NidaqDigitiser("Dev1")


@pytest.mark.hardware
def test_hardware_acquisition() -> None:
    from daq.digitiser_nidaq import NidaqDigitiser

    dig = NidaqDigitiser("Dev1")
    rate = dig.configure(
        AcquisitionConfig(sample_rate_Hz=100e3, n_samples=1000, n_pretrigger=100, timeout_s=5.0)
    )
    assert rate > 0
    dig.safe_state()
