"""The HDF5 run store of the run engine (provenance, resume) on top of ``protocols.runfile``."""

from daq.store.run_store import (
    StoreError,
    check_output_path,
    check_resume,
    create_run,
    resume_run,
    stored_request,
    stored_seed,
)

__all__ = [
    "StoreError",
    "check_output_path",
    "check_resume",
    "create_run",
    "resume_run",
    "stored_request",
    "stored_seed",
]
