"""A study's LocalCluster has no dashboard, but its scheduler still served its HTTP routes on
port 8787: with another process there (a second study, a notebook's cluster, any server) every
study printed "UserWarning: Port 8787 is already in use. Perhaps you already have a cluster
running?" in the terminal. The scheduler now takes a free port."""

from __future__ import annotations

import socket
import warnings

from daq.study_runner import dask_client


def test_a_busy_port_8787_says_nothing() -> None:
    holder = socket.socket()
    try:
        holder.bind(("", 8787))
        holder.listen()
    except OSError:
        pass  # something else holds it already: the same case
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with dask_client(1) as client:
                assert client.submit(sum, [1, 2]).result(timeout=60) == 3
        said = [str(w.message) for w in caught if "8787" in str(w.message)]
        assert said == []
    finally:
        holder.close()
