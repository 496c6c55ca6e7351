"""``nidaqmx.errors``: DaqError carries ``error_code``; the message ends with the status code."""

from __future__ import annotations

from .error_codes import DAQmxErrors


class Error(Exception):
    pass


class DaqError(Error):
    def __init__(self, message: str, error_code: int, task_name: str = "") -> None:
        self._error_code = int(error_code)
        try:
            self._error_type = DAQmxErrors(self._error_code)
        except ValueError:
            self._error_type = DAQmxErrors.UNKNOWN
        if task_name:
            message = f"{message}\n\nTask Name: {task_name}"
        message = f"{message}\n\nStatus Code: {self._error_code}"
        super().__init__(message)

    @property
    def error_code(self) -> int:
        return self._error_code

    @property
    def error_type(self) -> DAQmxErrors:
        return self._error_type


class DaqReadError(DaqError):
    def __init__(
        self, message: str, error_code: int, samps_per_chan_read: int, task_name: str = ""
    ) -> None:
        super().__init__(message, error_code, task_name)
        self._samps_per_chan_read = samps_per_chan_read

    @property
    def samps_per_chan_read(self) -> int:
        return self._samps_per_chan_read


class DaqWarning(Warning):
    pass


class DaqResourceWarning(ResourceWarning):
    pass
