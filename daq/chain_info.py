"""The model's view of a bench's chain (``/chain`` of every run file), from its bench file."""

from __future__ import annotations

from typing import Any

from protocols.bench import BenchFile
from protocols.runfile import ChainInfo

__all__ = ["chain_info", "chain_spec", "model_chain_info"]


def chain_spec(bf: BenchFile) -> Any:
    """The bench's ``sim_backend.dem.ChainSpec``: its chain file (``chain:``; null: the
    default) with its ``chain_set``, validated; a bad one raises a one-line
    :class:`ConfigError` naming the bench file's field."""
    from sim_backend import dem

    path = bf.chain_path()
    try:
        return dem.load_chain_with_settings(path, bf.bench.chain_set)
    except (dem.ChainFileError, OSError) as exc:
        field = "chain_set" if bf.bench.chain_set else "chain"
        raise bf.doc.error((field,), str(exc)) from None


def chain_info(bf: BenchFile, n_bands: int = 3) -> ChainInfo:
    """The model's view of the bench's chain (lengths, contact constants, quasi-band edges)."""
    from sim_backend import dem

    chain = dem.build_chain(chain_spec(bf))
    return model_chain_info(chain, dem.quasi_bands(chain, min(n_bands, chain.n_modes + 1)))


def model_chain_info(chain: Any, bands: Any) -> ChainInfo:
    """The run file's ``/chain`` of a built ``sim_backend.dem.Chain`` and its ``Bands``."""
    return ChainInfo.of_model(chain, bands)
